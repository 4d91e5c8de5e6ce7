"""Side-by-side benchmark of this checkout against another one: a speed-up over previous
code ("≥ 2× the previous step rate") needs the previous code measured in the same minutes,
since this VM's speed drifts by 2× within a day.

Each checkout measures "lanes" steps/s on a fixed track (the oval) and with a new
generated track per reset (random actions, resets included) and the median
``env.reset()`` onto a new track. Two ways:

- side by side (the default): both run at the same time, each pinned to one core, then
  swapped (``--pairs``); needs two cores;
- ``--turns``: both on one core, taking turns of ``TURN_STEPS`` steps (``TURN_RESETS``
  resets) per figure, the one that goes first alternating. Each turn has the core to
  itself, and the host's drift falls on both alike: on a host whose two cores are busy
  with other guests by different amounts (pairs of the same two checkouts read
  0.69–1.44 side by side), this is the reading to trust.

    python benchmarks/bench_ab.py --other /path/to/old/checkout/.venv/bin/python \\
        [--steps 3000] [--resets 150] [--pairs 2 | --turns] [--json]

``--other``: the Python of the other checkout's environment (``make install`` there); a
table, or ``--json``.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from _machine import host

CHILD_FLAG = "--child"
TURNS_FLAG = "--child-turns"

TURN_STEPS = 300
"""Steps of one figure per turn (``--turns``)."""

TURN_RESETS = 10
"""Resets per turn (``--turns``)."""

FIGURES = (("fixed_steps_per_s", "fixed track [steps/s]"),
           ("generated_steps_per_s", "generated [steps/s]"),
           ("reset_median_ms", "reset median [ms]"))
"""Each checkout's figures: key, label."""


def measure(steps: int, resets: int) -> dict[str, float]:
    """This interpreter's figures, on the one core it is pinned to (child process)."""
    import cv2
    import gymnasium as gym
    import numpy as np
    from bench_env import steps_per_second  # beside this script, whichever Python runs it

    import tfalda_sim  # noqa: F401  (registers TfaldaTrack-v0)

    cv2.setNumThreads(1)

    def rate(**kwargs: object) -> float:  # bench_env's loop, this checkout's copy of it
        make = gym.make("TfaldaTrack-v0", **kwargs)
        return steps_per_second(make, steps, "", quiet=True)["steps_per_s"]

    env = gym.make("TfaldaTrack-v0")
    env.reset(seed=0)
    times = []
    for seed in range(1, resets + 1):
        t0 = time.perf_counter()
        env.reset(seed=seed)
        times.append(time.perf_counter() - t0)
    return {"fixed_steps_per_s": rate(track="oval"), "generated_steps_per_s": rate(),
            "reset_median_ms": float(np.median(times) * 1000.0)}


def serve_turns() -> None:
    """A ``--turns`` child: this interpreter's envs, stepped on command. Reads lines
    ``fixed N``, ``generated N`` (N random-action steps, resets included) or ``reset N``
    (N resets onto new tracks) from stdin and answers each with a JSON line: the seconds
    taken (``times``: each reset's); ``quit`` or the end of stdin ends it. Ignores Ctrl-C:
    the parent reports what was finished, then ends it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    import cv2
    import gymnasium as gym

    import tfalda_sim  # noqa: F401  (registers TfaldaTrack-v0)

    cv2.setNumThreads(1)
    envs = {"fixed": gym.make("TfaldaTrack-v0", track="oval"),
            "generated": gym.make("TfaldaTrack-v0")}
    for env in envs.values():  # as bench_env: seeded, warmed up, then from reset(seed=1)
        env.action_space.seed(0)
        env.reset(seed=0)
        for _ in range(20):
            env.step(env.action_space.sample())
        env.reset(seed=1)
    resetting = gym.make("TfaldaTrack-v0")
    resetting.reset(seed=0)
    seed = 0
    print(json.dumps({"ready": True}), flush=True)
    for line in sys.stdin:
        command, _, count = line.partition(" ")
        if command == "quit":
            break
        n = int(count)
        if command == "reset":
            times = []
            for _ in range(n):
                seed += 1
                t0 = time.perf_counter()
                resetting.reset(seed=seed)
                times.append(time.perf_counter() - t0)
            print(json.dumps({"times": times}), flush=True)
            continue
        env = envs[command]
        t0 = time.perf_counter()
        for _ in range(n):
            _, _, terminated, truncated, _ = env.step(env.action_space.sample())
            if terminated or truncated:
                env.reset()
        print(json.dumps({"seconds": time.perf_counter() - t0}), flush=True)


class _TurnChild:
    """A child process of one checkout that answers commands in turns: by default
    ``serve_turns`` pinned to ``core``; else ``script`` run with ``args`` (``bench_vec_ab``).
    It says ``ready`` first, then one JSON line per command."""

    def __init__(self, python: str, core: int, who: str, script: Path | None = None,
                 args: tuple[str, ...] = ()) -> None:
        self.who = who
        command = ([python, str(script), *args] if script is not None
                   else [python, str(Path(__file__).resolve()), TURNS_FLAG, str(core)])
        self.proc = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True)
        self._read()  # ready

    def _read(self) -> dict[str, Any]:
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()
        if not line:
            self.proc.wait(timeout=10)
            err = self.proc.stderr.read() if self.proc.stderr else ""
            raise RuntimeError(f"the {self.who} checkout's run failed (exit "
                               f"{self.proc.returncode}):\n{err.strip()[-1500:]}")
        return json.loads(line)

    def ask(self, command: str, n: int) -> dict[str, Any]:
        assert self.proc.stdin is not None
        self.proc.stdin.write(f"{command} {n}\n")
        self.proc.stdin.flush()
        return self._read()

    def close(self) -> None:
        if self.proc.poll() is None:
            with contextlib.suppress(OSError):
                assert self.proc.stdin is not None
                self.proc.stdin.write("quit\n")
                self.proc.stdin.flush()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()


def run_turns(other: str, steps: int, resets: int, quiet: bool) -> dict[str, object]:
    """``--turns``: both checkouts on this process's first core, taking turns."""
    core = sorted(os.sched_getaffinity(0))[0]
    seconds = {side: {"fixed": 0.0, "generated": 0.0} for side in ("this", "other")}
    times: dict[str, list[float]] = {"this": [], "other": []}
    done = {"fixed": 0, "generated": 0, "reset": 0}
    children: dict[str, _TurnChild] = {}
    interrupted = False
    try:
        children["this"] = _TurnChild(sys.executable, core, "this")
        children["other"] = _TurnChild(other, core, "other")
        turn = 0
        while done["fixed"] < steps or done["reset"] < resets:
            order = ("this", "other") if turn % 2 == 0 else ("other", "this")
            for figure in ("fixed", "generated"):
                n = min(TURN_STEPS, steps - done[figure])
                if n > 0:  # counted once both sides made it (a Ctrl-C may come between)
                    took = {side: children[side].ask(figure, n)["seconds"] for side in order}
                    for side in order:
                        seconds[side][figure] += took[side]
                    done[figure] += n
            n = min(TURN_RESETS, resets - done["reset"])
            if n > 0:
                resets_took = {side: children[side].ask("reset", n)["times"] for side in order}
                for side in order:
                    times[side] += resets_took[side]
                done["reset"] += n
            turn += 1
            if not quiet:
                print(f"turn {turn}: {done['fixed']}/{steps} steps, {done['reset']}/{resets} "
                      "resets", file=sys.stderr)
    except KeyboardInterrupt:
        interrupted = True  # the turns finished so far are reported
    finally:
        for child in children.values():
            child.close()
    figures = {}
    for side in ("this", "other"):
        figures[side] = {
            "fixed_steps_per_s": done["fixed"] / seconds[side]["fixed"]
            if seconds[side]["fixed"] else float("nan"),
            "generated_steps_per_s": done["generated"] / seconds[side]["generated"]
            if seconds[side]["generated"] else float("nan"),
            "reset_median_ms": float(statistics.median(times[side]) * 1000.0)
            if times[side] else float("nan")}
    return {"machine": {**host(), "one_core_in_turns": core},
            "other_python": other, "steps": done["fixed"], "resets": done["reset"],
            "turn_steps": TURN_STEPS, "turn_resets": TURN_RESETS,
            "this": figures["this"], "other": figures["other"],
            "ratio": {k: figures["this"][k] / figures["other"][k] for k in figures["this"]},
            "interrupted": interrupted}


def _child(python: str, core: int, steps: int, resets: int) -> subprocess.Popen:
    return subprocess.Popen(
        [python, str(Path(__file__).resolve()), CHILD_FLAG, str(core), str(steps), str(resets)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _answer(proc: subprocess.Popen, who: str) -> dict[str, float]:
    out, err = proc.communicate()
    if proc.returncode != 0:
        raise RuntimeError(f"the {who} checkout's run failed (exit {proc.returncode}):\n"
                           f"{err.strip()[-1500:]}")
    return json.loads(out.strip().splitlines()[-1])


def run(other: str, steps: int, resets: int, pairs: int, quiet: bool) -> dict[str, object]:
    cores = sorted(os.sched_getaffinity(0))
    if len(cores) < 2:
        raise RuntimeError("bench_ab needs two cores (one process on each); this process "
                           f"may use {len(cores)}")
    rows: list[dict[str, object]] = []
    interrupted = False
    for k in range(pairs):
        this_core, other_core = (cores[0], cores[1]) if k % 2 == 0 else (cores[1], cores[0])
        procs = (_child(sys.executable, this_core, steps, resets),
                 _child(other, other_core, steps, resets))
        try:
            this, that = _answer(procs[0], "this"), _answer(procs[1], "other")
        except KeyboardInterrupt:
            interrupted = True  # the pairs finished so far are reported
            break
        finally:
            for proc in procs:
                if proc.poll() is None:
                    proc.kill()
        rows.append({"pair": k + 1, "this_core": this_core, "other_core": other_core,
                     "this": this, "other": that,
                     "ratio": {key: this[key] / that[key] for key in this}})
        if not quiet:
            print(f"pair {k + 1}/{pairs} done", file=sys.stderr)
    return {"machine": {**host(), "pinned_one_core_each": True},
            "other_python": other, "steps": steps, "resets": resets, "pairs": rows,
            "interrupted": interrupted}


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == [CHILD_FLAG]:
        core, steps, resets = (int(v) for v in argv[1:4])
        os.sched_setaffinity(0, {core})
        print(json.dumps(measure(steps, resets)))
        return 0
    if argv[:1] == [TURNS_FLAG]:
        os.sched_setaffinity(0, {int(argv[1])})
        serve_turns()
        return 0
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--other", required=True,
                        help="the Python of the other checkout's environment")
    parser.add_argument("--steps", type=int, default=3000, help="steps per configuration")
    parser.add_argument("--resets", type=int, default=150, help="resets onto new tracks")
    parser.add_argument("--pairs", type=int, default=None,
                        help="runs side by side (cores swapped; default 2)")
    parser.add_argument("--turns", action="store_true",
                        help="both checkouts on one core, taking turns (a noisy host)")
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    args = parser.parse_args(argv)
    if args.turns and args.pairs is not None:
        parser.error("--pairs and --turns contradict each other: pairs run side by side, "
                     "turns on one core; give one")
    if args.pairs is None:
        args.pairs = 2
    for name in ("steps", "resets", "pairs"):
        if getattr(args, name) < 1:
            parser.error(f"--{name} must be ≥ 1, got {getattr(args, name)}")
    if not (os.path.isfile(args.other) and os.access(args.other, os.X_OK)):
        parser.error(f"--other {args.other!r} is not an executable file: give the other "
                     "checkout's Python, e.g. /path/to/checkout/.venv/bin/python")
    try:
        if args.turns:
            return _report_turns(run_turns(args.other, args.steps, args.resets,
                                           quiet=args.json), args)
        result = run(args.other, args.steps, args.resets, args.pairs, quiet=args.json)
    except RuntimeError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    status = _status(result, args.json, f"{len(result['pairs'])} of {args.pairs} pairs "  # type: ignore[arg-type]
                     "finished")
    if args.json:
        return status
    print(f"machine: {result['machine']['cores']} cores of {result['machine']['cpu']}, "
          "one process pinned to each; "
          f"other: {args.other}")
    print(f"{'pair':<6}{'figure':<24}{'other':>10}{'this':>10}{'this/other':>12}")
    for row in result["pairs"]:  # type: ignore[union-attr]
        for key, label in FIGURES:
            print(f"{row['pair']:<6}{label:<24}{row['other'][key]:>10.2f}"
                  f"{row['this'][key]:>10.2f}{row['ratio'][key]:>12.2f}")
    return status


def _status(result: dict[str, Any], as_json: bool, finished: str) -> int:
    """The exit status (130 after a Ctrl-C, which says what was finished); the JSON
    printed if asked for."""
    status = 0
    if result["interrupted"]:
        print(f"interrupted: {finished}; those are reported", file=sys.stderr)
        status = 130
    if as_json:
        print(json.dumps(result, indent=2))
    return status


def _report_turns(result: dict[str, Any], args: argparse.Namespace) -> int:
    status = _status(result, args.json, f"{result['steps']} steps and {result['resets']} "
                     "resets per checkout finished")
    if args.json:
        return status
    print(f"machine: {result['machine']['cores']} cores of {result['machine']['cpu']}; "
          "both checkouts on core "
          f"{result['machine']['one_core_in_turns']}, in turns of {TURN_STEPS} steps "
          f"({TURN_RESETS} resets); other: {args.other}")
    print(f"{'figure':<24}{'other':>10}{'this':>10}{'this/other':>12}")
    for key, label in FIGURES:
        print(f"{label:<24}{result['other'][key]:>10.2f}{result['this'][key]:>10.2f}"
              f"{result['ratio'][key]:>12.2f}")
    return status


if __name__ == "__main__":
    sys.exit(main())
