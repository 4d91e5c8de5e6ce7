"""A/B benchmark of ``gymnasium.make_vec("TfaldaTrack-v0")`` (the target "2 envs ≥ 1.7×
one env"): this checkout against another one, in turns, so that the host's drift (± 10 %
within minutes here) falls on both alike.

    python benchmarks/bench_vec_ab.py --other /path/to/old/checkout/.venv/bin/python \\
        [--rounds 40] [--turn-steps 1500] [--warmup-steps 1500] [--json]

Each checkout runs in a child process of its own (its ``make install``'s Python) holding
three vector envs in "lanes" mode on default generated tracks, each warmed up
(``--warmup-steps`` vector steps) and stepped with uniformly random actions from a seeded
generator of its own:

- ``2 envs``: ``gymnasium.make_vec(…, num_envs=2)``, ``NEXT_STEP`` autoreset, ``step``
  (Gymnasium's merged infos);
- ``2 envs, SAME_STEP``: the same in ``SAME_STEP`` mode through ``step_per_env``
  (stable-baselines3's path, ``tfalda-sim train``);
- ``1 env``: ``make_vec`` with one env (all in the child's process).

Every round steps each figure ``--turn-steps`` vector steps in one checkout, then in the
other (who goes first alternates); the child that waits leaves the cores to the other
(its workers sleep on their pipes). Reports env steps/s per figure and checkout, the ratio
this / other over all rounds, the quartiles of the per-round ratios (how far the drift
within a round reaches) and each checkout's 2 envs / 1 env; a table, or ``--json``. A
Ctrl-C reports the rounds finished (exit 130).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import time
from pathlib import Path
from typing import Any

from _machine import host
from bench_ab import _status, _TurnChild

CHILD_FLAG = "--child"

WARMUP_STEPS = 1500
"""Vector steps each env takes before the first round, by default (its processes page
their scenes' memory in; a training run's steady state)."""

MAX_TURN_STEPS = 100_000
"""Largest ``--turn-steps`` and ``--warmup-steps`` (their actions are drawn at once:
bounded memory)."""

FIGURES = (("2", "2 envs"), ("2same", "2 envs, SAME_STEP"), ("1", "1 env"))
"""Each checkout's figures: key, label."""


def serve(warmup_steps: int) -> None:
    """A child: this interpreter's vector envs, stepped on command. Reads lines ``KEY N``
    (N vector steps of figure KEY) from stdin and answers each with a JSON line, the
    seconds taken; ``quit`` or the end of stdin ends it. Ignores Ctrl-C: the parent
    reports what was finished, then ends it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    import gymnasium as gym
    import numpy as np
    from gymnasium.vector import AutoresetMode

    import tfalda_sim  # noqa: F401  (registers TfaldaTrack-v0)

    envs = {"2": gym.make_vec("TfaldaTrack-v0", num_envs=2),
            "2same": gym.make_vec("TfaldaTrack-v0", num_envs=2,
                                  autoreset_mode=AutoresetMode.SAME_STEP),
            "1": gym.make_vec("TfaldaTrack-v0", num_envs=1)}
    steppers = {key: env.step_per_env if key == "2same" else env.step
                for key, env in envs.items()}
    rngs = {key: np.random.default_rng(k) for k, key in enumerate(envs)}
    try:
        for key, env in envs.items():
            env.reset(seed=0)
            for action in rngs[key].uniform(-1.0, 1.0, (warmup_steps, *env.action_space.shape)):
                steppers[key](action.astype(np.float32))
        print(json.dumps({"ready": True}), flush=True)
        for line in sys.stdin:
            key, _, count = line.partition(" ")
            if key == "quit":
                break
            env, step = envs[key], steppers[key]
            actions = rngs[key].uniform(-1.0, 1.0, (int(count), *env.action_space.shape)
                                        ).astype(np.float32)
            t0 = time.perf_counter()
            for action in actions:
                step(action)
            print(json.dumps({"seconds": time.perf_counter() - t0}), flush=True)
    finally:
        for env in envs.values():
            env.close()


def _quartiles(values: list[float]) -> list[float]:
    import numpy as np
    return [float(q) for q in np.percentile(values, [25, 50, 75])] if values else []


def run(other: str, rounds: int, turn_steps: int, warmup_steps: int, quiet: bool
        ) -> dict[str, Any]:
    script = Path(__file__).resolve()
    seconds = {side: {key: 0.0 for key, _ in FIGURES} for side in ("this", "other")}
    per_round: dict[str, list[float]] = {key: [] for key, _ in FIGURES}
    done = 0
    children: dict[str, _TurnChild] = {}
    interrupted = False
    try:
        args = (CHILD_FLAG, str(warmup_steps))
        children["this"] = _TurnChild(sys.executable, 0, "this", script, args)
        children["other"] = _TurnChild(other, 0, "other", script, args)
        while done < rounds:
            order = ("this", "other") if done % 2 == 0 else ("other", "this")
            took: dict[str, dict[str, float]] = {side: {} for side in order}
            for key, _ in FIGURES:
                for side in order:
                    took[side][key] = children[side].ask(key, turn_steps)["seconds"]
            for key, _ in FIGURES:  # counted once the whole round is done
                for side in order:
                    seconds[side][key] += took[side][key]
                per_round[key].append(took["other"][key] / took["this"][key])
            done += 1
            if not quiet:
                print(f"round {done}/{rounds}", file=sys.stderr)
    except KeyboardInterrupt:
        interrupted = True  # the rounds finished so far are reported
    finally:
        for child in children.values():
            child.close()
    figures: dict[str, dict[str, float]] = {}
    for side in ("this", "other"):
        figures[side] = {}
        for key, _ in FIGURES:
            envs = 1 if key == "1" else 2
            took_s = seconds[side][key]
            figures[side][key] = envs * turn_steps * done / took_s if took_s else float("nan")
        figures[side]["2/1"] = figures[side]["2"] / figures[side]["1"]
    return {"machine": host(), "other_python": other,
            "rounds": done, "turn_steps": turn_steps, "warmup_steps": warmup_steps,
            "figures": {key: label for key, label in FIGURES},
            "this": figures["this"], "other": figures["other"],
            "ratio": {key: figures["this"][key] / figures["other"][key]
                      for key in figures["this"]},
            "per_round_ratio_quartiles": {key: _quartiles(v) for key, v in per_round.items()},
            "interrupted": interrupted}


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == [CHILD_FLAG]:
        serve(int(argv[1]))
        return 0
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--other", required=True,
                        help="the Python of the other checkout's environment")
    parser.add_argument("--rounds", type=int, default=40, help="rounds of turns")
    parser.add_argument("--turn-steps", type=int, default=1500,
                        help="vector steps of each figure per turn")
    parser.add_argument("--warmup-steps", type=int, default=WARMUP_STEPS,
                        help="vector steps of each env before the first round")
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    args = parser.parse_args(argv)
    if not 0 <= args.warmup_steps <= MAX_TURN_STEPS:
        parser.error(f"--warmup-steps must be in 0…{MAX_TURN_STEPS}, got {args.warmup_steps}")
    if args.rounds < 1:
        parser.error(f"--rounds must be ≥ 1, got {args.rounds}")
    if not 1 <= args.turn_steps <= MAX_TURN_STEPS:
        parser.error(f"--turn-steps must be in 1…{MAX_TURN_STEPS}, got {args.turn_steps}")
    if not (os.path.isfile(args.other) and os.access(args.other, os.X_OK)):
        parser.error(f"--other {args.other!r} is not an executable file: give the other "
                     "checkout's Python, e.g. /path/to/checkout/.venv/bin/python")
    try:
        result = run(args.other, args.rounds, args.turn_steps, args.warmup_steps,
                     quiet=args.json)
    except RuntimeError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    status = _status(result, args.json, f"{result['rounds']} of {args.rounds} rounds")
    if args.json:
        return status
    print(f"machine: {result['machine']['cores']} cores of {result['machine']['cpu']}; "
          f"{result['rounds']} rounds of {args.turn_steps} vector steps a figure; "
          f"other: {args.other}")
    print(f"{'figure [env steps/s]':<24}{'other':>10}{'this':>10}{'this/other':>12}"
          f"{'  per round (quartiles)':<26}")
    for key, label in (*FIGURES, ("2/1", "2 envs / 1 env")):
        q = result["per_round_ratio_quartiles"].get(key)
        spread = f"  {q[0]:.3f} {q[1]:.3f} {q[2]:.3f}" if q else ""
        print(f"{label:<24}{result['other'][key]:>10.2f}{result['this'][key]:>10.2f}"
              f"{result['ratio'][key]:>12.3f}{spread}")
    return status


if __name__ == "__main__":
    sys.exit(main())
