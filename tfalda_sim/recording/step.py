"""One camera frame of a run as a recording takes it (``RecordedStep``): plain numpy and
Python values, so the recording needs none of the perception or simulation types.

Every field but the time and the frame is optional: a field left ``None`` in every step
gives no channel in the recording (a replay of footage has no pose, the Hough baseline no
LIS). The step checks its shapes when it is made, where a wrong one is the caller's bug.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

LANE_COUNT = 4
"""Lanes (and regions of interest) per frame: TFALDA's four lane lines."""

POLYLINE_TOLERANCE_PX = 0.5
"""How far a recorded polyline may stray from the line it stands for [px]: half a pixel is
invisible over the image, and a marking's polyline sampled every 2 cm on the ground shrinks
from ≈ 150 points to a handful."""


def polyline_segments(points: np.ndarray,
                      tolerance_px: float = POLYLINE_TOLERANCE_PX) -> np.ndarray:
    """An ``(N, 2)`` pixel polyline (NaN points dropped) as ``(k, 4)`` segments for
    ``RecordedStep.truth_lanes``, simplified to within ``tolerance_px`` (Douglas–Peucker,
    OpenCV's ``approxPolyDP``)."""
    pts = np.asarray(points, np.float64)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if len(pts) < 2:
        return np.zeros((0, 4))
    simple = cv2.approxPolyDP(pts.astype(np.float32).reshape(-1, 1, 2), tolerance_px,
                              False).reshape(-1, 2).astype(np.float64)
    return np.hstack([simple[:-1], simple[1:]])


_KINDS = {"f": "float", "i": "int", "u": "unsigned int", "b": "bool"}


def _check(name: str, value: np.ndarray | None, shape: tuple[int | None, ...],
           kinds: str) -> None:
    """``value`` is None or an array of ``shape`` (None: any length) whose dtype kind is
    one of ``kinds`` (numpy's ``dtype.kind`` letters)."""
    if value is None:
        return
    if not isinstance(value, np.ndarray):
        raise TypeError(f"{name} must be a numpy array, got {type(value).__name__}")
    if value.ndim != len(shape) or any(s is not None and s != n
                                       for s, n in zip(shape, value.shape, strict=True)):
        want = "×".join("n" if s is None else str(s) for s in shape)
        raise ValueError(f"{name} must have the shape ({want}), got {value.shape}")
    if value.dtype.kind not in kinds:
        want = " or ".join(_KINDS[k] for k in kinds)
        raise ValueError(f"{name} must hold {want} numbers, got {value.dtype}")


@dataclass(frozen=True, eq=False)  # arrays: == would be ambiguous; a step is itself only
class RecordedStep:
    """What a recording keeps of one camera frame (see ``tfalda_sim.recording.channels``
    for the channel table). Image coordinates are the detector's: x right, y down [px],
    the centre of the top-left pixel at (0, 0)."""

    t_s: float
    """Time of the frame from the run's start [s]; finite, ≥ 0, increasing from step to
    step (a message's time stamp is the recording's start + ``t_s``)."""
    frame: np.ndarray
    """(H, W) uint8 grey camera frame, as the detector saw it."""
    lanes: np.ndarray | None = None
    """(4, 4) float (x_top, y_top, x_bottom, y_bottom) [px]; a NaN row: no lane (TFALDA)."""
    accepted: np.ndarray | None = None
    """(4,) bool: the lanes the LIS kept (False: replaced by its estimate); needs ``lanes``."""
    rois: np.ndarray | None = None
    """(4, 4) int (x, y, w, h) [px]: the regions of interest the detector searched."""
    fault_counter: int | None = None
    """The LIS' consecutive fault frames; the LIS fields come all three or none."""
    roi_reset: bool | None = None
    """The LIS reset the regions of interest in this frame."""
    state: str | None = None
    """The LIS state's name."""
    segments: np.ndarray | None = None
    """(n, 4) float (x0, y0, x1, y1) [px]: line segments of the Hough baseline."""
    pose: tuple[float, float, float] | None = None
    """The car's x [m], y [m] and yaw [rad] in the track's frame."""
    speed_m_s: float | None = None
    """The car's forward speed [m/s]; needs ``pose``."""
    truth_lanes: np.ndarray | None = None
    """(k, 4) float (x0, y0, x1, y1) [px]: the true lane lines in the image as straight
    segments (a curved line as several); shown over the image, not a data channel."""
    cross_track_m: float | None = None
    """The car's signed distance from the lane's centre line [m] (ground truth)."""
    top_view: np.ndarray | None = None
    """(h, w, 3) uint8 BGR top-down picture of the run."""

    def __post_init__(self) -> None:
        if not (isinstance(self.t_s, (int, float, np.floating, np.integer))
                and math.isfinite(self.t_s) and self.t_s >= 0):
            raise ValueError(f"t_s must be a finite time ≥ 0 [s], got {self.t_s!r}")
        if isinstance(self.frame, np.ndarray) and self.frame.dtype != np.uint8:
            raise ValueError(f"frame must be uint8 grey, got {self.frame.dtype}")
        _check("frame", self.frame, (None, None), "u")
        _check("lanes", self.lanes, (LANE_COUNT, 4), "fiu")
        _check("accepted", self.accepted, (LANE_COUNT,), "b")
        if self.accepted is not None and self.lanes is None:
            raise ValueError("accepted needs lanes (the lanes it judges)")
        _check("rois", self.rois, (LANE_COUNT, 4), "iu")
        _check("segments", self.segments, (None, 4), "fiu")
        _check("truth_lanes", self.truth_lanes, (None, 4), "fiu")
        if isinstance(self.top_view, np.ndarray) and self.top_view.dtype != np.uint8:
            raise ValueError(f"top_view must be uint8 BGR, got {self.top_view.dtype}")
        _check("top_view", self.top_view, (None, None, 3), "u")
        lis = (self.fault_counter, self.roi_reset, self.state)
        if any(v is None for v in lis) and any(v is not None for v in lis):
            raise ValueError("the LIS fields fault_counter, roi_reset and state come all "
                             f"three or none, got {lis}")
        if self.pose is not None:
            if len(self.pose) != 3 or not all(math.isfinite(v) for v in self.pose):
                raise ValueError(f"pose must be finite (x [m], y [m], yaw [rad]), got "
                                 f"{self.pose!r}")
        elif self.speed_m_s is not None:
            raise ValueError("speed_m_s needs pose (odometry carries both)")
        for name in ("speed_m_s", "cross_track_m"):
            value = getattr(self, name)
            if value is not None and not math.isfinite(value):
                raise ValueError(f"{name} must be finite, got {value!r}")

    @property
    def has_lis(self) -> bool:
        """The step carries the LIS state."""
        return self.state is not None
