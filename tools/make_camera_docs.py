"""The pictures of docs/cameras.md: the derived geometry of both named profiles drawn on a
frame, and each reference frame beside a render through ``reference-car`` at a similar
pose.

    python tools/make_camera_docs.py   # writes docs/cameras/*.png
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from tfalda_sim.camera import load_camera
from tfalda_sim.perception import DetectorConfig, HoughConfig
from tfalda_sim.perception.hough import REAL_FRAME_BINARISE_LEVEL
from tfalda_sim.rendering import Renderer, build_scene
from tfalda_sim.tracks import generate, load_named

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "cameras"
REFERENCE = ROOT / "tests" / "data" / "reference"

RIGHT_CURVE_SEED: int = 10004
"""A generated track with a right curve, for the start-road frame's look-alike."""


def geometry_picture(frame: np.ndarray, camera_name: str) -> np.ndarray:
    """``frame`` with the derived initial ROIs (blue), the width-limit rows (green, with
    table 2.3's limits in px), the curve thresholds (yellow), the Hough crop (magenta) and
    the bonnet (red)."""
    cam = load_camera(camera_name)
    cfg = DetectorConfig.for_camera(cam)
    hough = HoughConfig.for_camera(cam, REAL_FRAME_BINARISE_LEVEL)
    img = cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
    for x, y, w, h in cfg.layout.table_px:
        cv2.rectangle(img, (x, y), (x + w - 1, y + h - 1), (255, 128, 0), 2)
    for k, (row, (lo, hi)) in enumerate(zip(cfg.lis.width_limit_rows_px,
                                            cfg.lis.width_limits_px, strict=True)):
        cv2.line(img, (0, int(row)), (12, int(row)), (0, 220, 0), 2)
        cv2.putText(img, f"{lo:.0f}-{hi:.0f} px", (16 + 90 * (k % 2), int(row) + 4),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 220, 0), 1, cv2.LINE_AA)
    top = cfg.layout.table_px[0][1]
    for x in (cfg.layout.left_curve_right_roi_x_px, cfg.layout.right_curve_left_roi_end_px):
        cv2.line(img, (x, top - 12), (x, top - 2), (0, 230, 230), 2)
    y0, y1 = hough.crop_top_px, hough.crop_top_px + hough.crop_height_px - 1
    cv2.rectangle(img, (0, y0), (cam.width - 1, y1), (255, 0, 255), 1)
    edge = cam.bonnet.edge(np.arange(cam.width), cam.width, cam.height)
    pts = np.column_stack([np.arange(cam.width), edge])
    pts = pts[np.isfinite(pts[:, 1])]
    cv2.polylines(img, [np.rint(pts).astype(np.int32)], False, (0, 0, 255), 1, cv2.LINE_AA)
    cv2.putText(img, f"{camera_name}: derived layout", (8, cam.height - 8),
                cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    return img


def render(camera_name: str, track, s_m: float, lateral_m: float = -0.2) -> np.ndarray:
    cam = load_camera(camera_name)
    x, y, h = (float(v) for v in track.pose(s_m, lateral_m))
    return Renderer(cam).render(build_scene(track), (x, y, h))


def _right_curve_entry(seed: int) -> tuple[object, float]:
    track = replace(generate(seed), obstacles=())
    t = track.table
    k = int(np.argmin(t.kappa))  # the tightest right curve (κ < 0)
    return track, float(t.s0[k]) - 1.0


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    straight = load_named("straight")
    thesis_frame = render("thesis", straight, 2.0)
    cv2.imwrite(str(OUT / "geometry-thesis.png"), geometry_picture(thesis_frame, "thesis"))
    ref = cv2.imread(str(REFERENCE / "straight-road.png"), cv2.IMREAD_GRAYSCALE)
    cv2.imwrite(str(OUT / "geometry-reference-car.png"), geometry_picture(ref, "reference-car"))
    # Side by side: the reference frames and renders at a similar pose.
    sim = render("reference-car", straight, 2.0)
    cv2.imwrite(str(OUT / "side-by-side-straight.png"), np.hstack([ref, sim]))
    start = cv2.imread(str(REFERENCE / "start-road.png"), cv2.IMREAD_GRAYSCALE)
    track, s = _right_curve_entry(RIGHT_CURVE_SEED)
    cv2.imwrite(str(OUT / "side-by-side-start.png"),
                np.hstack([start, render("reference-car", track, s)]))
    print(f"wrote {OUT}/geometry-thesis.png, geometry-reference-car.png, "
          "side-by-side-straight.png, side-by-side-start.png")


if __name__ == "__main__":
    main()
