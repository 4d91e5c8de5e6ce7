"""Benchmark of TFALDA's candidate search against its previous implementation, one core.

    python benchmarks/bench_candidates.py [--rois 400] [--repeat 20] [--json]

The ROIs of rendered frames (the thesis' four, along the right lane of the oval and two
generated tracks) are pre-processed as the detector does (resample, Sobel); then both
kernels search the same gradient images: the current ``search_candidates`` (row additions
padded to whole SIMD blocks) on int32 images, the same on uint16 images (what the detector
runs when every sum fits 16 bits, as for the thesis' ROIs: twice the lanes per vector) and
the previous one (issue 4's, kept below as the same-run reference: unpadded rows whose
rests ran as scalar code). All must give the same candidates. Reported: µs per ROI, the
ratios old/new, and the work against one core's SIMD:
the useful int32 additions ``Σ n·m`` (n samples of m starts per end offset), the ones
executed with padding, and the additions per ns that makes.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np
from _machine import machine, pin_to_one_core
from numba import njit

from tfalda_sim.perception import DetectorConfig
from tfalda_sim.perception.candidates import (
    SIMD_BLOCK,
    UINT16_MAX_SAMPLES,
    preprocess,
    search_candidates,
)
from tfalda_sim.perception.rois import initial_rois, windows
from tfalda_sim.rendering import Effects, Renderer, build_scene
from tfalda_sim.tracks import generate, load_named


@njit(cache=True, error_model="numpy")
def previous_search_candidates(flat: np.ndarray, height: int, width: int,
                               best_i: np.ndarray, best_end: np.ndarray,
                               sums: np.ndarray) -> None:
    """The candidate search before issue 18 (commit 1586277), unchanged: the reference."""
    w = width
    for x in range(w):
        best_i[x] = 0
        best_end[x] = 0
    dy = height - 1
    for dx in range(-(w - 1), w):
        adx = abs(dx)
        n = max(adx, dy) + 1
        lo = max(0, -dx)
        m = min(w, w - dx) - lo
        acc = sums[:m]
        acc[:] = 0
        den = 2 * (n - 1)
        ox = 0
        y = 0
        rx = n - 1
        ry = n - 1
        for i in range(n):
            if i > 0:
                rx += 2 * adx
                if rx >= den:
                    rx -= den
                    ox += 1
                ry += 2 * dy
                if ry >= den:
                    ry -= den
                    y += 1
            start = y * w + (lo + ox if dx >= 0 else lo - ox)
            seg = flat[start:start + m]
            for k in range(m):
                acc[k] += seg[k]
        for k in range(m):
            x = lo + k
            gt = np.int32(acc[k] > best_i[x])
            best_i[x] = best_i[x] + gt * (acc[k] - best_i[x])
            best_end[x] = best_end[x] + gt * (x + dx - best_end[x])


def additions(height: int, width: int) -> tuple[int, int]:
    """(useful, executed) int32 additions of one search on a height × width image."""
    useful = executed = 0
    for dx in range(-(width - 1), width):
        n = max(abs(dx), height - 1) + 1
        m = width - abs(dx)
        useful += n * m
        executed += n * (-(-m // SIMD_BLOCK) * SIMD_BLOCK)
    return useful, executed


def gradients(n: int) -> list[np.ndarray]:
    """Pre-processed ROIs (uint8 gradient images) of rendered frames."""
    config = DetectorConfig.thesis()
    rois = windows(initial_rois(config.layout))
    renderer = Renderer()
    tracks = [load_named("oval"), generate(3), generate(11)]
    frames_per = max(1, -(-n // (len(rois) * len(tracks))))
    out = []
    for track in tracks:
        scene = build_scene(track, Effects(), np.random.default_rng(0))
        s = (np.arange(frames_per) * 0.2 + 0.3) % track.length_m
        xs, ys, hs = track.pose(s, -0.5 * track.lane_width_m)
        for k, pose in enumerate(zip(xs, ys, hs, strict=True)):
            crops = renderer.render_windows(scene, tuple(map(float, pose)), rois, frame_seed=k)
            out += [preprocess(c, config.tfalda, False) for c in crops]
    return out[:n]


def run(n: int, repeat: int) -> dict[str, object]:
    pin_to_one_core()
    grads = gradients(n)
    def padded(dtype: type) -> list[tuple[np.ndarray, int, int, np.ndarray, np.ndarray]]:
        """(flat padded image of ``dtype``, height, width, best_i, best_end) per ROI."""
        out = []
        for g in grads:
            h, w = g.shape
            flat = np.zeros(h * w + SIMD_BLOCK, dtype)
            flat[:h * w] = g.ravel()
            out.append((flat, h, w, np.empty(w, np.int32), np.empty(w, np.int32)))
        return out

    inputs = padded(np.int32)
    inputs16 = padded(np.uint16)
    assert max(max(h, w) for _, h, w, _, _ in inputs16) <= UINT16_MAX_SAMPLES

    def time_kernel(kernel, inputs=inputs, dtype=np.int32
                    ) -> tuple[float, list[tuple[np.ndarray, np.ndarray]]]:
        """Best time per ROI over ``repeat`` passes, and the results."""
        scratch = np.empty(max(w for _, _, w, _, _ in inputs) + SIMD_BLOCK, dtype)
        for flat, h, w, bi, be in inputs:  # warm-up (JIT)
            kernel(flat, h, w, bi, be, scratch)
        best = np.inf
        for _ in range(repeat):
            t0 = time.perf_counter()
            for flat, h, w, bi, be in inputs:
                kernel(flat, h, w, bi, be, scratch)
            best = min(best, time.perf_counter() - t0)
        return best / len(inputs), [(bi.copy(), be.copy()) for *_, bi, be in inputs]

    t_old, r_old = time_kernel(previous_search_candidates)
    t_new, r_new = time_kernel(search_candidates)
    t_16, r_16 = time_kernel(search_candidates, inputs16, np.uint16)
    same = all(np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
               for new in (r_new, r_16) for a, b in zip(new, r_old, strict=True))
    useful = sum(additions(h, w)[0] for _, h, w, _, _ in inputs) / len(inputs)
    executed = sum(additions(h, w)[1] for _, h, w, _, _ in inputs) / len(inputs)
    sizes = sorted({(h, w) for _, h, w, _, _ in inputs})
    return {"machine": machine(), "rois": len(inputs), "repeat": repeat,
            "roi_sizes_resampled": [list(s) for s in sizes],
            "identical_results": same,
            "previous_us_per_roi": t_old * 1e6, "current_us_per_roi": t_new * 1e6,
            "current_uint16_us_per_roi": t_16 * 1e6,
            "speed_up": t_old / t_new, "speed_up_uint16": t_old / t_16,
            "useful_additions_per_roi": useful, "executed_additions_per_roi": executed,
            "useful_additions_per_ns_previous": useful / (t_old * 1e9),
            "useful_additions_per_ns_current": useful / (t_new * 1e9),
            "useful_additions_per_ns_uint16": useful / (t_16 * 1e9),
            "executed_additions_per_ns_current": executed / (t_new * 1e9)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rois", type=int, default=400, help="ROIs searched per timing")
    parser.add_argument("--repeat", type=int, default=20, help="timings (best one kept)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    if args.rois < 1 or args.repeat < 1:
        parser.error("--rois and --repeat must be ≥ 1")
    r = run(args.rois, args.repeat)
    if args.json:
        print(json.dumps(r))
        return 0 if r["identical_results"] else 1
    m = r["machine"]
    print(f"machine: {m['cores']} cores, pinned to one; {r['rois']} ROIs, resampled sizes "
          f"(h, w) {r['roi_sizes_resampled'][0]}…{r['roi_sizes_resampled'][-1]}")
    print(f"{'kernel':<34}{'µs/ROI':>9}{'adds/ns':>9}")
    print(f"{'previous (issue 4, reference)':<34}{r['previous_us_per_roi']:>9.1f}"
          f"{r['useful_additions_per_ns_previous']:>9.2f}")
    print(f"{'current (padded SIMD blocks)':<34}{r['current_us_per_roi']:>9.1f}"
          f"{r['useful_additions_per_ns_current']:>9.2f}")
    print(f"{'current, uint16 (the detector)':<34}{r['current_uint16_us_per_roi']:>9.1f}"
          f"{r['useful_additions_per_ns_uint16']:>9.2f}")
    print(f"speed-up {r['speed_up']:.2f}× (uint16 {r['speed_up_uint16']:.2f}×), results "
          f"identical: {r['identical_results']}")
    print(f"additions per ROI: {r['useful_additions_per_roi']:.0f} useful, "
          f"{r['executed_additions_per_roi']:.0f} executed with padding "
          f"({r['executed_additions_per_ns_current']:.2f} per ns)")
    return 0 if r["identical_results"] else 1


if __name__ == "__main__":
    sys.exit(main())
