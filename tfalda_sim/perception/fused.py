"""The detector's per-frame logic after a first frame in one numba call: TFALDA on every
ROI (``find_lane_in_crop``), the gap hold, the LIS (``lis.LaneInferenceSystem.infer``) and
the next frame's ROIs (``detector.TfaldaDetector._place`` with ``rois.follow``,
``rois.classify`` and the curve states' corrections).

The Python path stays the reference: this one does the same float64 operations in the
same order (tested frame by frame against it, every preset, over whole drives), and
``TfaldaDetector`` takes it only where it applies (no forced state, no lane change, no
side to search afresh). As a chain of small Python steps the frame's logic cost about as
much as its four kernel calls.

Lanes travel as rows ``(p, y_top, x_bottom, y_bottom, d, i, λ)`` [px, px, px, px, px, -,
-] (``LaneObservation``'s table, ``x_bottom = p + d``), ROIs as ``(x, y, width, height)``
[px].
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit

from .candidates import find_lane_in_crop
from .lis import LaneInferenceSystem, tolerance_scale
from .params import DetectorConfig, EdgeMode, WidthCheck

# ``FusedParams.flags``' columns
SOBEL_MANAGER, RISING, LOWPASS, MIN_MAX, WIDTH_CHANGE, FILTERED, VERTICAL, ROI_RESET, \
    ROI_PLACEMENT, CURVE_STATES, ROI_FROM_CURRENT = range(11)
# ``FusedParams.reals``' columns
RESAMPLE_FACTOR, SWITCH_RAD_TO_DEG, SWITCH_ANGLE_DEG, KI, GAP_HOLD_RATIO, ALPHA, \
    VERTICAL_TOLERANCE_PX, VERTICAL_WEIGHT = range(8)
# ``FusedParams.layout``' columns
MARGIN_LEFT, EXTRA_WIDTH, MIN_WIDTH, MAX_WIDTH, BORDER, IMAGE_WIDTH, LEFT_CURVE_X, \
    RIGHT_CURVE_END, FAULT_LIMIT = range(9)
# ``FusedParams.rows``' columns, per ROI row: the LIS's width limits [px] at its top and
# bottom edge, its width-change tolerances there [px], the vertical check's tolerance scale
# and the row's kp, kd (λ's weights over the row's ``lambda_scale``)
LO_TOP, LO_BOTTOM, HI_TOP, HI_BOTTOM, TOL_TOP, TOL_BOTTOM, VERTICAL_SCALE, KP, KD = range(9)

STRAIGHT, LEFT_CURVE, RIGHT_CURVE = 0, 1, 2
"""The driving states ``detect_frame`` returns (``rois.StateKind``'s first three)."""

RAD_TO_DEG: float = 180.0 / math.pi
"""``math.degrees``' factor (CPython multiplies by it)."""


@njit(cache=True, error_model="numpy")
def _round(v: float) -> int:
    """Python's ``round`` of a finite float: to the nearest int, halves to even."""
    return int(np.rint(v))


@njit(cache=True, error_model="numpy")
def _follow(p: float, x_bottom: float, d: float, y: int, height: int, layout: np.ndarray,
            out: np.ndarray) -> None:
    """``rois.follow`` of the lane ``(p, x_bottom, d)`` in the ROI row ``y``, ``height``,
    written to ``out`` (x, y, width, height)."""
    x = _round(min(p, x_bottom)) - layout[MARGIN_LEFT]
    width = min(max(layout[EXTRA_WIDTH] + _round(abs(d)), layout[MIN_WIDTH]),
                layout[MAX_WIDTH])
    border, image_width = layout[BORDER], layout[IMAGE_WIDTH]
    width = min(max(width, layout[MIN_WIDTH]), image_width - 2 * border)
    out[0] = min(max(x, border), image_width - border - width)
    out[1] = y
    out[2] = width
    out[3] = height


@njit(cache=True, error_model="numpy")
def _vertical(up: np.ndarray, low: np.ndarray, tolerance: float, weight: float) -> bool:
    """The LIS's vertical check of one side (``lis.LaneInferenceSystem._vertical``): moves
    ``low``'s upper end (in place) towards the line of ``up`` (eq. 2.4); whether it did."""
    x1, y1 = up[2], up[3]
    x2, y2 = up[0], up[1]
    y = 0.5 * (low[1] + y1)
    x3 = x1 if y2 == y1 else x1 - (x2 - x1) / (y2 - y1) * (y1 - y)
    if abs(x3 - low[0]) > tolerance:
        x_top = low[0] + weight * (x3 - low[0])
        x_bottom = low[2]
        low[0] = x_top
        low[4] = x_bottom - x_top
        low[2] = x_top + low[4]
        return True
    return False


@njit(cache=True, error_model="numpy")
def detect_frame(crops: tuple, segments: tuple, rois: np.ndarray, previous: np.ndarray,
                 widths: np.ndarray, fault_count: int, flags: np.ndarray, reals: np.ndarray,
                 layout: np.ndarray, rows: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, bool, int, np.ndarray]:
    """One frame after a first frame: ``crops`` (the ROIs' pixels, row by row, left before
    right) through ``rois`` (n, 4) with last frame's final lanes ``previous`` (n, 7), the
    LIS's filtered ``widths`` (rows, 2) [px] and ``fault_count``.

    Returns the frame's final lanes (n, 7), per lane (replaced, corrected) (n, 2), the new
    filtered widths (rows, 2), the fault count, whether the ROIs reset, the driving state
    (``STRAIGHT`` …; −1: the ROIs were not placed, the detector's state stands) and the
    next frame's ROIs (n, 4) (``rois`` itself when not placed)."""
    n = len(crops)
    n_rows = n // 2
    found = np.empty((n, 7))
    marks = np.zeros((n, 2), np.bool_)
    for k in range(n):
        r = k // 2
        crop = crops[k]
        x, y, w, h = rois[k, 0], rois[k, 1], rois[k, 2], rois[k, 3]
        f = reals[RESAMPLE_FACTOR]
        ch, cw = crop.shape
        small_h, small_w = (ch, cw) if f == 1.0 else (max(2, int(ch / f)), max(1, int(cw / f)))
        prev = previous[k]
        horizontal = False
        if flags[SOBEL_MANAGER]:
            angle = math.atan2(abs(prev[4]), max(prev[3] - prev[1], 1e-9))
            horizontal = angle * reals[SWITCH_RAD_TO_DEG] > reals[SWITCH_ANGLE_DEG]
        p, d, i, lam = find_lane_in_crop(crop, small_h, small_w, segments[k], horizontal,
                                         flags[RISING], np.float64(x), w / small_w, False,
                                         prev[0], prev[4], prev[5], rows[r, KP], rows[r, KD],
                                         reals[KI])
        if i < reals[GAP_HOLD_RATIO] * prev[5]:  # no marking here (a gap): keep the last
            found[k] = prev
            marks[k, 0] = True
        else:
            found[k, 0] = p
            found[k, 1] = np.float64(y)
            found[k, 2] = p + d
            found[k, 3] = np.float64(y + (h - 1))
            found[k, 4] = d
            found[k, 5] = i
            found[k, 6] = lam
    # The LIS, bottom row first (lis.LaneInferenceSystem.infer).
    final = found.copy()
    new_widths = widths.copy()
    alpha = reals[ALPHA]
    for r in range(n_rows - 1, -1, -1):
        left, right = final[2 * r], final[2 * r + 1]
        m0 = right[0] - left[0]
        m1 = right[2] - left[2]
        last0, last1 = widths[r, 0], widths[r, 1]
        f0, f1 = m0, m1
        if flags[LOWPASS]:
            f0 = alpha * m0 + (1.0 - alpha) * last0
            f1 = alpha * m1 + (1.0 - alpha) * last1
        ok = True
        if flags[MIN_MAX]:
            ok = (rows[r, LO_TOP] <= m0 <= rows[r, HI_TOP]
                  and rows[r, LO_BOTTOM] <= m1 <= rows[r, HI_BOTTOM])
        if ok and flags[WIDTH_CHANGE]:
            s0, s1 = (f0, f1) if flags[FILTERED] else (m0, m1)
            ok = abs(s0 - last0) <= rows[r, TOL_TOP] and abs(s1 - last1) <= rows[r, TOL_BOTTOM]
        if not ok:
            final[2 * r] = previous[2 * r]
            final[2 * r + 1] = previous[2 * r + 1]
            marks[2 * r, 0] = marks[2 * r + 1, 0] = True
            fault_count += 1
        elif fault_count > 0:
            fault_count -= 1
        if flags[VERTICAL] and r > 0:
            tolerance = reals[VERTICAL_TOLERANCE_PX] * rows[r, VERTICAL_SCALE]
            for side in range(2):
                marks[2 * r + side, 1] = _vertical(final[2 * (r - 1) + side],
                                                   final[2 * r + side], tolerance,
                                                   reals[VERTICAL_WEIGHT])
        new_widths[r, 0] = f0
        new_widths[r, 1] = f1
    reset = flags[ROI_RESET] and fault_count > layout[FAULT_LIMIT]
    if reset or not flags[ROI_PLACEMENT]:
        return final, marks, new_widths, fault_count, reset, -1, rois
    # The next ROIs (TfaldaDetector._place): each row's pair follows its lanes, then the
    # row's state (rois.classify) corrects it; the frame's state is the topmost row's that
    # is not straight.
    base = final if flags[ROI_FROM_CURRENT] else previous
    placed = np.empty((n, 4), rois.dtype)
    state = STRAIGHT
    border, image_width, min_w = layout[BORDER], layout[IMAGE_WIDTH], layout[MIN_WIDTH]
    for r in range(n_rows):
        a, b = placed[2 * r], placed[2 * r + 1]
        for side in range(2):
            lane = base[2 * r + side]
            _follow(lane[0], lane[2], lane[4], rois[2 * r + side, 1], rois[2 * r + side, 3],
                    layout, placed[2 * r + side])
        kind = STRAIGHT
        if flags[CURVE_STATES]:
            left_end = a[0] + a[2]
            if left_end > b[0] and b[0] < layout[LEFT_CURVE_X]:
                kind = LEFT_CURVE
            elif left_end > b[0] and left_end > layout[RIGHT_CURVE_END]:
                kind = RIGHT_CURVE
        if kind != STRAIGHT:
            k = max(0, a[0] + a[2] - b[0]) // 2
            if kind == LEFT_CURVE:
                a[0] = max(border, a[0] - k)
                a[2] = max(min_w, a[2] - k)
            else:
                b[0] = b[0] + k
                b[2] = max(min_w, b[2] - k)
                b[2] -= max(0, b[0] + b[2] - (image_width - border))
            if state == STRAIGHT:
                state = kind
    return final, marks, new_widths, fault_count, reset, state, placed


@dataclass(frozen=True, slots=True, eq=False)
class FusedParams:
    """``detect_frame``'s constants of one configuration and set of ROI rows."""

    flags: np.ndarray
    """bool: the switches (``SOBEL_MANAGER`` …)."""
    reals: np.ndarray
    """float64: the real parameters (``RESAMPLE_FACTOR`` …)."""
    layout: np.ndarray
    """int64: the ROI layout's numbers [px] and the LIS's fault limit (``MARGIN_LEFT`` …)."""
    rows: np.ndarray
    """float64 (rows, 9): per ROI row (``LO_TOP`` …)."""


def fused_params(config: DetectorConfig, lis: LaneInferenceSystem,
                 rows: Sequence[tuple[int, int]], lambda_scales: Sequence[float]
                 ) -> FusedParams:
    """``detect_frame``'s constants for ``config``, whose ``lis`` gives the width limits,
    and the ROI rows ``(y, height)`` [px]: each value as the Python path computes it."""
    tf, lc, lay = config.tfalda, config.lis, config.layout
    flags = np.zeros(11, np.bool_)
    flags[SOBEL_MANAGER] = tf.sobel_manager
    flags[RISING] = tf.edge_mode is EdgeMode.RISING
    flags[LOWPASS] = lc.lowpass
    flags[MIN_MAX] = lc.min_max
    flags[WIDTH_CHANGE] = lc.width_change
    flags[FILTERED] = lc.width_check is WidthCheck.FILTERED
    flags[VERTICAL] = lc.vertical
    flags[ROI_RESET] = lc.roi_reset
    flags[ROI_PLACEMENT] = lc.roi_placement
    flags[CURVE_STATES] = lc.curve_states
    flags[ROI_FROM_CURRENT] = lc.roi_from_current_lanes
    reals = np.empty(8)
    reals[RESAMPLE_FACTOR] = tf.resample_factor
    reals[SWITCH_RAD_TO_DEG] = RAD_TO_DEG
    reals[SWITCH_ANGLE_DEG] = tf.sobel_switch_angle_deg
    reals[KI] = tf.ki
    reals[GAP_HOLD_RATIO] = lc.gap_hold_ratio
    reals[ALPHA] = lc.alpha
    reals[VERTICAL_TOLERANCE_PX] = lc.vertical_tolerance_px
    reals[VERTICAL_WEIGHT] = lc.vertical_weight
    layout = np.array([lay.margin_left_px, lay.extra_width_px, lay.min_width_px,
                       lay.max_width_px, lay.border_px, lay.image_width,
                       lay.left_curve_right_roi_x_px, lay.right_curve_left_roi_end_px,
                       lc.fault_limit], np.int64)
    unit = all(v == 1.0 for v in lc.tolerance_scale)
    tol = lc.width_tolerance_px
    per_row = np.empty((len(rows), 9))
    for r, ((y, height), scale) in enumerate(zip(rows, lambda_scales, strict=True)):
        y_top, y_bottom = float(y), float(y + height - 1)
        per_row[r, LO_TOP], per_row[r, LO_BOTTOM], per_row[r, HI_TOP], per_row[r, HI_BOTTOM] = (
            lis.limits_at(y_top, y_bottom))
        per_row[r, TOL_TOP] = tol if unit else tol * tolerance_scale(lc, y_top)
        per_row[r, TOL_BOTTOM] = tol if unit else tol * tolerance_scale(lc, y_bottom)
        per_row[r, VERTICAL_SCALE] = 1.0 if unit else tolerance_scale(lc, y_top)
        kp, kd = tf.kp, tf.kd
        if scale != 1.0:
            kp, kd = kp / scale, kd / scale
        per_row[r, KP], per_row[r, KD] = kp, kd
    return FusedParams(flags, reals, layout, per_row)
