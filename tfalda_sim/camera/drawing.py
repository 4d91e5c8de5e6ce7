"""Pictures of a camera fit: the fitted model's marking lines drawn on the frame, and for a
refused fit the lines that were found and why they were refused."""

from __future__ import annotations

import textwrap

import cv2
import numpy as np

from .fit import LANE_WIDTH_M, LineFit, MountFit, model_line_pixels
from .models import Camera

_ROLE_COLOURS = {"left": (255, 160, 0), "centre": (0, 220, 255), "right": (0, 200, 0),
                 "other": (160, 160, 160)}  # BGR
REFUSED_COLOUR = (40, 40, 255)
"""The text of a refused fit and the car's body outline (BGR)."""

TEXT_HEIGHT_SHARE: float = 0.035
"""Line height of the overlay's text [share of the image height], at least 14 px."""


_ASCII = {"°": " deg", "±": "+/-", "–": "-", "—": "-", "−": "-", "×": "x", "…": "...",
          "σ": "sigma", "’": "'", "“": '"', "”": '"'}


def ascii_text(text: str) -> str:
    """``text`` in ASCII: OpenCV's Hershey fonts draw no other characters."""
    for a, b in _ASCII.items():
        text = text.replace(a, b)
    return text.encode("ascii", "replace").decode("ascii")


def _offsets(lane_width_m: float) -> dict[str, float]:
    return {"left": lane_width_m, "centre": 0.0, "right": -lane_width_m}


def draw_fit(frame: np.ndarray, lines: tuple[LineFit, ...], camera: Camera | None, *,
             lane_width_m: float = LANE_WIDTH_M, body: np.ndarray | None = None,
             text: list[str] | None = None, refused: bool = False) -> np.ndarray:
    """BGR image: ``frame`` (grey) with the marking pixels of each line found (dots, by
    role), the model's three lines (the lanes ``lane_width_m`` [m] apart, 0.05–40 m ahead,
    for a camera ``camera`` whose mount puts the car centred in the right lane) when a
    camera is given, the car's body outline ``body`` (``(n, 2)`` [px]) in red, and
    ``text`` at the top (red when ``refused``)."""
    img = cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
    h, w = frame.shape
    dot = max(1, int(round(h / 480)))
    for line in lines:
        for u, v in np.rint(line.pixels).astype(int):
            cv2.circle(img, (int(u), int(v)), dot, _ROLE_COLOURS[line.role], -1)
    if camera is not None:
        ahead = camera.mount.forward_m + np.geomspace(0.05, 40.0, 400)
        centre_y = lane_width_m / 2  # the car centred in the right lane
        for role, offset in _offsets(lane_width_m).items():
            uv = model_line_pixels(camera, centre_y, offset, ahead)
            if len(uv) >= 2 and np.all(np.abs(uv) < 1e6):
                cv2.polylines(img, [np.rint(uv * 16).astype(np.int32)], False,
                              _ROLE_COLOURS[role], dot, lineType=cv2.LINE_AA, shift=4)
    if body is not None:
        cv2.polylines(img, [np.rint(body * 16).astype(np.int32)], True, REFUSED_COLOUR, dot,
                      lineType=cv2.LINE_AA, shift=4)
    if text:
        step = max(14, int(round(TEXT_HEIGHT_SHARE * h)))
        scale = step / 36.0
        chars = max(20, int(w / (step * 0.55)))
        rows = [r for t in text for r in textwrap.wrap(ascii_text(t), chars)]
        thick = max(1, dot)
        widest = max(cv2.getTextSize(r, cv2.FONT_HERSHEY_SIMPLEX, scale, thick)[0][0]
                     for r in rows)
        band = img[:step * len(rows) + step // 3, :min(w, widest + step)]
        band[:] = (band * 0.35).astype(np.uint8)  # a dark band under the text
        for k, row in enumerate(rows):
            org = (max(4, step // 3), step * (k + 1))
            cv2.putText(img, row, org, cv2.FONT_HERSHEY_SIMPLEX, scale,
                        (90, 90, 255) if refused else (255, 255, 255), thick, cv2.LINE_AA)
    return img


def fit_overlay(frame: np.ndarray, fit: MountFit, text: list[str] | None = None
                ) -> np.ndarray:
    """BGR image: ``frame`` with the marking pixels each line was fitted to (dots) and the
    fitted model's three lines over them; the bonnet polygon, if the camera has one, in
    red; the residual and height (or ``text``) at the top."""
    cam = fit.camera
    body = cam.bonnet.polygon_px if cam.bonnet is not None else None
    if text is None:
        text = [f"residual {fit.residual_px:.2f} px, height {cam.mount.height_m * 1000:.0f} mm"]
    return draw_fit(frame, fit.lines, cam, lane_width_m=fit.lane_width_m, body=body,
                    text=text)
