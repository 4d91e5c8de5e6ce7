"""Benchmark of TfaldaTrack-v0: env steps per second against CarRacing-v3, one run.

    python benchmarks/bench_env.py [--steps 3000] [--json]

In one run, with uniformly random actions and resets included (random steering leaves the
road every ≈ 50 steps, so a reset's cost counts):

- Gymnasium's CarRacing-v3, the reference every other figure is divided by (this VM's
  speed drifts by 2× within a day; the ratio does not);
- ``gymnasium.make("TfaldaTrack-v0")`` in "lanes" mode (ROIs rendered on demand + TFALDA +
  LIS) and "image" mode (full frame + TFALDA + LIS), on one fixed track (the oval: a reset
  re-uses its scene) and with the default, a new generated track every reset;
- ``gymnasium.make_vec("TfaldaTrack-v0", num_envs=N)`` for N = 1 and 2 (the env's default
  vectorisation mode) and, for comparison, Gymnasium's ``AsyncVectorEnv`` with 2 envs, in
  "lanes" mode on default generated tracks; steps are env steps (N per vector step).

Single envs run pinned to one core with OpenCV on one thread (figures per core); the vector
envs get every core of the machine. A mode's fixed-track and generated-track envs run
interleaved, in chunks of ``CHUNK_STEPS`` steps each in turn, so that the host's drift
(± 10 % between runs a minute apart here) does not enter their ratio. Needs Box2D for the reference
(``pip install "gymnasium[box2d]"``, in the ``dev`` extra).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Callable
from typing import Any

import cv2
import gymnasium as gym
import numpy as np
from _machine import machine
from tqdm import tqdm

import tfalda_sim  # noqa: F401  (registers TfaldaTrack-v0)

REFERENCE = "CarRacing-v3 (reference)"
WARMUP_STEPS = 20  # JIT compilation, caches


def steps_per_second(env: gym.Env, steps: int, desc: str, quiet: bool) -> dict[str, float]:
    """Random-policy steps/s of one env over ``steps`` steps (resets included; warmed up
    first, then stepped from ``reset(seed=1)``)."""
    return interleaved_steps_per_second({desc: lambda: env}, steps, quiet)[desc]


CHUNK_STEPS = 300
"""Steps per turn when single envs run interleaved (``interleaved_steps_per_second``)."""


def interleaved_steps_per_second(makes: dict[str, Callable[[], gym.Env]], steps: int,
                                 quiet: bool) -> dict[str, dict[str, float]]:
    """Random-policy steps/s of several envs at once (resets included): each warmed up by
    ``WARMUP_STEPS`` steps, reset with seed 1, then all stepped in turns of
    ``CHUNK_STEPS`` steps until each has made ``steps``; an env's time is the sum of its
    turns."""
    envs = {name: make() for name, make in makes.items()}
    clock = dict.fromkeys(envs, 0.0)
    resets = dict.fromkeys(envs, 0)
    try:
        for env in envs.values():
            env.action_space.seed(0)
            env.reset(seed=0)
            for _ in range(WARMUP_STEPS):
                env.step(env.action_space.sample())
            env.reset(seed=1)
        with tqdm(total=steps * len(envs), desc=" + ".join(envs), disable=quiet,
                  file=sys.stderr) as bar:
            for start in range(0, steps, CHUNK_STEPS):
                n = min(CHUNK_STEPS, steps - start)
                for name, env in envs.items():
                    t0 = time.perf_counter()
                    for _ in range(n):
                        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
                        if terminated or truncated:
                            env.reset()
                            resets[name] += 1
                    clock[name] += time.perf_counter() - t0
                    bar.update(n)
    finally:
        for env in envs.values():
            env.close()
    return {name: {"steps_per_s": steps / clock[name], "ms_per_step": 1000 * clock[name] / steps,
                   "episodes": resets[name] + 1} for name in envs}


def vector_steps_per_second(make: Callable[[], gym.vector.VectorEnv], steps: int, desc: str,
                            quiet: bool) -> dict[str, float]:
    """Env steps/s of a vector env (autoreset inside) over about ``steps`` env steps."""
    venv = make()
    try:
        n = venv.num_envs
        venv.action_space.seed(0)
        venv.reset(seed=0)
        for _ in range(WARMUP_STEPS):
            venv.step(venv.action_space.sample())
        calls = max(1, steps // n)
        episodes = 0
        t0 = time.perf_counter()
        for _ in tqdm(range(calls), desc=desc, disable=quiet, file=sys.stderr):
            _, _, terminated, truncated, _ = venv.step(venv.action_space.sample())
            episodes += int(np.count_nonzero(terminated | truncated))
        elapsed = time.perf_counter() - t0
    finally:
        venv.close()
    return {"steps_per_s": calls * n / elapsed, "ms_per_step": 1000 * elapsed / (calls * n),
            "episodes": episodes}


def run(steps: int, quiet: bool) -> dict[str, Any]:
    all_cpus = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else None
    results: dict[str, dict[str, float] | str] = {}

    def one_core() -> None:  # per-core figures
        if all_cpus is not None:
            os.sched_setaffinity(0, {min(all_cpus)})
        cv2.setNumThreads(1)

    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")  # CarRacing draws with pygame
    one_core()
    try:
        results[REFERENCE] = steps_per_second(gym.make("CarRacing-v3"), min(steps, 2000),
                                              REFERENCE, quiet)
    except Exception as exc:  # the reference may be missing: say so in the table
        results[REFERENCE] = f"not available: {type(exc).__name__}: {exc}"
    for mode in ("lanes", "image"):
        results.update(interleaved_steps_per_second({
            f"{mode}, fixed track (oval)":
                lambda mode=mode: gym.make("TfaldaTrack-v0", observation=mode, track="oval"),
            f"{mode}, new generated track per reset":
                lambda mode=mode: gym.make("TfaldaTrack-v0", observation=mode)}, steps, quiet))
    if all_cpus is not None:  # the vector envs get the whole machine
        os.sched_setaffinity(0, all_cpus)
    for n in (1, 2):
        name = f"make_vec, {n} env{'s' if n > 1 else ''}, lanes, generated"
        results[name] = vector_steps_per_second(
            lambda n=n: gym.make_vec("TfaldaTrack-v0", num_envs=n), steps, name, quiet)
    name = "AsyncVectorEnv, 2 envs, lanes, generated"
    results[name] = vector_steps_per_second(
        lambda: gym.make_vec("TfaldaTrack-v0", num_envs=2, vectorization_mode="async"),
        steps, name, quiet)
    reference = results[REFERENCE]
    ref_rate = reference["steps_per_s"] if isinstance(reference, dict) else None
    for r in results.values():
        if isinstance(r, dict) and ref_rate:
            r["ratio_to_car_racing"] = r["steps_per_s"] / ref_rate
    scaling = {}
    one = results.get("make_vec, 1 env, lanes, generated")
    two = results.get("make_vec, 2 envs, lanes, generated")
    if isinstance(one, dict) and isinstance(two, dict):
        scaling["make_vec 2 envs / 1 env"] = two["steps_per_s"] / one["steps_per_s"]
    fixed = results.get("lanes, fixed track (oval)")
    generated = results.get("lanes, new generated track per reset")
    if isinstance(fixed, dict) and isinstance(generated, dict):
        scaling["generated / fixed track (lanes)"] = (generated["steps_per_s"]
                                                      / fixed["steps_per_s"])
    m = machine()
    m["pinned_to_one_core"] = "single envs only"
    return {"machine": m, "steps": steps, "envs": results, "ratios": scaling}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=3000, help="env steps per configuration")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    if args.steps < 1:
        parser.error("--steps must be ≥ 1")
    result = run(args.steps, quiet=args.json)
    if args.json:
        print(json.dumps(result))
        return 0
    m = result["machine"]
    print(f"machine: {m['cores']} cores (single envs pinned to one, OpenCV threads 1), "
          f"Python {m['python']}")
    print(f"{'configuration':<44}{'steps/s':>9}{'ms/step':>9}{'episodes':>9}"
          f"{'× CarRacing':>13}")
    for name, r in result["envs"].items():
        if isinstance(r, str):
            print(f"{name:<44}{r}")
        else:
            print(f"{name:<44}{r['steps_per_s']:>9.0f}{r['ms_per_step']:>9.3f}"
                  f"{r['episodes']:>9.0f}{r.get('ratio_to_car_racing', float('nan')):>12.2f}×")
    for name, ratio in result["ratios"].items():
        print(f"{name:<44}{ratio:>9.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
