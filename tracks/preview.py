"""Top views of a track, in one palette: the preview PNG (markings from the rasteriser,
obstacles, start and direction) and the base of the env's render inset
(``tfalda_sim.rendering.topdown``, which adds the car)."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np

from .model import Track
from .raster import DEFAULT_RESOLUTION_M, MarkingMap, rasterize
from .rules import obstacle_corners

# The palette of every top view (BGR).
MAT_BGR = (24, 24, 24)
ROAD_BGR = (64, 64, 64)
PAINT_BGR = (255, 255, 255)
OBSTACLE_BGR = (0, 140, 255)
START_BGR = (60, 200, 60)
ARROW_BGR = (230, 180, 60)
TEXT_BGR = (255, 255, 255)

SHIFT = 4
"""Fractional bits of the points given to cv2's drawing (1/16 px)."""


def to_px(m: MarkingMap, points_m: np.ndarray) -> np.ndarray:
    """World points ``(..., 2)`` [m] → fixed-point pixel points of ``m``'s image for cv2
    drawing with ``shift=SHIFT``."""
    return np.rint(m.world_to_pixel(points_m) * (1 << SHIFT)).astype(np.int32)


def top_view(track: Track, resolution_m: float) -> tuple[np.ndarray, MarkingMap]:
    """The track from above at ``resolution_m`` [m/px] (BGR): the road on the mat, its
    markings (``rasterize``) and its obstacles; and the marking map, whose pixels they
    are (``MarkingMap.world_to_pixel``)."""
    m = rasterize(track, resolution_m)
    img = np.empty((*m.shape, 3), np.uint8)
    img[:] = MAT_BGR
    # The road surface, so the layout reads even where lines are missing.
    _, centre = track.sample(0.05)
    cv2.polylines(img, [to_px(m, centre)], track.closed, ROAD_BGR,
                  max(1, round(2 * track.half_road_m / resolution_m)), cv2.LINE_AA,
                  shift=SHIFT)
    paint = m.intensity.astype(np.float32)[..., None] / 255.0
    img = (img * (1.0 - paint) + np.float32(PAINT_BGR) * paint).astype(np.uint8)
    for k in range(len(track.obstacles)):
        cv2.fillPoly(img, [to_px(m, obstacle_corners(track, k))], OBSTACLE_BGR, cv2.LINE_AA,
                     shift=SHIFT)
    return img, m


def preview_image(track: Track, max_side_px: int = 1600) -> np.ndarray:
    """A BGR top view of the track, at most ``max_side_px`` on its longer side, with the
    driving direction, the start and a label."""
    xmin, ymin, xmax, ymax = track.bounds(0.3)
    res = max(DEFAULT_RESOLUTION_M, max(xmax - xmin, ymax - ymin) / max_side_px)
    img, m = top_view(track, res)
    scale = 1.0 / res  # px per metre
    right = -track.lane_width_m / 2
    # Driving direction: an arrow every few metres along the right lane.
    total = track.length_m
    n_arrows = max(2, int(total // 3.0))
    for s_a in np.linspace(0.0, total, n_arrows, endpoint=False)[1:]:
        a = to_px(m, track.position(s_a, right))
        b = to_px(m, track.position(min(s_a + 0.35, total), right))
        cv2.arrowedLine(img, tuple(a), tuple(b), ARROW_BGR, max(1, int(0.03 * scale)),
                        cv2.LINE_AA, shift=SHIFT, tipLength=0.4)
    start = to_px(m, track.position(0.0, right))
    tip = to_px(m, track.position(min(0.8, total), right))
    cv2.circle(img, tuple(start), max(3, int(0.12 * scale)) << SHIFT, START_BGR, -1,
               cv2.LINE_AA, shift=SHIFT)
    cv2.arrowedLine(img, tuple(start), tuple(tip), START_BGR, max(2, int(0.05 * scale)),
                    cv2.LINE_AA, shift=SHIFT, tipLength=0.3)
    label = f"{track.name or 'track'}  {total:.1f} m"
    if math.isfinite(track.min_centre_radius_m):
        label += f"  min R {track.min_centre_radius_m:.2f} m"
    cv2.putText(img, label, (10, 28), cv2.FONT_HERSHEY_SIMPLEX, 0.8, TEXT_BGR, 2,
                cv2.LINE_AA)
    start_at = np.rint(m.world_to_pixel(track.position(0.0, right))).astype(np.int32)
    cv2.putText(img, "START", tuple(start_at + np.array([12, -12])),
                cv2.FONT_HERSHEY_SIMPLEX, 0.6, START_BGR, 2, cv2.LINE_AA)
    return img


def write_preview(track: Track, path: str | Path, *, overwrite: bool = False,
                  max_side_px: int = 1600) -> Path:
    """Write the preview PNG; an existing file is kept unless ``overwrite``."""
    target = Path(path)
    if target.suffix.lower() != ".png":
        raise ValueError(f"preview must be a .png file, got {target.name!r}")
    if target.exists() and not overwrite:
        raise FileExistsError(f"{target} exists; pass overwrite=True (CLI: --force) to replace it")
    target.parent.mkdir(parents=True, exist_ok=True)
    ok, buf = cv2.imencode(".png", preview_image(track, max_side_px))
    if not ok:
        raise OSError(f"could not encode {target} as PNG")
    target.write_bytes(buf.tobytes())
    return target
