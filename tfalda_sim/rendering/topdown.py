"""A small top-down map of the track with the car on it (the env's render inset)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from tfalda_sim.tracks import Track
from tfalda_sim.tracks.preview import MAT_BGR, SHIFT, top_view

from ..vehicle import CarParams

_CAR_BGR = (0, 0, 255)


@dataclass(frozen=True, eq=False)
class TopDownMap:
    """The track drawn once at ``size_px`` × ``size_px`` (BGR, ``tracks.preview.top_view``
    in its palette); ``draw(pose)`` adds the car."""

    base: np.ndarray
    origin_m: tuple[float, float]  # world point at the top-left corner of pixel (0, 0) [m]
    scale_px_m: float  # [px/m]
    car: CarParams

    @classmethod
    def of(cls, track: Track, size_px: int = 180, car: CarParams | None = None) -> TopDownMap:
        """The map of ``track``, north up, fitted into the square with a margin."""
        xmin, ymin, xmax, ymax = track.bounds(0.3)
        view, m = top_view(track, max(xmax - xmin, ymax - ymin) / (size_px - 1))
        img = np.empty((size_px, size_px, 3), np.uint8)
        img[:] = MAT_BGR
        h, w = min(view.shape[0], size_px), min(view.shape[1], size_px)
        img[:h, :w] = view[:h, :w]
        return cls(img, m.origin_m, 1.0 / m.resolution_m, car or CarParams())

    def _px(self, points_m: np.ndarray) -> np.ndarray:
        """World points ``(N, 2)`` [m] → fixed-point image points for cv2 drawing (pixel
        centres at integers, as ``MarkingMap.world_to_pixel``)."""
        p = np.asarray(points_m, np.float64)
        u = (p[:, 0] - self.origin_m[0]) * self.scale_px_m - 0.5
        v = (self.origin_m[1] - p[:, 1]) * self.scale_px_m - 0.5
        return np.rint(np.column_stack([u, v]) * (1 << SHIFT)).astype(np.int32)

    def draw(self, pose: tuple[float, float, float]) -> np.ndarray:
        """A copy of the map with the car at ``pose`` (x [m], y [m], yaw [rad]), drawn
        at least a few pixels large so it stays visible on a big track."""
        img = self.base.copy()
        x, y, yaw = pose
        grow = max(1.0, 6.0 / (self.car.length_m * self.scale_px_m))
        c, s = math.cos(yaw), math.sin(yaw)
        outline = np.array([(x + grow * (c * bx - s * by), y + grow * (s * bx + c * by))
                            for bx, by in self.car.body_outline()])
        cv2.fillPoly(img, [self._px(outline)], _CAR_BGR, cv2.LINE_AA, shift=SHIFT)
        return img
