"""Spatial hash for the reverse query (world point → arc length, lateral offset).

The mat is cut into square cells; each cell lists the segments that pass within
``reach`` of it. A query projects the point exactly onto the few segments of its cell,
so its cost does not grow with the track's length. Points farther than ``reach`` from
the road (or in an empty cell) fall back to all segments: still exact, just slower.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from .geometry import SegmentTable, pose_at, project

CELL_M: float = 0.5
"""Edge of a grid cell [m]."""

EXTRA_REACH_M: float = 0.6
"""How far beyond the road's outer edge [m] a point still gets the fast, cell-local
answer (an off-road car is detected well within this)."""

HINT_WINDOW_M: float = 1.0
"""With an arc-length hint, candidates within this arc distance [m] of the hint are
preferred: at a crossing this keeps the branch the car is on."""

_SAMPLE_STEP_M = 0.05


@dataclass(frozen=True)
class GridIndex:
    """Cells in row-major order; the segments of cell ``c`` are
    ``items[cell_start[c]:cell_start[c + 1]]``."""

    x0: float
    y0: float
    cell_m: float
    nx: int
    ny: int
    cell_start: np.ndarray
    items: np.ndarray


@njit(cache=True)
def _centre_samples(x0: np.ndarray, y0: np.ndarray, h0: np.ndarray, kappa: np.ndarray,
                    length: np.ndarray, step: float
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centre-line points every ``step`` [m] or less along each segment, both ends
    included, and their segment: ``np.linspace(0, length, n)`` spelled out (``i · step``,
    the last one the length), so the points are those numpy's would give."""
    total = 0
    for j in range(len(length)):
        total += max(2, math.ceil(length[j] / step) + 1)
    xs = np.empty(total)
    ys = np.empty(total)
    segs = np.empty(total, np.int64)
    k = 0
    for j in range(len(length)):
        n = max(2, math.ceil(length[j] / step) + 1)
        du = length[j] / (n - 1)
        for i in range(n):
            u = length[j] if i == n - 1 else i * du + 0.0
            xs[k], ys[k], _ = pose_at(x0[j], y0[j], h0[j], kappa[j], u)
            segs[k] = j
            k += 1
    return xs, ys, segs


@njit(cache=True)
def _cell_items(xs: np.ndarray, ys: np.ndarray, segs: np.ndarray, gx0: float, gy0: float,
                cell_m: float, nx: int, ny: int, span: int, reach: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """The grid's ``cell_start`` and ``items``: every segment of a sample whose cell square
    lies within ``reach`` of the sample, once per cell, a cell's segments in increasing
    order. The samples come segment by segment (``_centre_samples``), so a pair repeats
    only right after itself (``last`` drops it) and a counting sort by cell keeps the
    segments' order: no sort of all (sample, cell) pairs."""
    n_cells = nx * ny
    last = np.full(n_cells, -1, np.int64)
    side = 2 * span + 1
    pair_cell = np.empty(len(xs) * side * side, np.int64)
    pair_seg = np.empty(len(xs) * side * side, np.int64)
    n = 0
    r2 = reach * reach
    # A cell's squared distance is dx² + dy², its column's dx² plus its row's dy²: each
    # square computed once per column and row of the neighbourhood (2·side, not side²),
    # the same roundings as the sum of the two products.
    dy2 = np.empty(side)
    row_ok = np.empty(side, np.bool_)
    for k in range(len(xs)):
        sx = xs[k]
        sy = ys[k]
        seg = segs[k]
        ci = np.int64(math.floor((sx - gx0) / cell_m))
        cj = np.int64(math.floor((sy - gy0) / cell_m))
        for oj in range(-span, span + 1):
            jj = cj + oj
            cy_lo = gy0 + jj * cell_m
            dy = max(0.0, max(cy_lo - sy, sy - cy_lo - cell_m))
            dy2[oj + span] = dy * dy
            row_ok[oj + span] = 0 <= jj < ny
        for oi in range(-span, span + 1):
            ii = ci + oi
            if not 0 <= ii < nx:
                continue
            cx_lo = gx0 + ii * cell_m
            dx = max(0.0, max(cx_lo - sx, sx - cx_lo - cell_m))
            dx2 = dx * dx
            if dx2 > r2:  # dy² ≥ 0 only adds: no cell of this column
                continue
            for q in range(side):
                if dx2 + dy2[q] <= r2 and row_ok[q]:
                    c = (cj + q - span) * nx + ii
                    if last[c] == seg:
                        continue
                    last[c] = seg
                    pair_cell[n] = c
                    pair_seg[n] = seg
                    n += 1
    cell_start = np.zeros(n_cells + 1, np.int64)
    for q in range(n):
        cell_start[pair_cell[q] + 1] += 1
    for c in range(n_cells):
        cell_start[c + 1] += cell_start[c]
    fill = cell_start[:-1].copy()
    items = np.empty(n, np.int64)
    for q in range(n):
        c = pair_cell[q]
        items[fill[c]] = pair_seg[q]
        fill[c] += 1
    return cell_start, items


def build_index(table: SegmentTable, half_road_m: float, cell_m: float = CELL_M) -> GridIndex:
    """Register each segment in every cell within ``half_road_m + EXTRA_REACH_M`` of it."""
    reach = half_road_m + EXTRA_REACH_M + _SAMPLE_STEP_M
    xs_a, ys_a, seg_a = _centre_samples(table.x0, table.y0, table.h0, table.kappa,
                                        table.length, _SAMPLE_STEP_M)
    gx0 = xs_a.min() - reach - cell_m
    gy0 = ys_a.min() - reach - cell_m
    nx = int(math.ceil((xs_a.max() + reach + cell_m - gx0) / cell_m)) + 1
    ny = int(math.ceil((ys_a.max() + reach + cell_m - gy0) / cell_m)) + 1
    span = int(math.ceil(reach / cell_m)) + 1
    cell_start, items = _cell_items(xs_a, ys_a, seg_a, float(gx0), float(gy0), float(cell_m),
                                    nx, ny, span, float(reach))
    return GridIndex(float(gx0), float(gy0), float(cell_m), nx, ny, cell_start, items)


@njit(cache=True)
def locate_point(
    px: float,
    py: float,
    s_hint: float,
    x0: np.ndarray,
    y0: np.ndarray,
    h0: np.ndarray,
    kappa: np.ndarray,
    length: np.ndarray,
    s0: np.ndarray,
    total: float,
    closed: bool,
    half_road: float,
    gx0: float,
    gy0: float,
    cell: float,
    nx: int,
    ny: int,
    cell_start: np.ndarray,
    items: np.ndarray,
) -> tuple[float, float, float]:
    """``(s [m], d [m], distance [m])`` of the centre-line point nearest to ``(px, py)``.

    ``s_hint`` is NaN for no hint. With a hint, the nearest candidate whose arc length
    lies within ``HINT_WINDOW_M`` of it wins, if it is on the road.
    """
    ci = int(math.floor((px - gx0) / cell))
    cj = int(math.floor((py - gy0) / cell))
    lo = 0
    hi = 0
    if 0 <= ci < nx and 0 <= cj < ny:
        c = cj * nx + ci
        lo = cell_start[c]
        hi = cell_start[c + 1]
    use_all = hi <= lo
    n = len(length) if use_all else hi - lo
    best = (math.inf, 0.0, 0.0)  # (distance, s, d)
    near = (math.inf, 0.0, 0.0)  # best among candidates near the hint
    for k in range(n):
        j = k if use_all else items[lo + k]
        u, d, dist = project(x0[j], y0[j], h0[j], kappa[j], 0.0, length[j], px, py)
        s = s0[j] + u
        if closed and s >= total:
            s -= total
        if dist < best[0]:
            best = (dist, s, d)
        if s_hint == s_hint:  # not NaN
            ds = abs(s - s_hint)
            if closed:
                ds = min(ds, total - ds)
            if ds <= HINT_WINDOW_M and dist < near[0]:
                near = (dist, s, d)
    if near[0] <= half_road:
        return near[1], near[2], near[0]
    if not use_all and best[0] > half_road + EXTRA_REACH_M:
        # Beyond the guaranteed reach a segment outside this cell may be nearer.
        for j in range(len(length)):
            u, d, dist = project(x0[j], y0[j], h0[j], kappa[j], 0.0, length[j], px, py)
            if dist < best[0]:
                s = s0[j] + u
                if closed and s >= total:
                    s -= total
                best = (dist, s, d)
    return best[1], best[2], best[0]


@njit(cache=True)
def locate_points(
    pts: np.ndarray,
    x0: np.ndarray,
    y0: np.ndarray,
    h0: np.ndarray,
    kappa: np.ndarray,
    length: np.ndarray,
    s0: np.ndarray,
    total: float,
    closed: bool,
    half_road: float,
    gx0: float,
    gy0: float,
    cell: float,
    nx: int,
    ny: int,
    cell_start: np.ndarray,
    items: np.ndarray,
) -> np.ndarray:
    """``locate_point`` for an ``(N, 2)`` array; returns ``(3, N)``: s, d, distance [m]."""
    out = np.empty((3, pts.shape[0]))
    for i in range(pts.shape[0]):
        s, d, dist = locate_point(
            pts[i, 0], pts[i, 1], math.nan, x0, y0, h0, kappa, length, s0, total, closed,
            half_road, gx0, gy0, cell, nx, ny, cell_start, items,
        )
        out[0, i] = s
        out[1, i] = d
        out[2, i] = dist
    return out
