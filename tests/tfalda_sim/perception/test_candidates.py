"""The candidate search: the vectorised kernel equals a plain line walk, bit for bit."""

from __future__ import annotations

from fractions import Fraction

import cv2
import numpy as np
import pytest

from tfalda_sim.perception import TfaldaConfig
from tfalda_sim.perception.candidates import (
    UINT16_MAX_SAMPLES,
    candidates,
    choose_lane,
    distance_lambda,
    integer_dda_pixels,
    preprocess,
    sobel_horizontal_edges,
)
from tfalda_sim.perception.params import EdgeMode


def reference_candidates(img: np.ndarray) -> tuple[list[int], list[int], list[int]]:
    """Listing A.2 as written: for every start x, walk every segment to every end x
    (left to right), sum it, keep a strictly larger sum (initial max 0, end x 0)."""
    h, w = img.shape
    ps, ds, is_ = [], [], []
    for x0 in range(w):
        best, best_end = 0, 0
        for x1 in range(w):
            n = max(abs(x1 - x0), h - 1) + 1
            total = 0
            for k in range(n):
                t = Fraction(k, n - 1) if n > 1 else Fraction(0)
                # round half away from zero, independently of the kernel's integer formula
                fx = (x1 - x0) * t
                ox = int(abs(fx) + Fraction(1, 2)) * (1 if fx >= 0 else -1)
                y = int((h - 1) * t + Fraction(1, 2))
                total += int(img[y, x0 + ox])
            if total > best:
                best, best_end = total, x1
        ps.append(x0)
        ds.append(best_end - x0)
        is_.append(best)
    return ps, ds, is_


@pytest.mark.parametrize("seed", range(300))
def test_kernel_equals_the_plain_reference(seed: int) -> None:
    rng = np.random.default_rng(seed)
    h, w = int(rng.integers(2, 12)), int(rng.integers(1, 24))
    kind = seed % 3
    if kind == 0:  # dense noise
        img = rng.integers(0, 256, (h, w), dtype=np.uint8)
    elif kind == 1:  # sparse: many equal sums, exercises the tie rule
        img = (rng.random((h, w)) < 0.1).astype(np.uint8) * 255
    else:  # a bright slanted line on noise, as in a ROI
        img = rng.integers(0, 30, (h, w), dtype=np.uint8)
        x0, x1 = rng.integers(0, w, 2)
        for y, x in ((y, x0 + round((x1 - x0) * y / max(h - 1, 1))) for y in range(h)):
            img[y, x] = 250
    p, d, i = candidates(img)
    rp, rd, ri = reference_candidates(img)
    assert p.tolist() == rp
    assert d.tolist() == rd, (h, w, kind)
    assert i.tolist() == ri
    # The 16-bit variant (images whose sums fit: the detector's) is the same kernel.
    assert _search(img, np.uint16) == (rd, ri)
    assert _numpy_candidates(img) == (rd, ri)  # the wide images' reference, checked here


def _numpy_candidates(img: np.ndarray) -> tuple[list[int], list[int]]:
    """(D, I) per start x by numpy fancy indexing, one end offset at a time (the samples'
    integer rounding written out again): a reference fast enough for wide images."""
    h, w = img.shape
    best_i, best_end = np.zeros(w, np.int64), np.zeros(w, np.int64)
    for dx in range(-(w - 1), w):  # ascending end x for every start
        n = max(abs(dx), h - 1) + 1
        i = np.arange(n)
        den = max(2 * (n - 1), 1)
        ox = np.sign(dx) * ((2 * i * abs(dx) + n - 1) // den)
        y = (2 * i * (h - 1) + n - 1) // den
        starts = np.arange(max(0, -dx), min(w, w - dx))
        sums = img[y[None, :], starts[:, None] + ox[None, :]].astype(np.int64).sum(axis=1)
        better = sums > best_i[starts]
        best_i[starts[better]] = sums[better]
        best_end[starts[better]] = starts[better] + dx
    return (best_end - np.arange(w)).tolist(), best_i.tolist()


@pytest.mark.parametrize("width", [31, 32, 33, 64, 65, 96, 97, 128, 129, 200, 300])
def test_wide_images_sum_in_every_block_combination(width: int) -> None:
    """Images from one to ten blocks of starts wide (the search sums 1, 2 or 3 blocks of
    ``SIMD_BLOCK`` starts at once): equal to the numpy reference in both sum types, on a
    table kept for a wider image of the same height."""
    rng = np.random.default_rng(width)
    for h in (1, 2, 9, 42):
        img = rng.integers(0, 256, (h, width), dtype=np.uint8)
        img[rng.random(img.shape) < 0.5] = 0
        want = _numpy_candidates(img)
        assert _search(img, np.int32) == want
        if max(h, width) <= UINT16_MAX_SAMPLES:  # the sums fit 16 bits
            assert _search(img, np.uint16) == want


def test_segment_tables_are_kept_per_height_bounded_and_read_only() -> None:
    from tfalda_sim.perception.candidates import (
        SEGMENT_TABLES_KEPT,
        _build_segment_steps,
        _segment_steps,
        segment_steps,
    )

    steps, first = segment_steps(42, 90)
    assert segment_steps(42, 75)[0] is steps  # one table for the ROIs' changing widths
    assert not steps.flags.writeable and not first.flags.writeable
    want_steps, want_first = _build_segment_steps(42, 90)
    assert (first[:91] == want_first).all() and (steps[:want_first[-1]] == want_steps).all()
    for h in range(1, 3 * SEGMENT_TABLES_KEPT):
        segment_steps(h, 10)
    assert _segment_steps.cache_info().currsize == SEGMENT_TABLES_KEPT
    with pytest.raises(ValueError, match="≥ 1"):
        segment_steps(0, 5)


def test_the_search_refuses_arrays_it_would_read_or_write_past() -> None:
    """The block sums have no bounds checks of their own: the search checks first."""
    from tfalda_sim.perception.candidates import (
        SIMD_BLOCK,
        _build_segment_steps,
        search_candidates,
        segment_steps,
    )

    h, w = 5, 40
    ok = (np.zeros(h * w + SIMD_BLOCK, np.int32), h, w, segment_steps(h, w),
          np.empty(w, np.int32), np.empty(w, np.int32), np.empty(w + SIMD_BLOCK, np.int32))
    search_candidates(*ok)
    bad = {0: np.zeros(h * w, np.int32), 3: segment_steps(h + 1, w),
           6: np.empty(w, np.int32), 4: np.empty(w - 1, np.int32),
           5: np.empty(w - 1, np.int32), 1: 0, 2: -1}
    for k, value in bad.items():
        args = list(ok)
        args[k] = value
        with pytest.raises(ValueError, match="search_candidates"):
            search_candidates(*args)
    narrow = _build_segment_steps(h, w - 1)  # a table for narrower images
    with pytest.raises(ValueError, match="segment_steps"):
        search_candidates(*ok[:3], narrow, *ok[4:])
    from numba.core.errors import TypingError

    strided = np.zeros(2 * (h * w + SIMD_BLOCK), np.int32)[::2]  # long enough, not contiguous
    empty_2d = np.zeros((h * w + SIMD_BLOCK, 0), np.int32)  # its shape[0] passes, no data
    frozen = np.zeros(w + SIMD_BLOCK, np.int32)
    frozen.flags.writeable = False
    for k, value in ((0, strided), (0, empty_2d), (6, frozen)):
        args = list(ok)
        args[k] = value
        with pytest.raises(TypingError, match="block_sums"):
            search_candidates(*args)
    assert not frozen.any()


def _search(img: np.ndarray, dtype: type) -> tuple[list[int], list[int]]:
    """``search_candidates`` on ``img`` held as ``dtype``: (D, I) per start x."""
    from tfalda_sim.perception.candidates import SIMD_BLOCK, search_candidates, segment_steps

    h, w = img.shape
    flat = np.zeros(h * w + SIMD_BLOCK, dtype)
    flat[:h * w] = img.ravel()
    best_i, best_end = np.empty(w, np.int32), np.empty(w, np.int32)
    search_candidates(flat, h, w, segment_steps(h, w), best_i, best_end,
                      np.empty(w + SIMD_BLOCK, dtype))
    return (best_end - np.arange(w)).tolist(), best_i.tolist()


def test_the_16_bit_search_holds_the_largest_sums_it_is_used_for() -> None:
    """An all-white image as wide as the 16-bit search goes: its longest segments sum to
    65535 exactly, as the 32-bit search finds; one pixel wider, the detector's kernel
    switches to 32 bits and still equals the reference path."""
    from tfalda_sim.perception.candidates import find_lane, segment_steps

    white = np.full((2, UINT16_MAX_SAMPLES), 255, np.uint8)
    d16, i16 = _search(white, np.uint16)
    assert (d16, i16) == _search(white, np.int32) and max(i16) == 65535
    # Columns 0 0 255 255 …: |∂/∂x| saturates at 255 but in the first and last column, so
    # the longest segments inside a 260 px wide gradient sum past 16 bits.
    pattern = np.repeat(np.array([0, 255], np.uint8), 2)
    wider = np.tile(pattern, (3, 66))[:, :UINT16_MAX_SAMPLES + 3]
    gradient = preprocess(wider, TfaldaConfig(resample_factor=1.0, edge_mode=EdgeMode.BOTH),
                          False)
    assert _search(gradient, np.uint16) != _search(gradient, np.int32)  # 16 bits overflow
    args = (0.0, 1.0, True, 0.0, 0.0, 0.0, 1.0, 1.0, 0.01)
    np.testing.assert_equal(find_lane(wider, segment_steps(*wider.shape), False, False, *args),
                            choose_lane(gradient, *args))


def test_all_dark_candidates_keep_the_listing_end_x_0() -> None:
    p, d, i = candidates(np.zeros((5, 7), np.uint8))
    assert i.tolist() == [0] * 7
    assert (p + d).tolist() == [0] * 7


def test_integer_dda_pixels_are_connected_and_end_at_both_points() -> None:
    for x0, x1, h in [(0, 9, 4), (5, 0, 10), (3, 3, 6), (0, 20, 21)]:
        px = integer_dda_pixels(x0, x1, h)
        assert px[0] == (x0, 0) and px[-1] == (x1, h - 1)
        steps = np.abs(np.diff(np.array(px), axis=0))
        assert steps.max() <= 1 and np.all(steps.sum(axis=1) >= 1)


def test_sobel_manager_switches_beyond_45_degrees() -> None:
    assert not sobel_horizontal_edges(40.0, 84.0, 45.0)
    assert sobel_horizontal_edges(90.0, 84.0, 45.0)
    assert not sobel_horizontal_edges(-84.0, 84.0, 45.0)  # exactly 45°: stays vertical


def test_rising_edges_only_unless_both_are_asked_for() -> None:
    crop = np.zeros((20, 40), np.uint8)
    crop[:, 20:24] = 255  # a vertical white line
    rising = preprocess(crop, TfaldaConfig(resample_factor=1.0), horizontal_edges=False)
    both = preprocess(crop, TfaldaConfig(resample_factor=1.0, edge_mode=EdgeMode.BOTH), False)
    cols_rising = np.flatnonzero(rising.max(axis=0))
    cols_both = np.flatnonzero(both.max(axis=0))
    assert cols_rising.max() < 22  # only the dark→bright (left) edge
    assert cols_both.max() > 22  # both edges
    assert preprocess(crop, TfaldaConfig(), False).shape == (10, 20)  # resampled by 2


def test_distance_lambda_is_listing_3_1() -> None:
    from tfalda_sim.perception.candidates import distance_lambda

    lam = distance_lambda(np.array([10.0, 14.0]), np.array([-3.0, 1.0]), np.array([900, 1200]),
                          previous_p_px=12.0, previous_d_px=-2.0, previous_i=1000.0,
                          kp=2.0, kd=3.0, ki=0.01)
    # 2·|10−12| + 3·|−3+2| + 0.01·(1000−900); 2·|14−12| + 3·|1+2| + 0.01·(1000−1200)
    assert lam.tolist() == [4.0 + 3.0 + 1.0, 4.0 + 9.0 - 2.0]


@pytest.mark.parametrize("seed", range(60))
def test_choose_lane_equals_candidates_lambda_and_argmin(seed: int) -> None:
    """The detector's fused per-ROI kernel picks what the array functions pick, bit for bit
    (first frame: largest I; else smallest λ, first of equals, a NaN λ wins)."""
    rng = np.random.default_rng(seed)
    h, w = int(rng.integers(2, 45)), int(rng.integers(1, 95))
    img = rng.integers(0, 256, (h, w), dtype=np.uint8)
    if seed % 3 == 1:
        img[rng.random((h, w)) < 0.9] = 0  # ties
    roi_x, scale = float(rng.integers(0, 600)), float(rng.uniform(1.5, 2.5))
    p, d, i = candidates(img)
    p_img, d_img = (p + 0.5) * scale - 0.5 + roi_x, d * scale
    prev = (float(rng.uniform(0, 752)), float(rng.uniform(-80, 80)),
            float(rng.uniform(0, 5000)))
    if seed % 10 == 9:
        prev = (np.nan, *prev[1:])
    weights = (float(rng.uniform(0, 5)), float(rng.uniform(0, 5)), float(rng.uniform(0, 1)))
    for first in (True, False):
        got = choose_lane(img, roi_x, scale, first, *prev, *weights)
        if first:
            k, lam = int(np.argmax(i)), np.nan
        else:
            lams = distance_lambda(p_img, d_img, i, *prev, *weights)
            k = int(np.argmin(lams))
            lam = float(lams[k])
        want = (float(p_img[k]), float(d_img[k]), float(i[k]), lam)
        assert got[:3] == want[:3]
        assert got[3] == want[3] or (np.isnan(got[3]) and np.isnan(want[3]))


@pytest.mark.parametrize("seed", range(24))
def test_detector_sobel_equals_opencv_and_its_lane_the_reference(seed: int) -> None:
    """The detector's per-ROI kernel (``find_lane``: Sobel in numba, then the search) gives
    OpenCV's Sobel of the resampled crop (``preprocess``) bit for bit, in both directions
    and edge modes, down to 1 px wide images, and so the lane ``choose_lane`` picks."""
    from tfalda_sim.perception.candidates import find_lane, resample, segment_steps, sobel_into

    rng = np.random.default_rng(seed)
    h, w = int(rng.integers(2, 40)), int(rng.integers(1, 90))
    if seed < 3:
        w = seed + 1  # the narrowest crops: reflected borders meet
    crop = rng.integers(0, 256, (2 * h, 2 * w), dtype=np.uint8)
    if seed % 2:
        crop[:, rng.integers(0, 2 * w):] //= 8  # an edge
    for mode in EdgeMode:
        config = TfaldaConfig(edge_mode=mode)
        small = resample(crop, config)
        for horizontal in (False, True):
            want = preprocess(crop, config, horizontal)
            flat = np.full(small.size + 4, -1, np.int32)
            sobel_into(small, horizontal, mode is EdgeMode.RISING, flat)
            assert (flat[:small.size].reshape(small.shape) == want).all()
            assert (flat[small.size:] == -1).all()
            args = (float(rng.integers(0, 600)), 2 * w / small.shape[1], bool(seed % 3),
                    300.0, 10.0, 800.0, 1.0, 2.0, 0.01)
            np.testing.assert_equal(  # exact, NaN (first frame's λ) equal to NaN
                find_lane(small, segment_steps(*small.shape), horizontal,
                          mode is EdgeMode.RISING, *args),
                choose_lane(want, *args))


RESAMPLE_FACTORS = (1.0, 1.01, 1.3, 1.5, 1.99, 2.0, 2.5, 3.0, 4.0, 8.0)
"""Resample factors the numba resize is compared at: the thesis' 2 (odd and even crop
sizes: OpenCV's bilinear and 2×2-average paths), others up to the config's limit 8, and
ones that stretch a 1-px-high crop's 2 output rows (y upsampled, x not)."""


@pytest.mark.parametrize("factor", RESAMPLE_FACTORS)
def test_resample_into_equals_opencv_resize(factor: float) -> None:
    """``resample_into`` (the detector's resize) gives ``cv2.resize``'s bilinear result bit
    for bit for crops from 1 × 1 px to wider than any ROI, random and black-and-white
    content, contiguous, strided rows (a crop of a whole frame) and strided columns (the
    paired tap loads do not apply). OpenCV rounds its vertical
    pass in a way the plain fixed-point formula does not: ~5 % of pixels differ by 1
    with ``(r0·b0 + r1·b1 + 2²¹) >> 22``, so a port of the textbook formula fails here."""
    from tfalda_sim.perception.candidates import resample, resample_into, resample_shape

    config = TfaldaConfig(resample_factor=factor)
    rng = np.random.default_rng(int(factor * 100))
    heights = [*range(1, 10), 37, 74, 75, 85]
    widths = [*range(1, 12), 31, 32, 33, 100, 101, 143, 180, 275]
    for h in heights:
        for w in widths:
            frame = rng.integers(0, 256, (h + 3, w + 5), dtype=np.uint8)
            if (h + w) % 2:
                frame = np.where(frame < 128, 0, 255).astype(np.uint8)  # hard edges
            wide = np.repeat(frame[:h, :w], 2, axis=1)  # its every other column: a crop
            for crop in (np.ascontiguousarray(frame[:h, :w]), frame[2:h + 2, 3:w + 3],
                         wide[:, ::2]):  # whose pixels are not adjacent in memory
                want = resample(crop, config)
                got = np.full(resample_shape(h, w, config), 7, np.uint8)
                resample_into(crop, got)
                assert got.shape == want.shape
                assert np.array_equal(got, want), (
                    f"{h} × {w} px at factor {factor}: cv2.resize of OpenCV {cv2.__version__} "
                    "rounds otherwise than OpenCV 5.1 on x86-64, which resample_into follows")


def test_resample_into_refuses_empty_images() -> None:
    """An empty crop or output raises (OpenCV asserts too) instead of reading memory
    outside the crop."""
    from tfalda_sim.perception.candidates import resample_into

    for crop, out in ((np.zeros((0, 5), np.uint8), np.zeros((2, 2), np.uint8)),
                      (np.zeros((5, 0), np.uint8), np.zeros((2, 1), np.uint8)),
                      (np.zeros((5, 5), np.uint8), np.zeros((2, 0), np.uint8))):
        with pytest.raises(ValueError, match="at least 1 × 1"):
            resample_into(crop, out)


@pytest.mark.parametrize("seed", range(8))
def test_find_lane_in_crop_equals_find_lane_of_opencv_resample(seed: int) -> None:
    """The detector's per-ROI call (resize, Sobel and search in one kernel) equals
    ``find_lane`` of OpenCV's resampled crop, for crops of the thesis' ROI sizes."""
    from tfalda_sim.perception.candidates import (
        find_lane,
        find_lane_in_crop,
        resample,
        resample_shape,
        segment_steps,
    )

    rng = np.random.default_rng(seed)
    h, w = int(rng.choice([75, 85, 40])), int(rng.integers(100, 276))
    crop = rng.integers(0, 60, (h, w), dtype=np.uint8)
    x = int(rng.integers(0, w - 10))
    crop[:, x:x + int(rng.integers(3, 9))] = 230  # a line
    config = TfaldaConfig()
    small = resample(crop, config)
    sh, sw = resample_shape(h, w, config)
    for horizontal in (False, True):
        args = (horizontal, bool(seed % 2), float(rng.integers(0, 600)), w / sw,
                bool(seed % 3 == 0), 300.0, 10.0, 800.0, 1.0, 2.0, 0.01)
        np.testing.assert_equal(
            find_lane_in_crop(crop, sh, sw, segment_steps(sh, sw), *args),
            find_lane(small, segment_steps(*small.shape), *args))
