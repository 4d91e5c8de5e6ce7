"""PNG preview of a track: markings from the rasteriser, obstacles, start and direction."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np

from .model import Track
from .raster import DEFAULT_RESOLUTION_M, rasterize
from .rules import obstacle_corners

_ROAD_BGR = (40, 40, 40)
_OBSTACLE_BGR = (0, 140, 255)
_START_BGR = (60, 200, 60)
_ARROW_BGR = (230, 180, 60)


def preview_image(track: Track, max_side_px: int = 1600) -> np.ndarray:
    """A BGR top view of the track, at most ``max_side_px`` on its longer side."""
    xmin, ymin, xmax, ymax = track.bounds(0.3)
    res = max(DEFAULT_RESOLUTION_M, max(xmax - xmin, ymax - ymin) / max_side_px)
    m = rasterize(track, res)
    img = np.zeros((*m.shape, 3), np.uint8)
    # Road surface in dark grey so the layout reads even where lines are missing.
    to_px = lambda a: np.rint(a).astype(np.int32)  # noqa: E731
    _, centre = track.sample(0.05)
    cv2.polylines(img, [to_px(m.world_to_pixel(centre))], track.closed, _ROAD_BGR,
                  max(1, round(2 * track.half_road_m / res)), cv2.LINE_AA)
    paint = m.intensity.astype(np.float32)[..., None] / 255.0
    img = (img * (1.0 - paint) + 255.0 * paint).astype(np.uint8)
    for k in range(len(track.obstacles)):
        cv2.fillPoly(img, [to_px(m.world_to_pixel(obstacle_corners(track, k)))], _OBSTACLE_BGR)
    scale = 1.0 / res  # px per metre
    # Driving direction: an arrow every few metres along the right lane.
    total = track.length_m
    n_arrows = max(2, int(total // 3.0))
    for s_a in np.linspace(0.0, total, n_arrows, endpoint=False)[1:]:
        a = m.world_to_pixel(track.position(s_a, -track.lane_width_m / 2))
        b = m.world_to_pixel(track.position(min(s_a + 0.35, total), -track.lane_width_m / 2))
        cv2.arrowedLine(img, tuple(to_px(a)), tuple(to_px(b)), _ARROW_BGR,
                        max(1, int(0.03 * scale)), cv2.LINE_AA, tipLength=0.4)
    start = m.world_to_pixel(track.position(0.0, -track.lane_width_m / 2))
    tip = m.world_to_pixel(track.position(min(0.8, total), -track.lane_width_m / 2))
    cv2.circle(img, tuple(to_px(start)), max(3, int(0.12 * scale)), _START_BGR, -1, cv2.LINE_AA)
    cv2.arrowedLine(img, tuple(to_px(start)), tuple(to_px(tip)), _START_BGR,
                    max(2, int(0.05 * scale)), cv2.LINE_AA, tipLength=0.3)
    label = f"{track.name or 'track'}  {total:.1f} m"
    if math.isfinite(track.min_centre_radius_m):
        label += f"  min R {track.min_centre_radius_m:.2f} m"
    cv2.putText(img, label, (10, 28), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (255, 255, 255), 2,
                cv2.LINE_AA)
    cv2.putText(img, "START", tuple(to_px(start) + np.array([12, -12])),
                cv2.FONT_HERSHEY_SIMPLEX, 0.6, _START_BGR, 2, cv2.LINE_AA)
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
