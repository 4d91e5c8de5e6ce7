"""The Hough baseline (the seed's Matlab detector). Each stage is checked against a literal
Python transcription of the Matlab code it reproduces (the seed's merge loop; ``edge``,
``hough``, ``houghpeaks`` and ``houghlines``). The detector is checked on synthetic frames
drawn with OpenCV and on one rendered frame."""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np
import pytest

from tfalda_sim.perception.hough import (
    CAR_MASK,
    CROP_HEIGHT_PX,
    CROP_TOP_PX,
    HoughConfig,
    HoughDetector,
    HoughResult,
    apply_car_mask,
    binarise,
    default_nhood,
    hough_lines,
    hough_peaks,
    hough_transform,
    merge_double_edges,
    sobel_vertical_edges,
    theta_grid,
)

H_PX, W_PX = 480, 752
GROUND, WHITE = 40, 255
THICKNESS = 16


def frame_with(*lines: tuple[int, int, int, int], thickness: int = THICKNESS) -> np.ndarray:
    """Dark ground with white lines (x0, y0, x1, y1) [full-image px]."""
    f = np.full((H_PX, W_PX), GROUND, np.uint8)
    for x0, y0, x1, y1 in lines:
        cv2.line(f, (x0, y0), (x1, y1), WHITE, thickness)
    return f


def normal_angle_deg(x0: float, y0: float, x1: float, y1: float) -> float:
    """θ ∈ [−90, 90) of the normal form x·cos θ + y·sin θ = ρ of the line through two
    points (image axes: x right, y down)."""
    t = math.degrees(math.atan2(-(x1 - x0), y1 - y0))
    return t - 180.0 if t >= 90.0 else t + 180.0 if t < -90.0 else t


def distance_to_line(px: float, py: float, line: tuple[int, int, int, int]) -> float:
    x0, y0, x1, y1 = line
    return abs((x1 - x0) * (y0 - py) - (x0 - px) * (y1 - y0)) / math.hypot(x1 - x0, y1 - y0)


# --------------------------------------------------------------------------- Matlab oracles
def matlab_merge(sobel: np.ndarray, maxgap: int = 25) -> np.ndarray:
    """The seed's loop, line by line (``for y = 1:259, for x = 1:752``)."""
    out = np.zeros(sobel.shape, bool)
    counter = 0
    for y in range(sobel.shape[0]):
        for x in range(sobel.shape[1]):
            if sobel[y, x] == 1:
                if counter > 1 and counter < maxgap:
                    out[y, x] = True
                counter = 0
            else:
                counter = counter + 1
    return out


def matlab_edge_sobel_vertical(bw: np.ndarray, thresh: float, thinning: bool) -> np.ndarray:
    """``edge(bw, 'sobel', thresh, 'vertical')``: im2single, imfilter with
    fspecial('sobel')/8 and 'replicate', then computeEdgesWithThinning (kx = 1, ky = 0)."""
    a = bw.astype(np.float32)
    m, n = a.shape
    op = np.array([[1, 2, 1], [0, 0, 0], [-1, -2, -1]], np.float32) / 8  # fspecial('sobel')/8
    pad = np.pad(a, 1, mode="edge")

    def imfilter(k: np.ndarray) -> np.ndarray:  # correlation, as imfilter's default
        return sum(k[i, j] * pad[i:i + m, j:j + n] for i in range(3) for j in range(3))

    bx, by = imfilter(op.T), imfilter(op)
    kx, ky = 1, 0
    b = kx * bx * bx + ky * by * by
    cutoff = thresh ** 2
    if not thinning:
        return b > cutoff
    bx, by = np.abs(bx), np.abs(by)
    eps100 = np.finfo(np.float64).eps * 100
    e = np.zeros((m, n), bool)
    for r in range(m):
        for c in range(n):
            b1 = True if c - 1 < 0 else b[r, c - 1] <= b[r, c]
            b2 = True if c + 1 > n - 1 else b[r, c] > b[r, c + 1]
            b3 = True if r - 1 < 0 else b[r - 1, c] <= b[r, c]
            b4 = True if r + 1 > m - 1 else b[r, c] > b[r + 1, c]
            e[r, c] = b[r, c] > cutoff and (
                (bx[r, c] >= kx * by[r, c] - eps100 and b1 and b2)
                or (by[r, c] >= ky * bx[r, c] - eps100 and b3 and b4))
    return e


def matlab_hough(bw: np.ndarray, theta_deg: np.ndarray) -> np.ndarray:
    """standardHoughTransform: each on pixel (column-major) votes per θ."""
    m_rows, n_cols = bw.shape
    d = math.sqrt((m_rows - 1) ** 2 + (n_cols - 1) ** 2)
    q = math.ceil(d)
    rho = np.linspace(-q, q, 2 * q + 1)
    h = np.zeros((len(rho), len(theta_deg)), np.int64)
    slope = (len(rho) - 1) / (rho[-1] - rho[0])
    cost = [math.cos(t * math.pi / 180) for t in theta_deg]
    sint = [math.sin(t * math.pi / 180) for t in theta_deg]
    for n in range(n_cols):
        for m in range(m_rows):
            if bw[m, n]:
                for k in range(len(theta_deg)):
                    my_rho = n * cost[k] + m * sint[k]
                    h[int(slope * (my_rho - rho[0]) + 0.5), k] += 1
    return h


def matlab_houghpeaks(h: np.ndarray, numpeaks: int, threshold: float,
                      nhood: tuple[int, int]) -> np.ndarray:
    """houghpeaks' loop on a copy of H (0-based output)."""
    hnew = h.astype(np.float64).copy()
    nrho, ntheta = h.shape
    centre = ((nhood[0] - 1) // 2, (nhood[1] - 1) // 2)
    peaks: list[tuple[int, int]] = []
    while True:
        idx = int(np.argmax(hnew.ravel(order="F")))  # max(hnew(:)): column-major, first
        p, q = idx % nrho, idx // nrho
        if not hnew[p, q] >= threshold:
            break
        peaks.append((p, q))
        for pp in range(max(p - centre[0], 0), min(p + centre[0], nrho - 1) + 1):
            for qq in range(q - centre[1], q + centre[1] + 1):
                if qq < 0:  # theta_too_low: wrap, ρ mirrored
                    hnew[nrho - 1 - pp, qq + ntheta] = 0
                elif qq >= ntheta:  # theta_too_high
                    hnew[nrho - 1 - pp, qq - ntheta] = 0
                else:
                    hnew[pp, qq] = 0
        if len(peaks) == numpeaks:
            break
    return np.array(peaks, np.int64).reshape(-1, 2)


def matlab_houghlines(bw: np.ndarray, theta: np.ndarray, rho: np.ndarray, peaks: np.ndarray,
                      fillgap: float, minlength: float) -> np.ndarray:
    """houghlines with houghpixels and reSortHoughPixels; returns 0-based (x1, y1, x2, y2)."""
    xs, ys = np.nonzero(bw.T)  # [y, x] = find(bw): column-major order
    nrho = len(rho)
    slope = (nrho - 1) / (rho[-1] - rho[0])
    lines = []
    for p0, q0 in peaks:
        peak = (p0 + 1, q0 + 1)  # Matlab's 1-based peak
        theta_c = theta[peak[1] - 1] * math.pi / 180
        sel = [i for i in range(len(xs))
               if math.floor(slope * (xs[i] * math.cos(theta_c) + ys[i] * math.sin(theta_c)
                                      - rho[0]) + 1 + 0.5) == peak[0]]
        if not sel:
            continue
        r = [int(ys[i]) + 1 for i in sel]
        c = [int(xs[i]) + 1 for i in sel]
        if max(r) - min(r) > max(c) - min(c):
            rc = sorted(zip(r, c, strict=True))
        else:
            rc = sorted(zip(r, c, strict=True), key=lambda t: (t[1], t[0]))
        xy = [(cc, rr) for rr, cc in rc]
        cuts = [i + 1 for i in range(len(xy) - 1)
                if (xy[i + 1][0] - xy[i][0]) ** 2 + (xy[i + 1][1] - xy[i][1]) ** 2 > fillgap ** 2]
        idx = [0, *cuts, len(xy)]
        for k in range(len(idx) - 1):
            p1, p2 = xy[idx[k]], xy[idx[k + 1] - 1]
            if (p2[0] - p1[0]) ** 2 + (p2[1] - p1[1]) ** 2 >= minlength ** 2:
                lines.append((p1[0] - 1, p1[1] - 1, p2[0] - 1, p2[1] - 1))
    return np.array(lines, np.int64).reshape(-1, 4)


# --------------------------------------------------------------------------- constants
def test_crop_and_car_mask_are_the_seeds_matlab_ranges_converted() -> None:
    # imcrop(frame, [1 220 751 258]) takes the 1-based rows 220..220+258 over all columns
    assert CROP_TOP_PX == 220 - 1
    assert CROP_HEIGHT_PX == 258 + 1
    # bwframe(r0:r1, c0:c1) = 0, written out with 1-based inclusive loops
    matlab = ((195, 258, 155, 625), (160, 195, 210, 445), (125, 195, 110, 215),
              (110, 160, 345, 430))
    expected = np.ones((CROP_HEIGHT_PX, W_PX), bool)
    for r0, r1, c0, c1 in matlab:
        for r in range(r0, r1 + 1):
            for c in range(c0, c1 + 1):
                expected[r - 1, c - 1] = False
    assert np.array_equal(apply_car_mask(np.ones_like(expected), CAR_MASK), expected)
    assert expected[-1].all()  # the seed's 195:258 leaves the crop's last row unmasked


def test_the_crop_is_rows_219_to_477_and_im2bw_keeps_values_above_229_5() -> None:
    f = np.full((H_PX, W_PX), 230, np.uint8)
    f[CROP_TOP_PX - 1] = 255  # just above the crop
    f[CROP_TOP_PX + CROP_HEIGHT_PX] = 255  # just below it
    f[CROP_TOP_PX, :376] = 229  # first crop row: half just below 0.9 of full scale
    r = HoughDetector(HoughConfig(car_mask=())).detect(f)
    assert r.binary.shape == (CROP_HEIGHT_PX, W_PX)
    assert not r.binary[0, :376].any() and r.binary[0, 376:].all()
    assert r.binary[1:].all()
    assert np.array_equal(binarise(np.array([[0, 229, 230, 255]], np.uint8), 0.9),
                          [[False, False, True, True]])
    assert not binarise(np.full((2, 2), 255, np.uint8), 1.0).any()  # im2bw: A > 255·level


# --------------------------------------------------------------------------- stage oracles
def test_merge_reproduces_the_seeds_loop_on_a_hand_built_row() -> None:
    row = np.zeros((1, 60), bool)
    row[0, [0, 1, 4, 30, 50, 52]] = True
    merged = merge_double_edges(row)
    # counters at the edges: 0 (start), 0, 2, 25, 19, 1; marked when 1 < counter < 25
    assert np.flatnonzero(merged[0]).tolist() == [4, 50]
    assert np.array_equal(merged, matlab_merge(row))


def test_merge_counter_carries_over_from_one_row_to_the_next() -> None:
    n = 40
    edges = np.zeros((2, n), bool)
    edges[0, n - 2] = True  # 1 non-edge pixel after it in row 0
    edges[1, 1] = True  # 1 before it in row 1: counter 1 + 1 = 2 > 1 (per row: 1, no mark)
    assert merge_double_edges(edges)[1, 1]
    edges[:] = False
    edges[0, 20] = True  # 19 after it in row 0
    edges[1, 10] = True  # 19 + 10 = 29 ≥ 25 (per row: 10, a mark)
    assert not merge_double_edges(edges)[1, 10]
    edges[:] = False
    edges[0, 2] = True  # the counter starts at 0 before the first row: 2 > 1
    assert merge_double_edges(edges)[0, 2]
    for seed in range(20):
        e = np.random.default_rng(seed).random((5, 30)) < 0.15
        assert np.array_equal(merge_double_edges(e), matlab_merge(e))


@pytest.mark.parametrize("density", [0.02, 0.1, 0.4])
def test_merge_equals_the_matlab_loop_on_random_images(density: float) -> None:
    rng = np.random.default_rng(int(density * 100))
    sobel = rng.random((CROP_HEIGHT_PX, W_PX)) < density
    for gap in (25, 3, 60):
        assert np.array_equal(merge_double_edges(sobel, gap), matlab_merge(sobel, gap))


@pytest.mark.parametrize("thinning", [True, False])
@pytest.mark.parametrize("thresh", [0.2, 0.1, 0.3, 0.45])
def test_sobel_equals_matlab_edge_on_random_binary_images(thresh: float,
                                                          thinning: bool) -> None:
    rng = np.random.default_rng(7)
    for k in range(25):
        shape = (int(rng.integers(1, 14)), int(rng.integers(1, 18)))
        bw = rng.random(shape) < rng.uniform(0.1, 0.6)
        assert np.array_equal(sobel_vertical_edges(bw, thresh, thinning),
                              matlab_edge_sobel_vertical(bw, thresh, thinning)), (k, shape)


def test_sobel_equals_matlab_edge_on_a_drawn_frame() -> None:
    f = frame_with((100, 477, 300, 219), (650, 477, 430, 219))
    bw = binarise(f[CROP_TOP_PX:CROP_TOP_PX + CROP_HEIGHT_PX])
    assert np.array_equal(sobel_vertical_edges(bw), matlab_edge_sobel_vertical(bw, 0.2, True))


def test_hough_accumulator_equals_a_per_pixel_vote() -> None:
    rng = np.random.default_rng(3)
    bw = rng.random((23, 41)) < 0.06
    theta = theta_grid()
    h, th, rho = hough_transform(bw, theta)
    assert np.array_equal(th, theta) and len(theta) == 359
    assert rho[0] == -math.ceil(math.hypot(22, 40)) and len(rho) == h.shape[0]
    assert np.array_equal(h, matlab_hough(bw, theta))
    assert h.sum() == bw.sum() * len(theta)


@pytest.mark.parametrize(("numpeaks", "threshold", "nhood"),
                         [(5, 3, (5, 3)), (20, 2, (7, 5)), (8, 4, (1, 1)), (40, 1, (3, 9))])
def test_hough_peaks_equal_houghpeaks_on_random_accumulators(
        numpeaks: int, threshold: int, nhood: tuple[int, int]) -> None:
    rng = np.random.default_rng(numpeaks)
    for _ in range(10):
        h = rng.integers(0, 6, size=(61, 37)).astype(np.int32)  # many ties
        assert np.array_equal(hough_peaks(h, numpeaks, threshold, nhood),
                              matlab_houghpeaks(h, numpeaks, threshold, nhood))


def test_hough_peaks_suppress_across_theta_plus_minus_90() -> None:
    h = np.zeros((21, 10), np.int32)
    h[3, 0] = 9  # θ index 0 (−90°)
    h[21 - 1 - 3, 9] = 8  # its mirror at the last θ: inside the wrapped neighbourhood
    h[3, 9] = 7  # same ρ, last θ: not mirrored, so not suppressed
    peaks = hough_peaks(h, 5, 1, (3, 3))
    assert peaks.tolist() == [[3, 0], [3, 9]]
    assert np.array_equal(peaks, matlab_houghpeaks(h, 5, 1, (3, 3)))


def test_hough_lines_equal_houghlines() -> None:
    rng = np.random.default_rng(11)
    img = np.zeros((70, 110), np.uint8)
    for _ in range(5):
        x0, x1 = rng.integers(0, 110, 2)
        y0, y1 = rng.integers(0, 70, 2)
        cv2.line(img, (int(x0), int(y0)), (int(x1), int(y1)), 1, 1)
    img[rng.random(img.shape) < 0.02] = 1
    bw = img.astype(bool)
    h, theta, rho = hough_transform(bw)
    peaks = hough_peaks(h, 12, 2, (9, 5))
    assert len(peaks) >= 5
    for fillgap, minlength in ((120, 3), (5, 3), (2, 8), (20, 40)):
        segs, owner = hough_lines(bw, theta, rho, peaks, fillgap, minlength)
        assert np.array_equal(segs, matlab_houghlines(bw, theta, rho, peaks, fillgap,
                                                      minlength)), (fillgap, minlength)
        assert np.all(np.diff(owner) >= 0) and owner.max(initial=0) < len(peaks)


def test_hough_lines_split_at_gaps_above_fill_gap_and_drop_short_pieces() -> None:
    bw = np.zeros((259, 60), bool)
    bw[0:40, 30] = True
    bw[161:210, 30] = True  # a 122-px step from row 39: a gap > 120
    bw[250:252, 30] = True  # 2 px, 41 below the second piece: joined to it
    theta = theta_grid()
    h, _, rho = hough_transform(bw, theta)
    peaks = hough_peaks(h, 1, 1)
    segs, _ = hough_lines(bw, theta, rho, peaks, 120, 3)
    assert segs.tolist() == [[30, 0, 30, 39], [30, 161, 30, 251]]
    segs, _ = hough_lines(bw, theta, rho, peaks, 130, 3)  # the gap closes
    assert segs.tolist() == [[30, 0, 30, 251]]
    segs, _ = hough_lines(bw, theta, rho, peaks, 30, 40)  # 39 and 1 px long: too short
    assert segs.tolist() == [[30, 161, 30, 209]]


def test_detect_equals_the_chain_of_matlab_transcriptions() -> None:
    # the left line crosses the car mask (region 3 and 1): the whole seed loop end to end
    f = frame_with((100, 477, 300, 219), (650, 477, 430, 219), (720, 219, 700, 479),
                   thickness=14)
    det = HoughDetector()
    r = det.detect(f)
    crop = f[CROP_TOP_PX:CROP_TOP_PX + CROP_HEIGHT_PX]
    bw = crop > 0.9 * 255
    for r0, r1, c0, c1 in ((195, 258, 155, 625), (160, 195, 210, 445), (125, 195, 110, 215),
                           (110, 160, 345, 430)):
        bw[r0 - 1:r1, c0 - 1:c1] = False
    sobel = matlab_edge_sobel_vertical(bw, 0.2, True)
    merged = matlab_merge(sobel, 25)
    theta = np.arange(-90, 89.5, 0.5)
    h = matlab_hough(merged, theta)
    nhood = tuple(max(2 * math.ceil(s / 50 / 2) + 1, 1) for s in h.shape)  # houghpeaks default
    peaks = matlab_houghpeaks(h, 5, math.ceil(0.3 * h.max()), nhood)
    q = math.ceil(math.hypot(CROP_HEIGHT_PX - 1, W_PX - 1))
    lines = matlab_houghlines(merged, theta, np.linspace(-q, q, 2 * q + 1), peaks, 120, 3)
    assert np.array_equal(r.sobel, sobel) and np.array_equal(r.merged, merged)
    assert np.array_equal(r.accumulator, h)
    assert np.array_equal(r.peaks, peaks)
    assert np.array_equal(r.segments, lines + np.array([0, CROP_TOP_PX, 0, CROP_TOP_PX]))
    assert len(r.segments) >= 3


# --------------------------------------------------------------------------- the detector
def test_a_single_line_merges_to_one_pixel_per_row_and_one_segment_on_it() -> None:
    line = (670, 150, 690, 479)  # beyond the crop at both ends
    r = HoughDetector().detect(frame_with(line))
    assert np.array_equal(r.merged.sum(axis=1), np.ones(CROP_HEIGHT_PX))  # double edges merged
    assert (r.sobel.sum(axis=1) >= 2).all()  # …from (at least) two edges per row
    assert r.segments.shape == (1, 4)
    x1, y1, x2, y2 = r.segments[0]
    assert y1 <= CROP_TOP_PX + 10 and y2 >= CROP_TOP_PX + CROP_HEIGHT_PX - 11
    # the merged line is the first dark pixel right of the marking: centre + half a width
    for x, y in ((x1, y1), (x2, y2)):
        centre = line[0] + (line[2] - line[0]) * (y - line[1]) / (line[3] - line[1])
        assert abs(x - (centre + THICKNESS / 2)) <= 3
    assert abs(r.segment_theta_deg[0] - normal_angle_deg(*line)) <= 1.0


def test_two_slanted_lines_give_one_segment_each_at_their_angles() -> None:
    lines = ((100, 477, 300, 219), (650, 477, 430, 219))  # lane sides in perspective
    r = HoughDetector(HoughConfig(car_mask=())).detect(frame_with(*lines, thickness=14))
    assert len(r.segments) == 2
    for line in lines:
        hits = [k for k, s in enumerate(r.segments)
                if all(distance_to_line(x, y, line) <= 14 / 2 + 3 for x, y in (s[:2], s[2:]))]
        assert len(hits) == 1, line
        x1, y1, x2, y2 = r.segments[hits[0]]
        assert abs(r.segment_theta_deg[hits[0]] - normal_angle_deg(*line)) <= 1.0
        assert abs(normal_angle_deg(x1, y1, x2, y2) - normal_angle_deg(*line)) <= 2.0
        assert abs(y2 - y1) >= 150  # most of the crop's 259 rows
        assert r.segments[hits[0], [1, 3]].min() >= CROP_TOP_PX


def test_the_car_mask_blanks_markings_inside_its_rectangles() -> None:
    f = np.full((H_PX, W_PX), GROUND, np.uint8)
    # inside region 1: crop rows 194..257, cols 154..624 → full rows 413..476
    cv2.rectangle(f, (392, 420), (408, 470), WHITE, -1)
    r = HoughDetector().detect(f)
    assert r.binary.any() and not r.masked.any()
    assert not r.merged.any() and len(r.segments) == 0
    r = HoughDetector(HoughConfig(car_mask=())).detect(f)
    assert len(r.segments) >= 1
    assert any(392 <= x1 <= 412 and 392 <= x2 <= 412 and 420 <= min(y1, y2)
               and max(y1, y2) <= 470 for x1, y1, x2, y2 in r.segments)


def test_a_black_frame_gives_no_segments() -> None:
    det = HoughDetector()
    r = det.detect(np.zeros((H_PX, W_PX), np.uint8))
    assert r.segments.shape == (0, 4) and r.peaks.shape == (0, 2)
    assert r.segment_theta_deg.shape == (0,) and r.peak_votes.shape == (0,)
    assert not r.accumulator.any() and r.peak_threshold == 1


def test_peaks_respect_the_threshold_count_and_neighbourhood() -> None:
    f = frame_with((100, 477, 300, 219), (650, 477, 430, 219), (330, 479, 400, 219),
                   (560, 479, 520, 219), (20, 479, 90, 219), (740, 479, 700, 219),
                   thickness=12)
    det = HoughDetector(HoughConfig(car_mask=()))
    r = det.detect(f)
    h = r.accumulator
    assert h.shape == (len(r.rho_px), len(r.theta_deg)) == (1591, 359)
    assert h.sum() == r.merged.sum() * 359
    assert r.peak_threshold == math.ceil(0.3 * h.max())
    assert 1 <= len(r.peaks) <= 5
    assert np.array_equal(r.peak_votes, h[r.peaks[:, 0], r.peaks[:, 1]])
    assert r.peak_votes[0] == h.max() and (r.peak_votes >= r.peak_threshold).all()
    assert det.nhood == (33, 9)
    for i in range(len(r.peaks)):
        for j in range(i):
            dp, dq = np.abs(r.peaks[i] - r.peaks[j])
            assert dp > 16 or dq > 4  # outside every earlier peak's suppression box


def test_default_nhood_is_odd_and_about_a_fiftieth_of_the_accumulator() -> None:
    # houghpeaks: 2·ceil(size/50/2) + 1, an odd number in [size/50 + 1, size/50 + 3)
    for shape in ((1591, 359), (100, 100), (7, 3), (51, 49), (325, 600)):
        for v, s in zip(default_nhood(shape), shape, strict=True):
            assert v % 2 == 1 and s / 50 + 1 <= v < s / 50 + 3
    assert default_nhood((1591, 359)) == (33, 9)


@pytest.mark.parametrize(("frame", "exc", "match"), [
    (np.zeros((480, 750), np.uint8), ValueError, "shape"),
    (np.zeros((480, 752), np.float32), ValueError, "uint8"),
    (np.zeros((480, 752, 3), np.uint8), ValueError, "2-D grayscale"),
    ([[0] * 752] * 480, TypeError, "numpy array"),
])
def test_bad_frames_are_refused(frame: object, exc: type, match: str) -> None:
    with pytest.raises(exc, match=match):
        HoughDetector().detect(frame)  # type: ignore[arg-type]


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"crop_top_px": -1}, "crop_top_px"),
    ({"crop_top_px": 219.5}, "crop_top_px must be an integer"),
    ({"num_peaks": 2.0}, "num_peaks must be an integer"),
    ({"crop_height_px": 300}, "crop_height_px"),
    ({"binarise_level": 1.5}, "binarise_level"),
    ({"car_mask": ((0, 300, 0, 10),)}, r"car_mask\[0\]"),
    ({"car_mask": ((0, 10, 5, 5),)}, r"car_mask\[0\]"),
    ({"car_mask": ((0, 10, 0, 10), (0, 10, 0, 800))}, r"car_mask\[1\]"),
    ({"car_mask": ((0, 10, 0),)}, "four integers"),
    ({"car_mask": ((0.5, 10, 0, 5),)}, "four integers"),
    ({"car_mask": 5}, "car_mask"),
    ({"sobel_threshold": -0.1}, "sobel_threshold"),
    ({"merge_max_gap_px": 2}, "merge_max_gap_px"),
    ({"theta_min_deg": -91.0}, "theta_min_deg"),
    ({"theta_max_deg": 90.0}, "theta_max_deg"),
    ({"theta_step_deg": 0.0}, "theta_step_deg"),
    ({"rho_resolution_px": 0.0}, "rho_resolution_px"),
    ({"num_peaks": 0}, "num_peaks"),
    ({"peak_threshold_ratio": 1.2}, "peak_threshold_ratio"),
    ({"peak_nhood": (4, 3)}, "peak_nhood"),
    ({"fill_gap_px": 0.0}, "fill_gap_px"),
    ({"min_length_px": -1.0}, "min_length_px"),
])
def test_config_validation_names_the_field(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        HoughConfig(**kwargs)


def test_config_defaults_masks_and_oversized_neighbourhoods() -> None:
    c = HoughConfig()
    assert (c.crop_top_px, c.crop_height_px, c.binarise_level, c.sobel_threshold) == (
        CROP_TOP_PX, CROP_HEIGHT_PX, 0.9, 0.2)
    assert (c.merge_max_gap_px, c.num_peaks, c.peak_threshold_ratio) == (25, 5, 0.3)
    assert (c.fill_gap_px, c.min_length_px, c.car_mask) == (120.0, 3.0, CAR_MASK)
    assert HoughConfig(car_mask=[[0, 1, 0, 1]]).car_mask == ((0, 1, 0, 1),)  # type: ignore[arg-type]
    assert HoughConfig(car_mask=()).car_mask == ()
    hash(c)
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.num_peaks = 3  # type: ignore[misc]
    with pytest.raises(ValueError, match="peak_nhood"):
        HoughDetector(HoughConfig(peak_nhood=(3, 401)))


def test_detect_is_deterministic_and_stateless() -> None:
    f = frame_with((100, 477, 300, 219), (650, 477, 430, 219), (370, 300, 380, 479))
    det = HoughDetector()
    a = det.detect(f)
    det.detect(np.zeros_like(f))
    b = det.detect(f)
    c = HoughDetector().detect(f)
    for other in (b, c):
        for fld in dataclasses.fields(HoughResult):
            x, y = getattr(a, fld.name), getattr(other, fld.name)
            assert np.array_equal(x, y) if isinstance(x, np.ndarray) else x == y, fld.name


def test_on_a_rendered_straight_road_segments_lie_on_the_markings() -> None:
    from tfalda_sim.evaluation import lane_hit_rates, truth_distance
    from tfalda_sim.rendering import Effects, Renderer, build_scene, frame_truth
    from tfalda_sim.tracks import load_named

    track = load_named("straight")
    renderer = Renderer()
    scene = build_scene(track, Effects(), np.random.default_rng(0))
    x, y, h = track.pose(1.0, -0.5 * track.lane_width_m)
    pose = (float(x), float(y), float(h))
    frame = renderer.render(scene, pose, frame_seed=0)
    truth = frame_truth(track, renderer.camera, pose, bonnet=renderer.bonnet)
    r = HoughDetector(HoughConfig.simulator()).detect(frame)
    # Both lines of the ego lane, and nothing off the markings.
    assert len(r.segments) >= 2
    assert lane_hit_rates(r.segments, truth_distance(truth.labels)).min() >= 0.9
    assert np.ptp(r.segments[:, [0, 2]].mean(axis=1)) > 200  # left and right of the image


def test_the_simulator_mask_covers_the_bonnet_and_nothing_above_it() -> None:
    from tfalda_sim.rendering import Renderer

    cfg = HoughConfig.simulator()
    bonnet = Renderer().geometry.bonnet.astype(bool)[cfg.crop_top_px:][:cfg.crop_height_px]
    mask = apply_car_mask(np.ones_like(bonnet), cfg.car_mask)  # False where masked
    assert not (bonnet & mask).any()  # every bonnet pixel masked
    assert mask[~bonnet.any(axis=1)].all()  # every row above the bonnet kept
