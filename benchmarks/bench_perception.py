"""Benchmark of TFALDA + LIS and of the Hough baseline per frame, on one core.

    python benchmarks/bench_perception.py [--frames 2000] [--json]

Frames are rendered first (not timed) along the right lane of three named tracks and two
generated ones, then fed to ``TfaldaDetector.process`` in order, as a drive would.
Presets: the thesis ("all on"), without the LIS, and the improved one with two and three
ROI rows; the Hough baseline with the seed's numbers and with the simulator preset (the
seed's numbers find no rendered marking, so they time an almost empty pipeline). The
process is pinned to one CPU and OpenCV to one thread. Target: thesis preset
≤ 0.5 ms median per frame.
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

from tfalda_sim.perception import DetectorConfig, HoughConfig, HoughDetector, TfaldaDetector
from tfalda_sim.rendering import Effects, Renderer, build_scene
from tfalda_sim.tracks import generate, load_named


def _frames(n: int, quiet: bool) -> list[np.ndarray]:
    renderer = Renderer()
    tracks = [load_named("oval"), load_named("thesis"), load_named("figure-eight"),
              generate(3), generate(11)]
    per = max(1, n // len(tracks))
    frames = []
    rng = np.random.default_rng(0)
    for track in tqdm(tracks, desc="rendering", disable=quiet, file=sys.stderr):
        scene = build_scene(track, Effects(), rng)
        s = np.arange(per) * 0.03 + 0.3  # 1.5 m/s at 50 frames/s
        s = s % track.length_m if track.closed else np.minimum(s, track.length_m - 1.5)
        x, y, h = track.pose(s, -0.5 * track.lane_width_m)
        frames += [renderer.render(scene, (float(a), float(b), float(c)), frame_seed=k)
                   for k, (a, b, c) in enumerate(zip(x, y, h, strict=True))]
    return frames


def run(n: int, quiet: bool) -> dict[str, object]:
    pin_to_one_core()
    frames = _frames(n, quiet)
    presets: dict[str, Callable[[], Callable[[np.ndarray], object]]] = {
        "thesis": lambda: TfaldaDetector(DetectorConfig.thesis()).process,
        "without LIS": lambda: TfaldaDetector(DetectorConfig.without_lis()).process,
        "improved (2 rows)": lambda: TfaldaDetector(DetectorConfig.improved()).process,
        "improved (3 rows)": lambda: TfaldaDetector(DetectorConfig.improved(3)).process,
        "Hough (seed values)": lambda: HoughDetector(HoughConfig()).detect,
        "Hough (simulator)": lambda: HoughDetector(HoughConfig.simulator()).detect,
    }
    results = {}
    for name, make in presets.items():
        make()(frames[0])  # JIT warm-up
        process = make()
        times = []
        for frame in tqdm(frames, desc=name, disable=quiet, file=sys.stderr):
            t0 = time.perf_counter()
            process(frame)
            times.append(time.perf_counter() - t0)
        ms = 1000 * np.array(times)
        results[name] = {"median_ms": float(np.median(ms)), "p95_ms": float(np.percentile(ms, 95)),
                         "frames_per_s": float(1000 / np.median(ms)), "frames": len(ms)}
    return {"machine": machine(),
            "presets": results}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=2000, help="frames per preset")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    if args.frames < 1:
        parser.error("--frames must be ≥ 1")
    result = run(args.frames, quiet=args.json)
    if args.json:
        print(json.dumps(result))
        return 0
    m = result["machine"]
    print(f"machine: {m['cores']} cores of {m['cpu']} ({m['simd']}), pinned to one, "
          f"OpenCV threads {m['opencv_threads']}")
    print(f"{'preset':<22}{'median':>10}{'p95':>10}{'frames/s':>10}")
    for name, r in result["presets"].items():
        print(f"{name:<22}{r['median_ms']:>8.3f}ms{r['p95_ms']:>8.3f}ms{r['frames_per_s']:>10.0f}")
    print("target: thesis preset ≤ 0.5 ms median per frame (≥ 2000 frames/s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
