"""A small top-down map of the track with the car on it (the env's render inset)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from tfalda_sim.tracks import Track
from tfalda_sim.tracks.rules import obstacle_corners

from ..vehicle import CarParams

_ROAD_BGR = (70, 70, 70)
_LINE_BGR = (200, 200, 200)
_OBSTACLE_BGR = (0, 140, 255)
_CAR_BGR = (0, 0, 255)
_SHIFT = 4  # sub-pixel drawing: 1/16 px


@dataclass(frozen=True, eq=False)
class TopDownMap:
    """The track drawn once at ``size_px`` × ``size_px`` (BGR); ``draw(pose)`` adds the car."""

    base: np.ndarray
    origin_m: tuple[float, float]  # world point at pixel (0, 0) [m]
    scale_px_m: float  # [px/m]
    car: CarParams

    @classmethod
    def of(cls, track: Track, size_px: int = 180, car: CarParams | None = None) -> TopDownMap:
        """The map of ``track``, north up, fitted into the square with a margin."""
        xmin, ymin, xmax, ymax = track.bounds(0.3)
        scale = (size_px - 1) / max(xmax - xmin, ymax - ymin)
        img = np.full((size_px, size_px, 3), 24, np.uint8)
        origin = (xmin, ymax)  # y up in the world, down in the image
        m = cls(img, origin, scale, car or CarParams())
        s = np.arange(0.0, track.length_m, 0.05)
        road_px = max(1, round(2 * track.half_road_m * scale))
        cv2.polylines(img, [m._px(track.position(s))], track.closed, _ROAD_BGR, road_px,
                      cv2.LINE_AA, shift=_SHIFT)
        for offset in (-track.lane_width_m, track.lane_width_m):
            cv2.polylines(img, [m._px(track.position(s, offset))], track.closed, _LINE_BGR, 1,
                          cv2.LINE_AA, shift=_SHIFT)
        for k in range(len(track.obstacles)):
            cv2.fillPoly(img, [m._px(obstacle_corners(track, k))], _OBSTACLE_BGR,
                         cv2.LINE_AA, shift=_SHIFT)
        return m

    def _px(self, points_m: np.ndarray) -> np.ndarray:
        """World points ``(N, 2)`` [m] → fixed-point image points for cv2 drawing."""
        p = np.asarray(points_m, np.float64)
        u = (p[:, 0] - self.origin_m[0]) * self.scale_px_m
        v = (self.origin_m[1] - p[:, 1]) * self.scale_px_m
        return np.rint(np.column_stack([u, v]) * (1 << _SHIFT)).astype(np.int32)

    def draw(self, pose: tuple[float, float, float]) -> np.ndarray:
        """A copy of the map with the car at ``pose`` (x [m], y [m], yaw [rad]), drawn
        at least a few pixels large so it stays visible on a big track."""
        img = self.base.copy()
        x, y, yaw = pose
        grow = max(1.0, 6.0 / (self.car.length_m * self.scale_px_m))
        c, s = math.cos(yaw), math.sin(yaw)
        outline = np.array([(x + grow * (c * bx - s * by), y + grow * (s * bx + c * by))
                            for bx, by in self.car.body_outline()])
        cv2.fillPoly(img, [self._px(outline)], _CAR_BGR, cv2.LINE_AA, shift=_SHIFT)
        return img
