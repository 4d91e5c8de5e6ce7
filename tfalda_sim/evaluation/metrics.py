"""The thesis' black-box metric (section 4.1.7): how much of each found lane lies on a
marking of the ground-truth image."""

from __future__ import annotations

import cv2
import numpy as np

from tracks import Marking

EPSILON_PX: float = 5.0
"""Largest distance [px] from a lane pixel to a ground-truth marking pixel that still counts
as a hit (section 4.1.7; listing B.1 uses 10 px, the text 5 px: the text is used)."""

LANE_MARKINGS = (Marking.RIGHT_LINE, Marking.CENTRE_LINE, Marking.LEFT_LINE)
"""Ground-truth labels a lane may hit: the three longitudinal lines (the thesis painted
the road's lines; start and stop lines run across and are left out)."""


def segment_pixels(x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    """Integer pixels ``(N, 2)`` (x, y) of the segment, one per step of its longer axis,
    ends included (the Bresenham rasterisation of section 4.1.7)."""
    ax, ay, bx, by = (round(v) for v in (x0, y0, x1, y1))
    n = max(abs(bx - ax), abs(by - ay)) + 1
    t = np.arange(n) / max(n - 1, 1)
    xs = np.rint(ax + t * (bx - ax)).astype(np.int64)
    ys = np.rint(ay + t * (by - ay)).astype(np.int64)
    return np.column_stack([xs, ys])


def truth_distance(labels: np.ndarray, markings: tuple[Marking, ...] = LANE_MARKINGS
                   ) -> np.ndarray:
    """Distance [px] of every pixel to the nearest ground-truth marking pixel (float32)."""
    mask = np.isin(labels, [int(m) for m in markings])
    if not mask.any():
        return np.full(labels.shape, np.inf, np.float32)
    return cv2.distanceTransform((~mask).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)


def lane_hit_rates(lanes: np.ndarray, distance: np.ndarray, epsilon_px: float = EPSILON_PX
                   ) -> np.ndarray:
    """Per lane ``(x_top, y_top, x_bottom, y_bottom)`` [px]: the share of its pixels within
    ``epsilon_px`` of a marking (pixels outside the image count as misses)."""
    h, w = distance.shape
    rates = np.zeros(len(lanes))
    for k, (x0, y0, x1, y1) in enumerate(np.asarray(lanes, dtype=np.float64)):
        if not np.all(np.isfinite((x0, y0, x1, y1))):
            continue  # a missing lane scores 0
        px = segment_pixels(x0, y0, x1, y1)
        inside = (px[:, 0] >= 0) & (px[:, 0] < w) & (px[:, 1] >= 0) & (px[:, 1] < h)
        d = np.full(len(px), np.inf)
        d[inside] = distance[px[inside, 1], px[inside, 0]]
        rates[k] = float(np.mean(d <= epsilon_px))
    return rates
