"""Benchmark of the renderer: full frames and the four default ROIs, on one core.

    python benchmarks/bench_render.py [--frames 1500] [--json]

Frames are rendered along the right lane's ideal line of several tracks (named and
generated, obstacles included), as a drive would: once as full frames (the env's "image"
mode), once as the four thesis ROIs only (its "lanes" mode). The process is pinned to one CPU and
OpenCV to one thread. Targets: full frame ≤ 1.0 ms median; the four ROIs
≥ 5× faster than the full frame.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np
from _machine import machine, pin_to_one_core
from tqdm import tqdm

from tfalda_sim.rendering import DomainRandomization, Effects, Renderer, build_scene
from tfalda_sim.tracks import generate, load_named

THESIS_ROIS = [(195, 260, 150, 75), (365, 260, 150, 75), (80, 340, 180, 85), (429, 340, 180, 85)]
"""Initial ROIs of thesis table 2.4: (x, y, width, height) [px]."""


def _poses(track, n: int) -> list[tuple[float, float, float]]:
    total = track.length_m
    s = np.linspace(0.3, total - 0.3 if not track.closed else total, n, endpoint=False)
    x, y, h = track.pose(s, -0.5 * track.lane_width_m)
    return [(float(a), float(b), float(c)) for a, b, c in zip(x, y, h, strict=True)]


def run(frames: int, quiet: bool) -> dict[str, object]:
    pin_to_one_core()
    renderer = Renderer()
    tracks = [load_named("oval"), load_named("figure-eight"), generate(3), generate(5),
              generate(11)]
    variants = {
        "default": lambda rng: Effects(),
        "off": lambda rng: Effects.off(),
        "randomized": lambda rng: DomainRandomization().sample(rng),
    }
    results: dict[str, dict[str, float]] = {}
    rng = np.random.default_rng(0)
    per_track = max(1, frames // len(tracks))
    for name, make in variants.items():
        full_t, roi_t, moving_t = [], [], []
        for track in tqdm(tracks, desc=name, disable=quiet, file=sys.stderr):
            scene = build_scene(track, make(rng), rng)
            poses = _poses(track, per_track)
            renderer.render(scene, poses[0], speed_m_s=2.0)  # warm caches and JIT
            renderer.render_windows(scene, poses[0], THESIS_ROIS, speed_m_s=2.0)
            # Two separate drives, as the env runs them: full frames ("image" mode) and
            # only the ROIs ("lanes" mode, perception reads nothing else).
            for i, pose in enumerate(poses):
                t0 = time.perf_counter()
                renderer.render(scene, pose, speed_m_s=2.0, frame_seed=i)
                full_t.append(time.perf_counter() - t0)
            for i, pose in enumerate(poses):
                t0 = time.perf_counter()
                renderer.render_windows(scene, pose, THESIS_ROIS, speed_m_s=2.0, frame_seed=i)
                roi_t.append(time.perf_counter() - t0)
            # In a drive the LIS moves the ROIs every frame: new windows, nothing cached.
            shifts = rng.integers(-40, 41, size=(len(poses), len(THESIS_ROIS)))
            for i, pose in enumerate(poses):
                wins = [(x + int(dx), y, w, h)
                        for (x, y, w, h), dx in zip(THESIS_ROIS, shifts[i], strict=True)]
                t0 = time.perf_counter()
                renderer.render_windows(scene, pose, wins, speed_m_s=2.0, frame_seed=i)
                moving_t.append(time.perf_counter() - t0)
        full_ms, roi_ms = 1000 * np.median(full_t), 1000 * np.median(roi_t)
        results[name] = {"full_frame_median_ms": float(full_ms),
                         "full_frame_p95_ms": float(1000 * np.percentile(full_t, 95)),
                         "rois_median_ms": float(roi_ms), "roi_speedup": float(full_ms / roi_ms),
                         "moving_rois_median_ms": float(1000 * np.median(moving_t)),
                         "frames": len(full_t)}
    return {"machine": machine(),
            "effects": results}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=1500, help="frames per effects variant")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    result = run(args.frames, quiet=args.json)
    if args.json:
        print(json.dumps(result))
        return 0
    m = result["machine"]
    print(f"machine: {m['cores']} cores of {m['cpu']} ({m['simd']}), pinned to one, "
          f"OpenCV threads {m['opencv_threads']}")
    print(f"{'effects':<12}{'full median':>13}{'full p95':>11}{'4 ROIs':>10}{'speed-up':>10}"
          f"{'moving ROIs':>13}")
    for name, r in result["effects"].items():
        print(f"{name:<12}{r['full_frame_median_ms']:>11.3f}ms{r['full_frame_p95_ms']:>9.3f}ms"
              f"{r['rois_median_ms']:>8.3f}ms{r['roi_speedup']:>9.1f}×"
              f"{r['moving_rois_median_ms']:>11.3f}ms")
    print("targets: full frame ≤ 1.0 ms median (default effects); ROIs ≥ 5× faster")
    return 0


if __name__ == "__main__":
    sys.exit(main())
