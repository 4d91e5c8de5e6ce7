"""Benchmark of TfaldaTrack-v0: env steps per second, one env, one core, random policy.

    python benchmarks/bench_env.py [--steps 3000] [--json]

Runs ``gymnasium.make("TfaldaTrack-v0")`` in the "lanes" (ROIs rendered on demand +
TFALDA + LIS) and "image" (full frame + TFALDA + LIS) modes with uniformly random
actions, resets included (episodes end quickly with random steering: the car leaves
the road). Two track set-ups: one fixed track (the oval: a reset re-uses its scene) and
the default, a new generated track every reset (track generation and scene building,
≈ 0.1 s, dominate there). In the same run, Gymnasium's CarRacing-v3 as the reference, if
Box2D is installed (``pip install "gymnasium[box2d]"``). Targets (issue 6): ≥ 1000 steps/s
in "lanes" mode, ≥ 400 in "image" mode.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import gymnasium as gym
from _machine import machine, pin_to_one_core
from tqdm import tqdm

import tfalda_sim  # noqa: F401  (registers TfaldaTrack-v0)


def steps_per_second(env: gym.Env, steps: int, desc: str, quiet: bool) -> dict[str, float]:
    """Random-policy steps/s over ``steps`` steps (resets included, after a warm-up)."""
    env.action_space.seed(0)
    env.reset(seed=0)
    for _ in range(20):  # warm caches and JIT
        env.step(env.action_space.sample())
    env.reset(seed=1)
    resets = 0
    t0 = time.perf_counter()
    for _ in tqdm(range(steps), desc=desc, disable=quiet, file=sys.stderr):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()
            resets += 1
    elapsed = time.perf_counter() - t0
    env.close()
    return {"steps_per_s": steps / elapsed, "ms_per_step": 1000 * elapsed / steps,
            "episodes": resets + 1}


def run(steps: int, quiet: bool) -> dict[str, object]:
    pin_to_one_core()
    results: dict[str, dict[str, float] | str] = {}
    for mode in ("lanes", "image"):
        results[f"{mode}, fixed track (oval)"] = steps_per_second(
            gym.make("TfaldaTrack-v0", observation=mode, track="oval"), steps,
            f"{mode}/oval", quiet)
        results[f"{mode}, new generated track per reset"] = steps_per_second(
            gym.make("TfaldaTrack-v0", observation=mode), steps, f"{mode}/generated", quiet)
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")  # CarRacing draws with pygame
    try:
        car_racing = gym.make("CarRacing-v3")
    except Exception as exc:
        results["CarRacing-v3 (reference)"] = f"not available: {type(exc).__name__}: {exc}"
    else:
        results["CarRacing-v3 (reference)"] = steps_per_second(
            car_racing, min(steps, 2000), "CarRacing-v3", quiet)
    return {"machine": machine(), "steps": steps, "envs": results}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=3000, help="steps per configuration")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    if args.steps < 1:
        parser.error("--steps must be ≥ 1")
    result = run(args.steps, quiet=args.json)
    if args.json:
        print(json.dumps(result))
        return 0
    m = result["machine"]
    print(f"machine: {m['cores']} cores, pinned to one, OpenCV threads {m['opencv_threads']}")
    print(f"{'configuration':<40}{'steps/s':>10}{'ms/step':>10}{'episodes':>10}")
    for name, r in result["envs"].items():  # type: ignore[union-attr]
        if isinstance(r, str):
            print(f"{name:<40}{r}")
        else:
            print(f"{name:<40}{r['steps_per_s']:>10.0f}{r['ms_per_step']:>10.3f}"
                  f"{r['episodes']:>10.0f}")
    print("targets: ≥ 1000 steps/s in lanes mode, ≥ 400 in image mode")
    return 0


if __name__ == "__main__":
    sys.exit(main())
