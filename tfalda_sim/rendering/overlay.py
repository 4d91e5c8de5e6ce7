"""The thesis' TFALDA Visualizer (chapter 4): a camera frame in colour with the ROIs, the
lanes and, optionally, the ground truth drawn in."""

from __future__ import annotations

import cv2
import numpy as np

from ..perception import LaneObservation
from .truth import FrameTruth

ROI_BGR = (255, 160, 0)
LANE_BGR = (0, 220, 0)
"""A lane TFALDA found and the LIS accepted."""
REPLACED_BGR = (0, 0, 255)
"""A lane the LIS rejected (the last frame's lane is shown)."""
CORRECTED_BGR = (0, 220, 255)
"""A lane the vertical check moved."""
TRUTH_BGR = (255, 0, 255)


def to_bgr(frame: np.ndarray) -> np.ndarray:
    """A (h, w) uint8 grey frame as (h, w, 3) BGR; colour frames are copied."""
    if frame.dtype != np.uint8 or frame.ndim not in (2, 3):
        raise ValueError(f"frame must be a uint8 (h, w) or (h, w, 3) image, got "
                         f"{frame.dtype} {frame.shape}")
    return cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR) if frame.ndim == 2 else frame.copy()


def draw_observation(frame: np.ndarray, obs: LaneObservation, *,
                     truth: FrameTruth | None = None, text: str | None = None) -> np.ndarray:
    """The frame (grey or BGR) with ``obs``'s ROIs and lanes drawn: green accepted, red
    replaced by the LIS, yellow vertically corrected; the truth's ego-lane boundaries in
    magenta when given; a status line (frame, state, fault counter, ``text``) at the top."""
    out = to_bgr(frame)
    if truth is not None:
        for line in (truth.left_boundary_px, truth.right_boundary_px):
            if len(line) >= 2:
                cv2.polylines(out, [np.rint(line * 4).astype(np.int32)], False, TRUTH_BGR, 1,
                              cv2.LINE_AA, shift=2)
    for (x, y, w, h) in obs.rois:
        cv2.rectangle(out, (int(x), int(y)), (int(x + w - 1), int(y + h - 1)), ROI_BGR, 1)
    for k, lane in enumerate(obs.lanes):
        if not np.all(np.isfinite(lane)):
            continue
        colour = (REPLACED_BGR if obs.replaced[k] else
                  CORRECTED_BGR if obs.corrected[k] else LANE_BGR)
        p0 = np.rint(lane[:2] * 4).astype(int)
        p1 = np.rint(lane[2:] * 4).astype(int)
        cv2.line(out, tuple(p0), tuple(p1), colour, 2, cv2.LINE_AA, shift=2)
    status = f"frame {obs.frame}  {obs.state.name.lower()}  faults {obs.fault_count}"
    if obs.reset:
        status += "  RESET"
    if text:
        status = f"{text}  {status}"
    (tw, th), base = cv2.getTextSize(status, cv2.FONT_HERSHEY_SIMPLEX, 0.5, 1)
    cv2.rectangle(out, (4, 4), (12 + tw, 12 + th + base), (0, 0, 0), -1)
    cv2.putText(out, status, (8, 8 + th), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1,
                cv2.LINE_AA)
    return out
