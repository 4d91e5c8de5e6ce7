"""Side-by-side benchmark of this checkout against another one (issue 18: "≥ 2× the
previous step rate" needs the previous code measured in the same minutes, since this VM's
speed drifts by 2× within a day).

Both run at the same time, each pinned to one core, then swapped (pairs); each measures
"lanes" steps/s on a fixed track (the oval) and with a new generated track per reset
(random actions, resets included) and the median ``env.reset()`` onto a new track:

    python benchmarks/bench_ab.py --other /path/to/old/checkout/.venv/bin/python \\
        [--steps 3000] [--resets 150] [--pairs 2] [--json]

``--other``: the Python of the other checkout's environment (``make install`` there).
Needs two cores (one process per core); a table, or ``--json``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

CHILD_FLAG = "--child"


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
    return {"machine": {"cores": os.cpu_count(), "pinned_one_core_each": True},
            "other_python": other, "steps": steps, "resets": resets, "pairs": rows,
            "interrupted": interrupted}


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == [CHILD_FLAG]:
        core, steps, resets = (int(v) for v in argv[1:4])
        os.sched_setaffinity(0, {core})
        print(json.dumps(measure(steps, resets)))
        return 0
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--other", required=True,
                        help="the Python of the other checkout's environment")
    parser.add_argument("--steps", type=int, default=3000, help="steps per configuration")
    parser.add_argument("--resets", type=int, default=150, help="resets onto new tracks")
    parser.add_argument("--pairs", type=int, default=2, help="runs side by side (cores swapped)")
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    args = parser.parse_args(argv)
    for name in ("steps", "resets", "pairs"):
        if getattr(args, name) < 1:
            parser.error(f"--{name} must be ≥ 1, got {getattr(args, name)}")
    if not (os.path.isfile(args.other) and os.access(args.other, os.X_OK)):
        parser.error(f"--other {args.other!r} is not an executable file: give the other "
                     "checkout's Python, e.g. /path/to/checkout/.venv/bin/python")
    try:
        result = run(args.other, args.steps, args.resets, args.pairs, quiet=args.json)
    except RuntimeError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    status = 0
    if result["interrupted"]:
        print(f"interrupted: {len(result['pairs'])} of {args.pairs} pairs finished; "  # type: ignore[arg-type]
              "those are reported", file=sys.stderr)
        status = 130
    if args.json:
        print(json.dumps(result, indent=2))
        return status
    print(f"machine: {result['machine']['cores']} cores, one process pinned to each; "
          f"other: {args.other}")
    print(f"{'pair':<6}{'figure':<24}{'other':>10}{'this':>10}{'this/other':>12}")
    for row in result["pairs"]:  # type: ignore[union-attr]
        for key, label in (("fixed_steps_per_s", "fixed track [steps/s]"),
                           ("generated_steps_per_s", "generated [steps/s]"),
                           ("reset_median_ms", "reset median [ms]")):
            print(f"{row['pair']:<6}{label:<24}{row['other'][key]:>10.2f}"
                  f"{row['this'][key]:>10.2f}{row['ratio'][key]:>12.2f}")
    return status


if __name__ == "__main__":
    sys.exit(main())
