"""The car's own body in the camera image: the bonnet (and whatever of the car the camera
sees) as an image region below an edge row per column.

Two shapes: the thesis camera's parabola (its edge ``top_row`` in the middle, lower toward
the borders) and, for a real car, a polygon drawn on one of its frames. Either way the
region is everything at or below ``edge(u)`` in column ``u``: the renderer paints the
bonnet there (mirroring the scene above the edge), the ground truth and the detectors'
masks leave it out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from .limits import MIN_BONNET_TOP_SHARE, check_range

BONNET_TOP_ROW_PX: float = 440.0
"""Row of the thesis camera's bonnet edge in the image middle [px]: below table 2.4's
lowest ROI row (425) and fig. 2.2's bottom line (row 480 − 10)."""

BONNET_EDGE_DROP_PX: float = 22.0
"""How much lower the thesis camera's bonnet edge is at the image borders [px]."""

MIN_POLYGON_VERTICES: int = 3
"""Fewest vertices of a bonnet polygon."""

MAX_POLYGON_VERTICES: int = 1000
"""Most vertices of a bonnet polygon (a hand-drawn outline has tens)."""


@dataclass(frozen=True, eq=False)  # array field: identity equality, hashable
class Bonnet:
    """The car's body in the image. With ``polygon_px`` (``(n, 2)`` vertices ``(u, v)``
    [px], image coordinates), the body is that polygon's lower hull: every pixel at or
    below its topmost point in each column it spans. Without, the thesis camera's
    parabola: the edge at ``top_row`` [px] in the middle and ``edge_drop_px`` lower at the
    left and right border. ``enabled=False``: no body in view."""

    top_row: float = BONNET_TOP_ROW_PX
    edge_drop_px: float = BONNET_EDGE_DROP_PX
    enabled: bool = True
    polygon_px: np.ndarray | None = None

    def __post_init__(self) -> None:
        for name in ("top_row", "edge_drop_px"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"bonnet {name} must be finite, got {getattr(self, name)}")
        if self.polygon_px is not None:
            poly = np.asarray(self.polygon_px, dtype=np.float64)
            if poly.ndim != 2 or poly.shape[1] != 2:
                raise ValueError(f"bonnet polygon must be a list of [u, v] pixel pairs, got "
                                 f"shape {poly.shape}")
            if not MIN_POLYGON_VERTICES <= len(poly) <= MAX_POLYGON_VERTICES:
                raise ValueError(f"bonnet polygon needs {MIN_POLYGON_VERTICES}–"
                                 f"{MAX_POLYGON_VERTICES} vertices, got {len(poly)}")
            if not np.all(np.isfinite(poly)):
                raise ValueError("bonnet polygon vertices must be finite")
            poly.setflags(write=False)
            object.__setattr__(self, "polygon_px", poly)

    def __setstate__(self, state: dict) -> None:
        # A pickled or copied bonnet keeps its polygon read-only.
        self.__dict__.update(state)
        if self.polygon_px is not None:
            self.polygon_px.setflags(write=False)

    @classmethod
    def none(cls) -> Bonnet:
        """No car body in view."""
        return cls(enabled=False)

    @classmethod
    def polygon(cls, vertices_px: np.ndarray | list[list[float]]) -> Bonnet:
        """The body outlined by ``vertices_px`` [(u, v) px]."""
        return cls(polygon_px=np.asarray(vertices_px, dtype=np.float64))

    def check_inside(self, width: int, height: int) -> None:
        """Refuse a polygon with a vertex outside a ``width``×``height`` image (a polygon
        drawn for another image size), a parabola whose edge is not in the image, or a body
        that reaches above ``MIN_BONNET_TOP_SHARE`` of the image (it would hide the road)."""
        lowest_top = MIN_BONNET_TOP_SHARE * height
        why = (f"the car's body may cover at most the lower {1 - MIN_BONNET_TOP_SHARE:.0%} of "
               f"the {height}-row image, or it hides the road ahead")
        if self.polygon_px is None:
            if self.enabled and not (0.0 <= self.top_row < height
                                     and -height <= self.edge_drop_px <= height):
                raise ValueError(f"bonnet parabola top_row {self.top_row:g} px must lie in the "
                                 f"{height}-row image and edge_drop_px "
                                 f"{self.edge_drop_px:g} within ±{height} px")
            if self.enabled:
                check_range("bonnet parabola top_row", self.top_row, lowest_top, height - 1.0,
                            "px", why)
                if self.edge_drop_px < 0:  # the edge is highest at the borders
                    check_range("bonnet parabola top_row + edge_drop_px (its edge at the "
                                "borders)", self.top_row + self.edge_drop_px, lowest_top,
                                height - 1.0, "px", why)
            return
        u, v = self.polygon_px[:, 0], self.polygon_px[:, 1]
        bad = (u < -0.5) | (u > width - 0.5) | (v < -0.5) | (v > height - 0.5)
        if bad.any():
            k = int(np.argmax(bad))
            raise ValueError(f"bonnet polygon vertex {k} ({u[k]:g}, {v[k]:g}) lies outside the "
                             f"{width}×{height} image: was it drawn on a frame of another size?")
        k = int(np.argmin(v))
        check_range(f"bonnet polygon vertex {k} row v", float(v[k]), lowest_top, height - 0.5,
                    "px", why)

    def edge(self, u: np.ndarray, width: int, height: int | None = None) -> np.ndarray:
        """Row of the body's top edge [px] at columns ``u``; ``inf`` where a column shows no
        body (``height`` is needed for a polygon)."""
        if not self.enabled:
            return np.full(np.shape(u), np.inf)
        if self.polygon_px is None:
            t = (np.asarray(u, dtype=np.float64) - (width - 1) / 2) / ((width - 1) / 2)
            return self.top_row + self.edge_drop_px * t * t
        if height is None:
            raise ValueError("a polygon bonnet's edge needs the image height")
        top = self._polygon_edge(width, height)
        cols = np.clip(np.rint(np.asarray(u, dtype=np.float64)).astype(np.int64), 0, width - 1)
        return top[cols]

    def _polygon_edge(self, width: int, height: int) -> np.ndarray:
        mask = self.mask(width, height)
        any_row = mask.any(axis=0)
        first = np.argmax(mask, axis=0).astype(np.float64)
        return np.where(any_row, first, np.inf)

    def mask(self, width: int, height: int) -> np.ndarray:
        """``(height, width)`` bool: the pixels the body covers (at or below the edge)."""
        v = np.arange(height, dtype=np.float64)[:, None]
        if not self.enabled:
            return np.zeros((height, width), bool)
        if self.polygon_px is None:
            return v >= self.edge(np.arange(width), width)[None, :]
        filled = np.zeros((height, width), np.uint8)
        shift = 4  # sub-pixel vertices: 1/16 px
        pts = np.rint(self.polygon_px * (1 << shift)).astype(np.int32)
        cv2.fillPoly(filled, [pts], 1, lineType=cv2.LINE_8, shift=shift)
        # Everything below the polygon's top in a column is body too (the polygon is the
        # outline of what hides the road; the road is never seen under it).
        top = np.where(filled.any(axis=0), np.argmax(filled, axis=0), height)
        return v >= top[None, :]

    def top_px(self, width: int, height: int) -> float:
        """The highest row the body reaches anywhere in the image [px] (``inf``: none)."""
        return float(np.min(self.edge(np.arange(width), width, height)))
