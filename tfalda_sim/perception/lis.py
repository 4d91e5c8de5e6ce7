"""The Lane Inference System (thesis section 2, listing A.4), on lanes alone.

Per ROI row, bottom row first as in listing 3.3 / A.4, in this order:

1. low-pass filter of the lane width at the row's top and bottom edge (eq. 2.1/2.2; it runs
   every frame, also when the row is rejected);
2. min/max check of the measured widths (table 2.3);
3. width-change check of the filtered widths (listing 2.2 / A.4);
   a rejected row takes the previous frame's lanes and raises the fault counter, an
   accepted one lowers it by one (not below 0);
4. vertical check (section 2.2, eq. 2.4): the lane above fixes the direction, the lower
   lane's upper end is moved onto its line when they differ by more than the tolerance;
5. the filtered widths are remembered.

After the rows: a fault counter above the limit asks for a reset (section 2.4).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from .params import LisConfig, WidthCheck
from .segment import LaneSegment

Rows = list[tuple[LaneSegment, LaneSegment]]
"""Lanes per ROI row, top row first: (left, right)."""

def width_limits(config: LisConfig, y_px: float) -> tuple[float, float]:
    """(min, max) lane width [px] at image row ``y_px``: table 2.3's values at its four
    rows, linear in between (for layouts with more than two rows) and held beyond."""
    rows, lo, hi = _limit_table(config)
    return float(np.interp(y_px, rows, lo)), float(np.interp(y_px, rows, hi))


@functools.lru_cache(maxsize=16)
def _limit_table(config: LisConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``width_limits``' rows, minima and maxima as arrays, made once per configuration
    (four times a frame they cost more than the interpolation)."""
    return (np.array(config.width_limit_rows_px, np.float64),
            np.array([a for a, _ in config.width_limits_px], np.float64),
            np.array([b for _, b in config.width_limits_px], np.float64))


def tolerance_scale(config: LisConfig, y_px: float) -> float:
    """The factor on the LIS's pixel tolerances at image row ``y_px`` (1 on the thesis'
    camera)."""
    return float(np.interp(y_px, config.width_limit_rows_px, config.tolerance_scale))


def measured_widths(left: LaneSegment, right: LaneSegment) -> tuple[float, float]:
    """Lane width at the row's top and bottom edge [px] (listing A.4 ``lowpass``)."""
    return right.x_top - left.x_top, right.x_bottom - left.x_bottom


def vertical_target(upper: LaneSegment, lower: LaneSegment) -> float:
    """x [px] of the upper lane's line at the height midway between its lower end and the
    lower lane's upper end: eq. 2.4, ``x = x1 − (x2 − x1)/(y2 − y1) · (y1 − y)`` with P1 the
    upper lane's lower end and P2 its upper end (listing A.4 has an operator-precedence slip
    here; the equation is used)."""
    x1, y1 = upper.x_bottom, upper.y_bottom
    x2, y2 = upper.x_top, upper.y_top
    y = 0.5 * (lower.y_top + y1)
    if y2 == y1:
        return x1
    return x1 - (x2 - x1) / (y2 - y1) * (y1 - y)


@dataclass(frozen=True)
class LisResult:
    """What the LIS made of one frame's lanes."""

    rows: Rows
    replaced: list[bool]  # per row: took the previous frame's lanes
    corrected: list[tuple[bool, bool]]  # per row and side: upper end moved by the vertical check
    widths: np.ndarray  # (rows, 2) filtered widths at the top and bottom edge [px]
    fault_count: int
    roi_reset_due: bool


class LaneInferenceSystem:
    """The LIS's memory (filtered widths, fault counter) and its per-frame inference."""

    def __init__(self, config: LisConfig, rows: int) -> None:
        self.config = config
        self.widths = np.zeros((rows, 2))  # y_{n−1}: last filtered widths [px]
        # the thesis camera's tolerances are the thesis' pixels: no per-frame interpolation
        self._unit_scale = all(s == 1.0 for s in config.tolerance_scale)
        # Looked up here once: hashing the (frozen, uncached) config for the cache four
        # times a frame cost more than the interpolation.
        self._limits = _limit_table(config)
        self._row_limits: dict[tuple[float, float], tuple[float, float, float, float]] = {}
        self.fault_count = 0

    def __getstate__(self) -> dict[str, object]:
        state = self.__dict__.copy()
        del state["_limits"]  # derived from the config: pickles stay as they were
        state.pop("_row_limits", None)
        return state

    def __setstate__(self, state: dict[str, object]) -> None:
        self.__dict__.update(state)
        self._limits = _limit_table(self.config)
        self._row_limits = {}

    def start(self, rows: Rows) -> None:
        """Initialise the filter with a first frame's widths (listing A.4 ``init``)."""
        self.widths = np.array([measured_widths(left, right) for left, right in rows],
                               dtype=np.float64)

    def reset(self) -> None:
        self.fault_count = 0

    def infer(self, rows: Rows, previous: Rows) -> LisResult:
        """Check and correct ``rows`` (this frame's lanes) against ``previous`` (the last
        frame's final lanes)."""
        cfg = self.config
        alpha = cfg.alpha
        out = list(rows)
        replaced = [False] * len(rows)
        corrected = [(False, False)] * len(rows)
        new_widths = self.widths.copy()
        # Per row two widths (top, bottom edge): plain floats, the same IEEE operations as
        # on two-element arrays at a fraction of their cost per frame.
        for r in range(len(rows) - 1, -1, -1):  # bottom row first
            left, right = out[r]
            measured = measured_widths(left, right)
            last = (float(self.widths[r, 0]), float(self.widths[r, 1]))
            filtered = ((alpha * measured[0] + (1.0 - alpha) * last[0],
                         alpha * measured[1] + (1.0 - alpha) * last[1]) if cfg.lowpass
                        else measured)
            ok = True
            if cfg.min_max:  # ``width_limits`` at both edges
                lo0, lo1, hi0, hi1 = self.limits_at(left.y_top, left.y_bottom)
                ok = lo0 <= measured[0] <= hi0 and lo1 <= measured[1] <= hi1
            if ok and cfg.width_change:
                seen = filtered if cfg.width_check is WidthCheck.FILTERED else measured
                tol = cfg.width_tolerance_px
                tols = (tol, tol) if self._unit_scale else (
                    tol * tolerance_scale(cfg, left.y_top),
                    tol * tolerance_scale(cfg, left.y_bottom))
                ok = abs(seen[0] - last[0]) <= tols[0] and abs(seen[1] - last[1]) <= tols[1]
            if not ok:
                out[r] = previous[r]
                replaced[r] = True
                self.fault_count += 1
            elif self.fault_count > 0:
                self.fault_count -= 1
            if cfg.vertical and r > 0:
                out[r], corrected[r] = self._vertical(out[r - 1], out[r])
            new_widths[r] = filtered
        self.widths = new_widths
        roi_reset_due = cfg.roi_reset and self.fault_count > cfg.fault_limit
        return LisResult(out, replaced, corrected, new_widths.copy(), self.fault_count,
                         roi_reset_due)

    def limits_at(self, y_top: float, y_bottom: float) -> tuple[float, float, float, float]:
        """``width_limits`` (min, min, max, max) at a row's top and bottom edge [px]: np.interp
        of the table, remembered per row (the ROI rows keep their heights, and two
        interpolations per row and frame cost more than the rest of the check)."""
        key = (y_top, y_bottom)
        found = self._row_limits.get(key)
        if found is None:
            table_rows, table_lo, table_hi = self._limits
            los = np.interp(key, table_rows, table_lo)
            his = np.interp(key, table_rows, table_hi)
            if len(self._row_limits) >= 64:  # bounded, whatever the ROIs do
                self._row_limits.clear()
            found = self._row_limits[key] = (float(los[0]), float(los[1]), float(his[0]),
                                             float(his[1]))
        return found

    def _vertical(self, upper: tuple[LaneSegment, LaneSegment],
                  lower: tuple[LaneSegment, LaneSegment]
                  ) -> tuple[tuple[LaneSegment, LaneSegment], tuple[bool, bool]]:
        cfg = self.config
        new, moved = [], []
        for up, low in zip(upper, lower, strict=True):
            x3 = vertical_target(up, low)
            scale = 1.0 if self._unit_scale else tolerance_scale(cfg, low.y_top)
            if abs(x3 - low.x_top) > cfg.vertical_tolerance_px * scale:
                new.append(low.with_top(low.x_top + cfg.vertical_weight * (x3 - low.x_top)))
                moved.append(True)
            else:
                new.append(low)
                moved.append(False)
        return (new[0], new[1]), (moved[0], moved[1])
