"""The ``"lanes"`` observation: a ``LaneObservation`` as a normalised float32 vector.

For ``n`` ROIs (``R`` rows, ``n = 2R``; the thesis: R = 2, n = 4, 42 entries) in the
detector's order (row by row from the top, left ROI before right):

| indices | entry | range |
|---|---|---|
| ``[0, 4n)`` | per ROI: lane ends ``x_top / W, y_top / H, x_bottom / W, y_bottom / H`` | [−1, 2] |
| ``[4n, 5n)`` | per ROI: centre column of the ROI read this frame ``/ W`` | [0, 1] |
| ``[5n, 6n)`` | per ROI: 1 if the LIS replaced the lane by last frame's | {0, 1} |
| ``[6n, 7n)`` | per ROI: 1 if the vertical check corrected the lane | {0, 1} |
| ``[7n, 7n + 2R)`` | per row: filtered lane width at its top, bottom edge ``/ W`` | [0, 2] |
| ``7n + 2R`` | LIS fault counter ``/ (fault limit + 1)`` | [0, 1] |
| ``+1`` | 1 if the LIS reset in this frame | {0, 1} |
| ``+2`` | 1 if this was a first frame (start or after a reset) | {0, 1} |
| ``+3 … +7`` | driving state one-hot (order ``STATES``) | {0, 1} |
| ``+8`` | car speed ``/`` top speed (odometry) | [0, 1] |
| ``+9`` | front-wheel angle ``/`` steering limit (servo feedback) | [−1, 1] |

W = 752, H = 480 [px]. Values are clipped into the ranges (a lane end may lie a little
outside its ROI); a missing lane reads −1, any other missing value 0.
``lane_vector_names`` gives the name of every index; ``read_lane_vector`` is the inverse
of ``lane_vector`` (every user of the layout decodes through it, never by offsets).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from numba import njit

from tfalda_sim.perception import LaneObservation, StateKind

STATES: tuple[StateKind, ...] = (StateKind.STRAIGHT, StateKind.LEFT_CURVE,
                                 StateKind.RIGHT_CURVE, StateKind.LANE_CHANGE_LEFT,
                                 StateKind.LANE_CHANGE_RIGHT)
"""Order of the driving-state one-hot."""


def lane_vector_names(rows: int) -> list[str]:
    """The name of each entry of the vector for ``rows`` ROI rows."""
    rois = [f"r{r}_{side}" for r in range(rows) for side in ("left", "right")]
    names = [f"{roi}_{end}" for roi in rois
             for end in ("x_top", "y_top", "x_bottom", "y_bottom")]
    names += [f"{roi}_roi_centre_x" for roi in rois]
    names += [f"{roi}_replaced" for roi in rois]
    names += [f"{roi}_corrected" for roi in rois]
    names += [f"r{r}_width_{edge}" for r in range(rows) for edge in ("top", "bottom")]
    names += ["fault_count", "roi_reset", "first_frame"]
    names += [f"state_{s.name.lower()}" for s in STATES]
    names += ["speed", "steer"]
    return names


def lane_vector_bounds(rows: int) -> tuple[np.ndarray, np.ndarray]:
    """``(low, high)`` float32 bounds of the vector for ``rows`` ROI rows."""
    low, high = _bounds(rows)
    return low.copy(), high.copy()


@functools.lru_cache(maxsize=8)
def _bounds(rows: int) -> tuple[np.ndarray, np.ndarray]:
    n = 2 * rows
    size = len(lane_vector_names(rows))
    low = np.zeros(size, np.float32)
    high = np.ones(size, np.float32)
    low[:4 * n] = -1.0
    high[:4 * n] = 2.0
    high[7 * n:7 * n + 2 * rows] = 2.0
    low[-1] = -1.0
    return low, high


def lane_vector(obs: LaneObservation, *, image_width: int, image_height: int,
                fault_limit: int, speed_ratio: float, steer_ratio: float,
                out: np.ndarray | None = None) -> np.ndarray:
    """Encode ``obs`` (and the car's odometry ratios) as the documented float32 vector."""
    low, high = _bounds(obs.n_rows)
    v = np.empty(len(low), np.float32) if out is None else out
    _encode(v, obs.lanes, obs.rois, obs.replaced, obs.corrected, obs.widths,
            float(image_width), float(image_height), obs.fault_count / (fault_limit + 1),
            bool(obs.roi_reset), bool(obs.first_frame), STATES.index(obs.state),
            float(speed_ratio), float(steer_ratio), low, high)
    return v


@njit(cache=True)
def _encode(v: np.ndarray, lanes: np.ndarray, rois: np.ndarray, replaced: np.ndarray,
            corrected: np.ndarray, widths: np.ndarray, width: float, height: float,
            fault_share: float, roi_reset: bool, first_frame: bool, state: int,
            speed_ratio: float, steer_ratio: float, low: np.ndarray, high: np.ndarray
            ) -> None:
    """The vector's entries in one pass (it was a dozen small numpy calls per step): the
    same float64 arithmetic rounded once to float32, a missing lane −1, other NaNs 0, then
    clipped into ``[low, high]``."""
    n = lanes.shape[0]
    rows = widths.shape[0]
    f32 = np.float32
    for i in range(n):
        for j in range(4):
            x = f32(lanes[i, j] / (width if j % 2 == 0 else height))
            v[4 * i + j] = f32(-1.0) if np.isnan(x) else x
        v[4 * n + i] = f32((rois[i, 0] + 0.5 * rois[i, 2]) / width)
        v[5 * n + i] = f32(replaced[i])
        v[6 * n + i] = f32(corrected[i])
    for r in range(rows):
        v[7 * n + 2 * r] = f32(widths[r, 0] / width)
        v[7 * n + 2 * r + 1] = f32(widths[r, 1] / width)
    k = 7 * n + 2 * rows
    v[k] = f32(fault_share)
    v[k + 1] = f32(roi_reset)
    v[k + 2] = f32(first_frame)
    for s in range(len(STATES)):
        v[k + 3 + s] = f32(1.0) if s == state else f32(0.0)
    v[-2] = f32(speed_ratio)
    v[-1] = f32(steer_ratio)
    for i in range(len(v)):
        x = v[i]
        if np.isnan(x):
            x = f32(0.0)
        v[i] = min(max(x, low[i]), high[i])


def lane_vector_rows(size: int) -> int:
    """The ROI rows ``R`` of a vector of ``size`` entries (``16 R + 10``)."""
    rows = (size - 10) // 16
    if rows < 1 or 16 * rows + 10 != size:
        raise ValueError(f"not a lanes observation: {size} entries (expected 16·rows + 10, "
                         "e.g. 42 for the thesis' two rows)")
    return rows


@dataclass(frozen=True)
class LaneVector:
    """A decoded ``"lanes"`` observation (``read_lane_vector``), in the detector's order
    (row by row from the top, left ROI before right)."""

    lanes: np.ndarray
    """(n, 4) lane ends x_top, y_top, x_bottom, y_bottom [px]; NaN rows: missing lanes."""
    roi_centre_x_px: np.ndarray
    """(n,) centre column of the ROI read this frame [px]."""
    replaced: np.ndarray
    """(n,) bool: the LIS replaced the lane by last frame's."""
    corrected: np.ndarray
    """(n,) bool: the vertical check corrected the lane."""
    widths_px: np.ndarray
    """(R, 2) filtered lane width at each row's top and bottom edge [px]."""
    fault_share: float
    """LIS fault counter / (fault limit + 1) [0, 1]."""
    roi_reset: bool
    """The LIS reset the ROIs in this frame."""
    first_frame: bool
    """A first frame (start or after an ROI reset)."""
    state: StateKind
    """The driving state."""
    speed_ratio: float
    """Car speed / top speed [0, 1]."""
    steer_ratio: float
    """Front-wheel angle / steering limit [−1, 1]."""

    @property
    def rows(self) -> int:
        return len(self.widths_px)


def read_lane_vector(vector: np.ndarray | dict[str, np.ndarray], *, image_width: int,
                     image_height: int) -> LaneVector:
    """The inverse of ``lane_vector`` (of a dict observation, its ``"lanes"``); values
    ``lane_vector`` clipped stay clipped, a lane that read −1 is NaN."""
    v = np.asarray(vector["lanes"] if isinstance(vector, dict) else vector,
                   np.float64).ravel()
    rows = lane_vector_rows(len(v))
    n = 2 * rows
    ends = v[:4 * n].reshape(n, 4)
    lanes = ends * [image_width, image_height, image_width, image_height]
    lanes[np.any(ends < 0.0, axis=1)] = np.nan  # a missing lane reads −1
    k = 7 * n + 2 * rows
    return LaneVector(
        lanes=lanes,
        roi_centre_x_px=v[4 * n:5 * n] * image_width,
        replaced=v[5 * n:6 * n] > 0.5,
        corrected=v[6 * n:7 * n] > 0.5,
        widths_px=v[7 * n:k].reshape(rows, 2) * image_width,
        fault_share=float(v[k]),
        roi_reset=bool(v[k + 1] > 0.5),
        first_frame=bool(v[k + 2] > 0.5),
        state=STATES[int(np.argmax(v[k + 3:k + 3 + len(STATES)]))],
        speed_ratio=float(v[-2]),
        steer_ratio=float(v[-1]),
    )
