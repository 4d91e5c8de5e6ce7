"""Pictures of a camera fit: the fitted model's marking lines drawn on the frame."""

from __future__ import annotations

import cv2
import numpy as np

from .fit import LANE_WIDTH_M, MountFit

_ROLE_COLOURS = {"left": (255, 160, 0), "centre": (0, 220, 255), "right": (0, 200, 0),
                 "other": (160, 160, 160)}  # BGR
_OFFSETS = {"left": LANE_WIDTH_M, "centre": 0.0, "right": -LANE_WIDTH_M}


def fit_overlay(frame: np.ndarray, fit: MountFit) -> np.ndarray:
    """BGR image: ``frame`` with the marking pixels each line was fitted to (dots) and the
    fitted model's three lines (the rules' 0.4 m lanes, 0.05–40 m ahead) over them; the
    bonnet polygon, if the camera has one, in red."""
    img = cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
    cam = fit.camera
    for line in fit.lines:
        for u, v in np.rint(line.pixels).astype(int):
            cv2.circle(img, (int(u), int(v)), 1, _ROLE_COLOURS[line.role], -1)
    ahead = cam.mount.forward_m + np.geomspace(0.05, 40.0, 400)
    centre_y = LANE_WIDTH_M / 2  # the car centred in the right lane
    for role, offset in _OFFSETS.items():
        pts = np.column_stack([ahead, np.full_like(ahead, centre_y + offset), np.zeros_like(ahead)])
        uv = cam.project(cam.car_to_camera(pts))
        uv = uv[np.all(np.isfinite(uv), axis=1)]
        cv2.polylines(img, [np.rint(uv * 16).astype(np.int32)], False, _ROLE_COLOURS[role], 1,
                      lineType=cv2.LINE_AA, shift=4)
    if cam.bonnet.polygon_px is not None:
        cv2.polylines(img, [np.rint(cam.bonnet.polygon_px * 16).astype(np.int32)], True,
                      (0, 0, 255), 1, lineType=cv2.LINE_AA, shift=4)
    text = f"residual {fit.residual_px:.2f} px, height {cam.mount.height_m * 1000:.0f} mm"
    cv2.putText(img, text, (8, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1,
                cv2.LINE_AA)
    return img
