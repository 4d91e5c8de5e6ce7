"""The thesis' TFALDA Visualizer (chapter 4): a camera frame in colour with the ROIs, the
lanes and, optionally, the ground truth drawn in; and the Hough baseline's segments and
its seed's 2×2 stage view."""

from __future__ import annotations

import cv2
import numpy as np

from ..perception import HoughResult, LaneObservation
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
    if obs.roi_reset:
        status += "  RESET"
    if text:
        status = f"{text}  {status}"
    (tw, th), base = cv2.getTextSize(status, cv2.FONT_HERSHEY_SIMPLEX, 0.5, 1)
    cv2.rectangle(out, (4, 4), (12 + tw, 12 + th + base), (0, 0, 0), -1)
    cv2.putText(out, status, (8, 8 + th), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1,
                cv2.LINE_AA)
    return out


# --------------------------------------------------------------------------- Hough baseline
SEGMENT_BGR: tuple[int, int, int] = (0, 0, 255)
"""Hough segments (the seed plots them in red)."""
MASK_BGR: tuple[int, int, int] = (255, 160, 0)
"""Outlines of the car-mask rectangles in the stage view's panel 1 (not in the seed)."""
TITLE_BGR: tuple[int, int, int] = (0, 220, 255)
"""Panel titles and status text."""


def draw_segments(image: np.ndarray, segments: np.ndarray, *, row_offset_px: int = 0) -> None:
    """Draw the segments ``(N, 4)`` (x1, y1, x2, y2) [px] into the BGR ``image``, rows
    shifted by ``-row_offset_px`` (full-image segments on a crop)."""
    for x1, y1, x2, y2 in np.rint(segments).astype(np.int64):
        cv2.line(image, (int(x1), int(y1) - row_offset_px), (int(x2), int(y2) - row_offset_px),
                 SEGMENT_BGR, 2, cv2.LINE_AA)


def _panel(image: np.ndarray) -> np.ndarray:
    """A bool stage image as white-on-black BGR."""
    return cv2.cvtColor(image.astype(np.uint8) * 255, cv2.COLOR_GRAY2BGR)


def _title(panel: np.ndarray, title: str) -> None:
    """``title`` in the panel's top-left corner, outlined in black to read on white."""
    org = (8, 22)
    cv2.putText(panel, title, org, cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 0, 0), 4, cv2.LINE_AA)
    cv2.putText(panel, title, org, cv2.FONT_HERSHEY_SIMPLEX, 0.6, TITLE_BGR, 1, cv2.LINE_AA)


def draw_hough(frame: np.ndarray, result: HoughResult, *, text: str = "") -> np.ndarray:
    """The frame (grey or BGR) with the Hough segments in red and a status line."""
    out = to_bgr(frame)
    draw_segments(out, result.segments)
    cv2.putText(out, f"{text} hough: {len(result.segments)} segments".strip(), (8, 20),
                cv2.FONT_HERSHEY_SIMPLEX, 0.5, TITLE_BGR, 1, cv2.LINE_AA)
    return out


def stage_view(result: HoughResult) -> np.ndarray:
    """The seed's 2×2 figure as one uint8 BGR image, (2·crop_height, 2·752, 3). The panels
    are crop-sized: 1) ROI + im2bw, with the car mask outlined, 2) Sobel edges, 3) merged
    lines, 4) the Hough segments in red over the merged image."""
    p1 = _panel(result.binary)
    for r0, r1, c0, c1 in result.car_mask:
        cv2.rectangle(p1, (c0, r0), (c1 - 1, r1 - 1), MASK_BGR, 1)
    p2 = _panel(result.sobel)
    p3 = _panel(result.merged)
    p4 = p3.copy()
    draw_segments(p4, result.segments, row_offset_px=result.crop_top_px)
    _title(p1, "1) ROI + im2bw" + (" (car mask outlined)" if result.car_mask else ""))
    _title(p2, "2) Sobel, vertical edges")
    _title(p3, "3) merged double edges")
    _title(p4, f"4) Hough: {len(result.segments)} segments")
    return np.vstack((np.hstack((p1, p2)), np.hstack((p3, p4))))
