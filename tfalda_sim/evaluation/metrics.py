"""Frame metrics: the thesis' black-box hit rate (section 4.1.7: how much of each found
lane lies on a marking of the ground-truth image) and TuSimple-style accuracy with false
positives and negatives against the ego lane's boundaries."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from tfalda_sim.tracks import Marking

from ..rendering.truth import FrameTruth

EPSILON_PX: float = 5.0
"""Largest distance [px] from a lane pixel to a ground-truth marking pixel that still counts
as a hit (section 4.1.7; listing B.1 uses 10 px, the text 5 px: the text is used)."""

LANE_MARKINGS = (Marking.RIGHT_LINE, Marking.CENTRE_LINE, Marking.LEFT_LINE)
"""Ground-truth labels a lane may hit: the three longitudinal lines (the thesis painted
the road's lines; start and stop lines run across and are left out)."""


def dda_pixels(x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    """Integer pixels ``(N, 2)`` (x, y) of the segment between the rounded ends: a DDA, one
    sample per step of its longer axis, ends included, coordinates rounded half to even
    (``np.rint``) — Bresenham's pixels up to ties (the rasterisation of section 4.1.7;
    ``perception.candidates.integer_dda_pixels`` breaks ties away from zero)."""
    ax, ay, bx, by = (round(v) for v in (x0, y0, x1, y1))
    n = max(abs(bx - ax), abs(by - ay)) + 1
    t = np.arange(n) / max(n - 1, 1)
    xs = np.rint(ax + t * (bx - ax)).astype(np.int64)
    ys = np.rint(ay + t * (by - ay)).astype(np.int64)
    return np.column_stack([xs, ys])


def truth_distance(labels: np.ndarray, markings: tuple[Marking, ...] = LANE_MARKINGS
                   ) -> np.ndarray:
    """Distance [px] of every pixel to the nearest ground-truth marking pixel (float32)."""
    mask = np.isin(labels, [int(m) for m in markings])
    if not mask.any():
        return np.full(labels.shape, np.inf, np.float32)
    return cv2.distanceTransform((~mask).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)


def lane_hit_rates(lanes: np.ndarray, distance: np.ndarray, epsilon_px: float = EPSILON_PX
                   ) -> np.ndarray:
    """Per lane ``(x_top, y_top, x_bottom, y_bottom)`` [px]: the share of its pixels within
    ``epsilon_px`` of a marking (pixels outside the image count as misses)."""
    h, w = distance.shape
    rates = np.zeros(len(lanes))
    for k, (x0, y0, x1, y1) in enumerate(np.asarray(lanes, dtype=np.float64)):
        if not np.all(np.isfinite((x0, y0, x1, y1))):
            continue  # a missing lane scores 0
        px = dda_pixels(x0, y0, x1, y1)
        inside = (px[:, 0] >= 0) & (px[:, 0] < w) & (px[:, 1] >= 0) & (px[:, 1] < h)
        d = np.full(len(px), np.inf)
        d[inside] = distance[px[inside, 1], px[inside, 0]]
        rates[k] = float(np.mean(d <= epsilon_px))
    return rates


TUSIMPLE_THRESHOLD_PX: float = 20.0 * 752 / 1280
"""A lane point is correct when it lies closer than this [px] to the truth along its row
(TuSimple's 20 px on 1280-px-wide images, scaled to our 752 px; widened by 1/cos of the
truth's angle to the vertical, as TuSimple does)."""

TUSIMPLE_MIN_ACCURACY: float = 0.85
"""A lane is correct when at least this share of its truth rows is correct (TuSimple);
a found lane below it is a false positive, a truth lane without a correct lane a false
negative."""

TRUTH_MIN_SHARE: float = 0.5
"""A ROI holds a truth lane when the ego-lane boundary it should find crosses at least
this share of its rows; otherwise there is nothing to find there."""

LANE_FAILURE_HIT_RATE: float = 0.5
"""A ROI's lane fails in a frame when less than this share of it hits a marking (our
choice for the per-ROI failure counts: most of the lane is off the markings)."""


def boundary_x_at_rows(polyline: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """x [px] where the polyline ``(k, 2)`` (x, y), ordered from the car outwards, crosses
    each image row; NaN where it does not. A row crossed twice (a curve bending back)
    takes the crossing nearest the car."""
    rows = np.asarray(rows, np.float64)
    out = np.full(len(rows), np.nan)
    p = np.asarray(polyline, np.float64)
    if len(p) < 2 or len(rows) == 0:
        return out
    ya, yb = p[:-1, 1], p[1:, 1]
    xa, xb = p[:-1, 0], p[1:, 0]
    lo, hi = np.minimum(ya, yb), np.maximum(ya, yb)
    # rows × segments: which segment spans which row (flat segments span none)
    spans = (rows[:, None] >= lo[None]) & (rows[:, None] <= hi[None]) & (hi > lo)[None]
    has = spans.any(axis=1)
    first = np.argmax(spans, axis=1)
    seg = first[has]
    t = (rows[has] - ya[seg]) / (yb[seg] - ya[seg])
    out[has] = xa[seg] + t * (xb[seg] - xa[seg])
    return out


def lane_x_at_rows(lane: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """x [px] of the lane ``(x_top, y_top, x_bottom, y_bottom)`` at each row; NaN outside
    its rows, for a missing (non-finite) lane or a flat one."""
    rows = np.asarray(rows, np.float64)
    x0, y0, x1, y1 = (float(v) for v in lane)
    if not np.all(np.isfinite((x0, y0, x1, y1))) or y0 == y1:
        return np.full(len(rows), np.nan)
    t = (rows - y0) / (y1 - y0)
    x = x0 + t * (x1 - x0)
    x[(t < -1e-9) | (t > 1 + 1e-9)] = np.nan
    return x


def tusimple_accuracy(pred_x: np.ndarray, truth_x: np.ndarray, rows: np.ndarray,
                      threshold_px: float = TUSIMPLE_THRESHOLD_PX) -> float:
    """Share of the truth rows (finite ``truth_x``) where the lane is closer than the
    angle-widened threshold; NaN when there is no truth row."""
    ok = np.isfinite(truth_x)
    if not ok.any():
        return float("nan")
    cos = 1.0
    if ok.sum() >= 2:
        slope = np.polyfit(np.asarray(rows, np.float64)[ok], truth_x[ok], 1)[0]
        cos = float(np.cos(np.arctan(slope)))
    err = np.abs(pred_x[ok] - truth_x[ok])
    return float(np.mean(np.nan_to_num(err, nan=np.inf) < threshold_px / cos))


@dataclass(frozen=True)
class FrameScore:
    """The scores of one frame's lanes (one entry per ROI, the detector's order)."""

    hit_rates: np.ndarray
    """(n,) black-box hit rate per lane [0, 1] (section 4.1.7)."""
    accuracy: np.ndarray
    """(n,) TuSimple point accuracy per ROI [0, 1]; NaN where the ROI holds no truth."""
    false_positive: np.ndarray
    """(n,) bool: a lane was given but is not correct (accuracy < 0.85 or no truth)."""
    false_negative: np.ndarray
    """(n,) bool: the ROI holds a truth lane and no correct lane was given."""
    truth_present: np.ndarray
    """(n,) bool: the ROI holds a truth lane (the ego boundary crosses ≥ half its rows)."""

    @property
    def confidence(self) -> float:
        """The thesis' per-frame figure: the mean hit rate of the lanes."""
        return float(self.hit_rates.mean()) if len(self.hit_rates) else float("nan")


def roi_truth_x(truth: FrameTruth, roi: np.ndarray, column: int) -> tuple[np.ndarray, np.ndarray]:
    """The rows [px] of ``roi = (x, y, w, h)`` and where the ego boundary its column should
    find crosses them (left ROIs: the lane's left line, right ROIs: its right line)."""
    y, h = int(roi[1]), int(roi[3])
    rows = np.arange(y, y + h, dtype=np.float64)
    line = truth.left_boundary_px if column == 0 else truth.right_boundary_px
    return rows, boundary_x_at_rows(line, rows)


def score_frame(lanes: np.ndarray, rois: np.ndarray, truth: FrameTruth,
                distance: np.ndarray | None = None, *, epsilon_px: float = EPSILON_PX,
                threshold_px: float = TUSIMPLE_THRESHOLD_PX) -> FrameScore:
    """Score one frame's lanes ``(n, 4)`` found in ``rois`` ``(n, 4)`` (row-major, left
    before right) against ``truth``; pass ``distance`` (``truth_distance``) to reuse it."""
    lanes = np.asarray(lanes, np.float64)
    rois = np.asarray(rois)
    if lanes.ndim != 2 or lanes.shape[1] != 4 or rois.shape != lanes.shape:
        raise ValueError(f"lanes and rois must both be (n, 4), got {lanes.shape} and {rois.shape}")
    if distance is None:
        distance = truth_distance(truth.labels)
    n = len(lanes)
    acc = np.full(n, np.nan)
    present = np.zeros(n, bool)
    for k in range(n):
        rows, tx = roi_truth_x(truth, rois[k], k % 2)
        if len(rows) and np.isfinite(tx).mean() >= TRUTH_MIN_SHARE:
            present[k] = True
            acc[k] = tusimple_accuracy(lane_x_at_rows(lanes[k], rows), tx, rows, threshold_px)
    given = np.all(np.isfinite(lanes), axis=1)
    correct = present & (np.nan_to_num(acc, nan=0.0) >= TUSIMPLE_MIN_ACCURACY)
    return FrameScore(hit_rates=lane_hit_rates(lanes, distance, epsilon_px),
                      accuracy=acc, false_positive=given & ~correct,
                      false_negative=present & ~correct, truth_present=present)
