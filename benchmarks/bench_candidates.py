"""Benchmark of TFALDA's candidate search against its previous implementations, one core.

    python benchmarks/bench_candidates.py [--rois 400] [--repeat 20] [--json]

The ROIs of rendered frames (the thesis' four, along the right lane of the oval and two
generated tracks) are pre-processed as the detector does (resample, Sobel); then every
kernel searches the same gradient images, on int32 images and on uint16 ones (what the
detector runs when every sum fits 16 bits, as for the thesis' ROIs):

- the current ``search_candidates``: blocks of ``SIMD_BLOCK`` starts summed in vector
  registers over a segment's samples, offsets from a table per image height;
- the previous one (kept below as the same-run reference, commit b819aa8): a row
  addition through memory per sample, padded to whole blocks, with a DDA step;
- the first one (kept below, commit 1586277): unpadded row additions whose rests ran as
  scalar code.

All must give the same candidates. Reported: µs per ROI, the ratios to the current
kernel, and the work against one core's SIMD: the useful int32 additions ``Σ n·m``
(n samples of m starts per end offset), the ones executed with padding, and the
additions per ns that makes.

Then the detector's whole per-ROI path on the same crops (resize, Sobel, search, the
lane's choice): the current ``find_lane_in_crop`` (the resize in numba, one call) against
the previous one (``cv2.resize``, then ``find_lane``), which must pick the same lanes.
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
    find_lane,
    find_lane_in_crop,
    preprocess,
    resample,
    resample_shape,
    search_candidates,
    segment_steps,
)
from tfalda_sim.perception.rois import initial_rois, windows
from tfalda_sim.rendering import Effects, Renderer, build_scene
from tfalda_sim.tracks import generate, load_named


def row_search(block: int):  # type: ignore[no-untyped-def]  # a numba dispatcher
    """The candidate search before this one, unchanged, padded to ``block`` lanes: each
    sample a row addition through memory with a DDA step. ``block`` 1 is the first search
    (commit 1586277: the rows' rests ran as scalar code), ``SIMD_BLOCK`` the previous one
    (commit b819aa8). ``block`` is a constant of the compiled code, as it was."""

    @njit(error_model="numpy")
    def search(flat: np.ndarray, height: int, width: int, best_i: np.ndarray,
               best_end: np.ndarray, sums: np.ndarray) -> None:
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
            padded = (m + block - 1) // block * block
            acc = sums[:padded]
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
                seg = flat[start:start + padded]
                for k in range(padded):
                    acc[k] += seg[k]
            for k in range(m):
                x = lo + k
                gt = np.int32(acc[k] > best_i[x])
                best_i[x] = best_i[x] + gt * (acc[k] - best_i[x])
                best_end[x] = best_end[x] + gt * (x + dx - best_end[x])

    return search


previous_search_candidates = row_search(1)
row_search_candidates = row_search(SIMD_BLOCK)


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
    return [preprocess(c, config.tfalda, False) for c in roi_crops(n)]


def roi_crops(n: int) -> list[np.ndarray]:
    """ROI crops (uint8) of rendered frames: the thesis' four ROIs along the right lane of
    the oval and two generated tracks."""
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
            out += crops
    return out[:n]


def per_roi_paths(n: int, repeat: int) -> dict[str, object]:
    """The detector's per-ROI path, previous (``cv2.resize`` + ``find_lane``) and current
    (``find_lane_in_crop``), on ``n`` crops: best µs per ROI and whether the lanes agree."""
    tcfg = DetectorConfig.thesis().tfalda
    crops = roi_crops(n)
    args = (False, True, 120.0)  # vertical edges, rising edges, the ROI's x [px]
    lane = (False, 30.0, 5.0, 900.0, tcfg.kp, tcfg.kd, tcfg.ki)  # a later frame: λ decides

    def previous(crop: np.ndarray) -> tuple[float, ...]:
        small = resample(crop, tcfg)
        return find_lane(small, segment_steps(*small.shape), *args,
                         crop.shape[1] / small.shape[1], *lane)

    def current(crop: np.ndarray) -> tuple[float, ...]:
        h, w = resample_shape(*crop.shape, tcfg)
        return find_lane_in_crop(crop, h, w, segment_steps(h, w), *args, crop.shape[1] / w,
                                 *lane)

    out: dict[str, object] = {}
    results = {}
    for key, path in (("previous", previous), ("current", current)):
        results[key] = [path(c) for c in crops]  # warm-up (JIT)
        best = np.inf
        for _ in range(repeat):
            t0 = time.perf_counter()
            for c in crops:
                path(c)
            best = min(best, time.perf_counter() - t0)
        out[f"{key}_us_per_roi"] = best / len(crops) * 1e6
    out["identical_lanes"] = bool(np.array_equal(  # λ may be NaN: equal to NaN here
        np.array(results["previous"]), np.array(results["current"]), equal_nan=True))
    out["speed_up_over_previous"] = out["previous_us_per_roi"] / out["current_us_per_roi"]
    return out


KERNELS: tuple[tuple[str, str, str], ...] = (
    ("first", "first (unpadded rows)", "int32"),
    ("previous", "previous (rows through memory)", "int32"),
    ("previous_uint16", "previous, uint16", "uint16"),
    ("current", "current (register blocks)", "int32"),
    ("current_uint16", "current, uint16 (the detector)", "uint16"),
)
"""(key, label, image type) of the kernels timed, in the table's order."""


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

    inputs = {"int32": padded(np.int32), "uint16": padded(np.uint16)}
    assert max(max(h, w) for _, h, w, _, _ in inputs["uint16"]) <= UINT16_MAX_SAMPLES
    tables = {(h, w): segment_steps(h, w) for _, h, w, _, _ in inputs["int32"]}
    kernels = {"first": previous_search_candidates, "previous": row_search_candidates,
               "previous_uint16": row_search_candidates}

    def current(flat: np.ndarray, h: int, w: int, bi: np.ndarray, be: np.ndarray,
                scratch: np.ndarray) -> None:
        search_candidates(flat, h, w, tables[h, w], bi, be, scratch)

    kernels["current"] = kernels["current_uint16"] = current

    def time_kernel(key: str, dtype: str
                    ) -> tuple[float, list[tuple[np.ndarray, np.ndarray]]]:
        """Best time per ROI over ``repeat`` passes, and the results."""
        kernel, rois = kernels[key], inputs[dtype]
        scratch = np.empty(max(w for _, _, w, _, _ in rois) + SIMD_BLOCK, dtype)
        for flat, h, w, bi, be in rois:  # warm-up (JIT)
            kernel(flat, h, w, bi, be, scratch)
        best = np.inf
        for _ in range(repeat):
            t0 = time.perf_counter()
            for flat, h, w, bi, be in rois:
                kernel(flat, h, w, bi, be, scratch)
            best = min(best, time.perf_counter() - t0)
        return best / len(rois), [(bi.copy(), be.copy()) for *_, bi, be in rois]

    times, results = {}, {}
    for key, _, dtype in KERNELS:
        times[key], results[key] = time_kernel(key, dtype)
    reference = results["first"]
    same = all(np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
               for r in results.values() for a, b in zip(r, reference, strict=True))
    rois = inputs["int32"]
    useful = sum(additions(h, w)[0] for _, h, w, _, _ in rois) / len(rois)
    executed = sum(additions(h, w)[1] for _, h, w, _, _ in rois) / len(rois)
    sizes = sorted({(h, w) for _, h, w, _, _ in rois})
    return {"machine": machine(), "rois": len(rois), "repeat": repeat,
            "roi_sizes_resampled": [list(s) for s in sizes],
            "identical_results": same,
            "kernels": {key: {"label": label, "image_type": dtype,
                              "us_per_roi": times[key] * 1e6,
                              "useful_additions_per_ns": useful / (times[key] * 1e9),
                              "executed_additions_per_ns": executed / (times[key] * 1e9),
                              "time_over_current": times[key] / times[
                                  "current_uint16" if dtype == "uint16" else "current"]}
                        for key, label, dtype in KERNELS},
            "speed_up_over_previous": times["previous"] / times["current"],
            "speed_up_over_previous_uint16": times["previous_uint16"]
            / times["current_uint16"],
            "speed_up_over_first": times["first"] / times["current"],
            "useful_additions_per_roi": useful, "executed_additions_per_roi": executed,
            "per_roi_path": per_roi_paths(n, repeat)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rois", type=int, default=400, help="ROIs searched per timing")
    parser.add_argument("--repeat", type=int, default=20, help="timings (best one kept)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    if args.rois < 1 or args.repeat < 1:
        parser.error("--rois and --repeat must be ≥ 1")
    r = run(args.rois, args.repeat)
    ok = r["identical_results"] and r["per_roi_path"]["identical_lanes"]
    if args.json:
        print(json.dumps(r))
        return 0 if ok else 1
    m = r["machine"]
    print(f"machine: {m['cores']} cores of {m['cpu']} ({m['simd']}), pinned to one; "
          f"{r['rois']} ROIs, resampled sizes "
          f"(h, w) {r['roi_sizes_resampled'][0]}…{r['roi_sizes_resampled'][-1]}")
    print(f"{'kernel':<34}{'µs/ROI':>9}{'adds/ns':>9}{'× current':>11}")
    for k in r["kernels"].values():
        print(f"{k['label']:<34}{k['us_per_roi']:>9.1f}{k['useful_additions_per_ns']:>9.2f}"
              f"{k['time_over_current']:>11.2f}")
    print(f"speed-up over the previous kernel {r['speed_up_over_previous']:.2f}× (uint16 "
          f"{r['speed_up_over_previous_uint16']:.2f}×), over the first "
          f"{r['speed_up_over_first']:.2f}×; results identical: {r['identical_results']}")
    print(f"additions per ROI: {r['useful_additions_per_roi']:.0f} useful, "
          f"{r['executed_additions_per_roi']:.0f} executed with padding "
          f"({r['kernels']['current_uint16']['executed_additions_per_ns']:.2f} per ns, "
          f"uint16)")
    p = r["per_roi_path"]
    print(f"per-ROI path (resize, Sobel, search): previous (cv2.resize + find_lane) "
          f"{p['previous_us_per_roi']:.1f} µs, current (find_lane_in_crop) "
          f"{p['current_us_per_roi']:.1f} µs: {p['speed_up_over_previous']:.2f}×; "
          f"lanes identical: {p['identical_lanes']}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
