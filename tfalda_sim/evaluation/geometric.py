"""The black-box hit rate from the track geometry, cheap enough for every env step.

The thesis scores a lane by the share of its pixels within ε of a marking in a painted
reference image (section 4.1.7; ``metrics.lane_hit_rates``). Painting that image costs
milliseconds; here the lane's points are instead taken back to the ground through the
camera's per-pixel ground hits (``PixelGeometry``) and compared with the track's line
positions: a point hits when it lies within half a line width plus ε — ε converted from
pixels to metres by that pixel's footprint on the ground — of a lane line. As in the
thesis' reference images the dashed centre line counts as continuous; rule gaps count as
painted too (they are at most 1 m long).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from tfalda_sim.tracks import Track
from tfalda_sim.tracks.dimensions import LINE_WIDTH_M
from tfalda_sim.tracks.index import locate_points

from ..rendering import PixelGeometry
from .metrics import EPSILON_PX

HIT_SAMPLES: int = 9
"""Points sampled along each lane, ends included."""


@njit(cache=True)
def _ground_points(lanes: np.ndarray, gx: np.ndarray, gy: np.ndarray, rho: np.ndarray,
                   bonnet: np.ndarray, log2_fp: np.ndarray, x: float, y: float, yaw: float,
                   samples: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World points ``(n·samples, 2)`` [m] of the lanes' sample pixels, whether each is a
    ground pixel inside the image, and each pixel's footprint on the ground [m]."""
    n = lanes.shape[0]
    h, w = rho.shape
    pts = np.zeros((n * samples, 2))
    ok = np.zeros(n * samples, np.bool_)
    footprint = np.zeros(n * samples)
    c, s = math.cos(yaw), math.sin(yaw)
    for k in range(n):
        for i in range(samples):
            t = i / (samples - 1)
            u = lanes[k, 0] + t * (lanes[k, 2] - lanes[k, 0])
            v = lanes[k, 1] + t * (lanes[k, 3] - lanes[k, 1])
            j = k * samples + i
            if not (math.isfinite(u) and math.isfinite(v)):
                continue
            col, row = int(round(u)), int(round(v))
            # The bonnet's geometry describes its mirror image: no lane point lies there.
            if (not (0 <= col < w and 0 <= row < h) or not math.isfinite(rho[row, col])
                    or bonnet[row, col]):
                continue
            px, py = float(gx[row, col]), float(gy[row, col])
            pts[j, 0] = x + c * px - s * py
            pts[j, 1] = y + s * px + c * py
            ok[j] = True
            footprint[j] = 2.0 ** float(log2_fp[row, col])
    return pts, ok, footprint


@njit(cache=True)
def _hit_rates(lanes: np.ndarray, gx: np.ndarray, gy: np.ndarray, rho: np.ndarray,
               bonnet: np.ndarray, log2_fp: np.ndarray, x: float, y: float, yaw: float,
               samples: int, x0: np.ndarray, y0: np.ndarray, h0: np.ndarray,
               kappa: np.ndarray, length: np.ndarray, s0: np.ndarray, total: float,
               closed: bool, half_road: float, grid_x0: float, grid_y0: float, cell_m: float,
               nx: int, ny: int, cell_start: np.ndarray, items: np.ndarray, lane_w: float,
               half_line: float, epsilon_px: float) -> np.ndarray:
    """``geometric_hit_rates`` in one call (every env step reports it): the lanes' sample
    points on the ground, located on the track (``Track.locate_many``'s kernel), and per
    lane the share within ``half_line`` + ε·footprint [m] of a line."""
    pts, ok, footprint = _ground_points(lanes, gx, gy, rho, bonnet, log2_fp, x, y, yaw,
                                        samples)
    lateral = locate_points(pts, x0, y0, h0, kappa, length, s0, total, closed, half_road,
                            grid_x0, grid_y0, cell_m, nx, ny, cell_start, items)[1]
    rates = np.zeros(lanes.shape[0])
    for k in range(lanes.shape[0]):
        count = 0
        for i in range(samples):
            j = k * samples + i
            # Distance to the nearest of the three lines (right side, centre, left side).
            off_line = min(abs(lateral[j]), abs(abs(lateral[j]) - lane_w))
            if ok[j] and off_line <= half_line + epsilon_px * footprint[j]:
                count += 1
        rates[k] = count / samples  # a mean of 0/1 values, as numpy's: the sum / n
    return rates


def geometric_hit_rates(lanes: np.ndarray, geometry: PixelGeometry, track: Track,
                        pose: tuple[float, float, float], epsilon_px: float = EPSILON_PX
                        ) -> np.ndarray:
    """Per lane ``(x_top, y_top, x_bottom, y_bottom)`` [px] of ``lanes`` ``(n, 4)``, the
    share of its sample points that lie on a lane line, seen from a car at ``pose``
    (x [m], y [m], yaw [rad]). Points above the horizon or off the image miss."""
    lanes = np.asarray(lanes, np.float64)
    n = len(lanes)
    if n == 0:
        return np.zeros(0)
    g, t, index = geometry, track.table, track.index
    return _hit_rates(lanes, g.gx, g.gy, g.rho, g.bonnet, g.log2_fp, float(pose[0]),
                      float(pose[1]), float(pose[2]), HIT_SAMPLES, t.x0, t.y0, t.h0, t.kappa,
                      t.length, t.s0, track.length_m, track.closed, track.half_road_m,
                      index.x0, index.y0, index.cell_m, index.nx, index.ny, index.cell_start,
                      index.items, track.lane_width_m, 0.5 * LINE_WIDTH_M,
                      float(epsilon_px))
