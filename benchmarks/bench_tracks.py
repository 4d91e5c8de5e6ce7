"""Benchmark of the track layer: generation, validation, rasterisation, reverse query.

    python benchmarks/bench_tracks.py [--seeds 1000] [--raster-seeds 50] [--json]

Prints a table (or one JSON object with ``--json``). JIT compilation is warmed up first
and not counted. Targets: generation < 50 ms median, rasterisation < 200 ms.
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
import time

import numpy as np
from _machine import host
from tqdm import tqdm

from tfalda_sim.tracks import generate, load_named, rasterize, validate


def _ms(samples: list[float]) -> dict[str, float]:
    arr = np.array(samples) * 1000.0
    return {"median_ms": float(np.median(arr)), "p95_ms": float(np.percentile(arr, 95)),
            "max_ms": float(arr.max())}


def run(seeds: int, raster_seeds: int, quiet: bool) -> dict[str, object]:
    warm = generate(0)  # compile the numba kernels before timing
    rasterize(warm)
    warm.locate(0.0, 0.0)

    gen_t, val_t, lengths, invalid = [], [], [], []
    for seed in tqdm(range(seeds), desc="generate", disable=quiet, file=sys.stderr):
        t0 = time.perf_counter()
        track = generate(seed)
        t1 = time.perf_counter()
        violations = validate(track)
        t2 = time.perf_counter()
        gen_t.append(t1 - t0)
        val_t.append(t2 - t1)
        lengths.append(track.length_m)
        if violations:
            invalid.append(seed)

    ras_t, mpix = [], []
    for seed in tqdm(range(raster_seeds), desc="rasterise", disable=quiet, file=sys.stderr):
        track = generate(seed)
        t0 = time.perf_counter()
        m = rasterize(track)
        ras_t.append(time.perf_counter() - t0)
        mpix.append(m.intensity.size / 1e6)

    locate = {}
    rng = np.random.default_rng(0)
    for name, track in (("oval", load_named("oval")), ("seed-3", generate(3))):
        s = rng.uniform(0, track.length_m, 20_000)
        pts = track.position(s, rng.uniform(-0.4, 0.4, s.size))
        t0 = time.perf_counter()
        for x, y in pts[:5000]:
            track.locate(float(x), float(y))
        single = (time.perf_counter() - t0) / 5000
        t0 = time.perf_counter()
        track.locate_many(pts)
        batch = (time.perf_counter() - t0) / len(pts)
        locate[name] = {"length_m": track.length_m, "segments": len(track.segments),
                        "locate_us": single * 1e6, "locate_many_us_per_point": batch * 1e6}

    return {
        "machine": {**host(), "processor": platform.processor() or platform.machine()},
        "generate": {"seeds": seeds, "invalid": invalid, **_ms(gen_t),
                     "median_length_m": statistics.median(lengths)},
        "validate": {**_ms(val_t)},
        "rasterize": {"seeds": raster_seeds, "resolution_mm": 4.0, **_ms(ras_t),
                      "median_megapixels": statistics.median(mpix)},
        "locate": locate,
    }


def print_table(r: dict) -> None:
    g, v, ra = r["generate"], r["validate"], r["rasterize"]
    m = r["machine"]
    print(f"machine: {m['cores']} cores of {m['cpu']} ({m['simd']}), Python {m['python']}")
    print(f"{'stage':<28}{'median':>10}{'p95':>10}{'max':>10}  note")
    print(f"{'generate (incl. checks)':<28}{g['median_ms']:>8.2f}ms{g['p95_ms']:>8.2f}ms"
          f"{g['max_ms']:>8.2f}ms  {g['seeds']} seeds, {len(g['invalid'])} invalid, "
          f"median length {g['median_length_m']:.1f} m (target < 50 ms)")
    print(f"{'validate':<28}{v['median_ms']:>8.2f}ms{v['p95_ms']:>8.2f}ms{v['max_ms']:>8.2f}ms")
    print(f"{'rasterize 4 mm/px':<28}{ra['median_ms']:>8.2f}ms{ra['p95_ms']:>8.2f}ms"
          f"{ra['max_ms']:>8.2f}ms  {ra['seeds']} tracks, median {ra['median_megapixels']:.1f} MPx"
          " (target < 200 ms)")
    for name, loc in r["locate"].items():
        print(f"{'locate ' + name:<28}{loc['locate_us']:>8.2f}us{'':>10}{'':>10}  "
              f"{loc['segments']} segments, {loc['length_m']:.1f} m; batch "
              f"{loc['locate_many_us_per_point']:.2f} us/point")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=1000, help="tracks to generate")
    parser.add_argument("--raster-seeds", type=int, default=50, help="tracks to rasterise")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    result = run(args.seeds, args.raster_seeds, quiet=args.json)
    if args.json:
        print(json.dumps(result))
    else:
        print_table(result)
    return 1 if result["generate"]["invalid"] else 0


if __name__ == "__main__":
    sys.exit(main())
