"""Benchmark of ``env.reset()``: a reset onto a new generated track, with the scene
painted lazily (the env's default) and eagerly (the whole marking map and mip atlas at
reset: the previous implementation, the same-run reference), and a reset on a fixed
track; "lanes" mode, first observation included, one core.

    python benchmarks/bench_reset.py [--resets 200] [--json]

Prints a table (or one JSON object with ``--json``). The kinds are measured in turns, in
the same run, so a busy machine slows them alike; eager/lazy is the ratio of the medians.
Target: a reset onto a new generated track ≤ 5 ms median.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable

import numpy as np
from _machine import machine, pin_to_one_core
from tqdm import tqdm

from tfalda_sim.envs.tfalda_track import TfaldaTrackEnv
from tfalda_sim.rendering import Effects, Scene, build_scene
from tfalda_sim.tracks import Track

EAGER_SEED_OFFSET: int = 1_000_000
"""The eager env resets from other seeds, so that no cache filled by the lazy env's
track (the spatial index) helps it."""


class _EagerEnv(TfaldaTrackEnv):
    """The env with the eager scene: the whole map rasterised and mipmapped at reset."""

    def _build_scene(self, track: Track, effects: Effects, scene_seed: int,
                     reuse: Scene | None = None) -> Scene:
        # An eager scene takes no memory over (``reuse`` is for lazy ones).
        return build_scene(track, effects, np.random.default_rng(scene_seed), lazy=False)


def _ms(samples: list[float]) -> dict[str, float]:
    arr = np.array(samples) * 1000.0
    return {"median_ms": float(np.median(arr)), "p95_ms": float(np.percentile(arr, 95)),
            "max_ms": float(arr.max())}


def run(resets: int, quiet: bool) -> dict[str, object]:
    pin_to_one_core()
    kinds: dict[str, tuple[TfaldaTrackEnv, int]] = {
        "fixed track (seed 7)": (TfaldaTrackEnv(track=7), 0),
        "new track, lazy scene": (TfaldaTrackEnv(), 0),
        "new track, eager scene": (_EagerEnv(), EAGER_SEED_OFFSET),
        "new track, lazy, image mode": (TfaldaTrackEnv(observation="image"), 2 * EAGER_SEED_OFFSET),
    }
    for env, offset in kinds.values():  # compile and fill the caches of the first reset
        env.reset(seed=offset)
    times: dict[str, list[float]] = {name: [] for name in kinds}
    resets_of: list[tuple[str, Callable[[int], object]]] = [
        (name, lambda s, env=env, offset=offset: env.reset(seed=offset + s))
        for name, (env, offset) in kinds.items()]
    for seed in tqdm(range(1, resets + 1), desc="reset", disable=quiet, file=sys.stderr):
        for name, reset in resets_of:
            t0 = time.perf_counter()
            reset(seed)
            times[name].append(time.perf_counter() - t0)
    result = {name: {"resets": resets, **_ms(t)} for name, t in times.items()}
    lazy = result["new track, lazy scene"]["median_ms"]
    eager = result["new track, eager scene"]["median_ms"]
    return {"machine": machine(), "reset": result, "eager_over_lazy": eager / lazy}


def print_table(r: dict) -> None:
    m = r["machine"]
    print(f"machine: {m['cores']} cores of {m['cpu']} ({m['simd']}; pinned to one), "
          f"Python {m['python']}")
    print(f"{'env.reset() (lanes mode)':<32}{'median':>10}{'p95':>10}{'max':>10}")
    for name, t in r["reset"].items():
        print(f"{name:<32}{t['median_ms']:>8.2f}ms{t['p95_ms']:>8.2f}ms{t['max_ms']:>8.2f}ms")
    print(f"eager / lazy (medians): {r['eager_over_lazy']:.1f}×  (target: lazy ≤ 5 ms)")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resets", type=int, default=200, help="resets of each kind")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    result = run(args.resets, quiet=args.json)
    if args.json:
        print(json.dumps(result))
    else:
        print_table(result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
