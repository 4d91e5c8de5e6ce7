"""Top-down rasterisation of a track's markings: an intensity map and a label map.

The intensity map is white paint on a black mat (uint8, 255 = fully painted pixel), with
edges anti-aliased by the exact area a pixel shares with a line (box filter, measured
across and along the road). The label map says which marking a pixel belongs to; pixels
where a marking *would* run but is not painted (the gaps between centre-line dashes, rule
gaps in a line) carry the marking's id with the ``VIRTUAL`` bit, so ground truth can paint
the dashed centre line continuous as the thesis does.

Pixel convention (as OpenCV's): pixel ``(row, col)`` has its centre at
``x = origin_x + (col + 0.5)·res``, ``y = origin_y − (row + 0.5)·res``; rows grow
southward (−y). ``MarkingMap.world_to_pixel`` returns coordinates with pixel centres at
integers, ready for ``cv2.remap``.
"""

from __future__ import annotations

import math
import mmap
from dataclasses import dataclass
from enum import IntEnum
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from . import dimensions

if TYPE_CHECKING:
    from .model import Track

MAX_MAP_PIXELS: int = 400_000_000
"""Largest marking map [px] (two uint8 layers: 800 MB): an 80 m × 80 m mat at the
default 4 mm/px, four times the largest generated track's."""

DEFAULT_RESOLUTION_M: float = 0.004
"""Default edge of a map pixel [m] (the tracks' specification: at most 4 mm)."""

CHUNK_M: float = 0.75
"""Road is painted in chunks of at most this length [m], each in its own pixel box (the
map does not depend on it: tested). A tile meets fewer chunks of longer ones, each with
its rows' spans to find; longer ones bulge more on arcs and leave the plain path (no
``_paint_pixel``) over more road near gaps and crossing markings: 0.75 m painted a view's
tiles 9–15 % faster than 0.25 m in three runs, 0.5 m and 1 m less consistently
(BENCHMARKS.md)."""

VIRTUAL: int = 0x80
"""Label bit: the marking runs here but is not painted (dash gap or rule gap)."""


class Marking(IntEnum):
    """Label ids of the marking map (``labels & ~VIRTUAL``)."""

    NONE = 0
    RIGHT_LINE = 1
    CENTRE_LINE = 2
    LEFT_LINE = 3
    START_LINE = 4
    STOP_LINE = 5
    OBSTACLE = 6
    """Only in camera ground truth: a carton hiding what lies behind it."""


@dataclass(frozen=True)
class MarkingMap:
    """Rasterised markings. ``intensity`` and ``labels`` are ``(H, W)`` uint8 arrays;
    ``origin_m`` is the world position [m] of the map's top-left corner, ``resolution_m``
    the edge of one pixel [m]."""

    intensity: np.ndarray
    labels: np.ndarray
    origin_m: tuple[float, float]
    resolution_m: float

    @property
    def shape(self) -> tuple[int, int]:
        return self.intensity.shape  # type: ignore[return-value]

    def world_to_pixel(self, xy: np.ndarray) -> np.ndarray:
        """``(..., 2)`` world points [m] → ``(..., 2)`` (col, row) [px], centres at integers."""
        xy = np.asarray(xy, dtype=np.float64)
        col = (xy[..., 0] - self.origin_m[0]) / self.resolution_m - 0.5
        row = (self.origin_m[1] - xy[..., 1]) / self.resolution_m - 0.5
        return np.stack([col, row], axis=-1)

    def pixel_to_world(self, colrow: np.ndarray) -> np.ndarray:
        """Inverse of ``world_to_pixel``."""
        colrow = np.asarray(colrow, dtype=np.float64)
        x = self.origin_m[0] + (colrow[..., 0] + 0.5) * self.resolution_m
        y = self.origin_m[1] - (colrow[..., 1] + 0.5) * self.resolution_m
        return np.stack([x, y], axis=-1)


@njit(cache=True)
def _band(v: float, lo: float, hi: float, res: float) -> float:
    """Share of the pixel interval ``[v − res/2, v + res/2]`` inside ``[lo, hi]``."""
    a = max(v - 0.5 * res, lo)
    b = min(v + 0.5 * res, hi)
    return max(0.0, b - a) / res


@njit(cache=True)
def _cyclic_band(s: float, lo: float, hi: float, res: float, total: float, closed: bool) -> float:
    if not closed:
        return _band(s, lo, hi, res)
    return max(_band(s, lo - total, hi - total, res), _band(s, lo, hi, res),
               _band(s, lo + total, hi + total, res))


@njit(cache=True)
def _dash_integral(x: float, dash: float, period: float) -> float:
    """Painted length of the dashed line on ``[0, x]`` (dashes start at s = 0)."""
    k = math.floor(x / period)
    return k * dash + min(x - k * period, dash)


@njit(cache=True)
def _paint_pixel(
    intensity: np.ndarray,
    labels: np.ndarray,
    r: int,
    q: int,
    s: float,
    d: float,
    res: float,
    total: float,
    closed: bool,
    lane_w: float,
    line_w: float,
    dash: float,
    period: float,
    gap_line: np.ndarray,
    gap_lo: np.ndarray,
    gap_hi: np.ndarray,
    gap_ids: np.ndarray,
    n_gaps: int,
    passes: np.ndarray,
    start_s: float,
    start_w: float,
    stop_w: float,
    special: bool,
    with_labels: bool,
) -> None:
    """Paint one pixel at road coordinates ``(s, d)`` [m] (its label too if
    ``with_labels``; the intensity never depends on the labels). Only the rule gaps
    ``gap_ids[:n_gaps]`` and, with ``special``, the crossing markings (intersections,
    start line) are looked at: the caller leaves out those that cover none of the pixel
    (each would add exactly 0)."""
    half_road = lane_w + 0.5 * line_w
    # Intersections: no lines inside the crossing road, stop lines before it.
    cut = 0.0
    stop = 0.0
    for sx in passes if special else passes[:0]:
        cut = max(cut, _cyclic_band(s, sx - half_road, sx + half_road, res, total, closed))
        stop = max(stop, _cyclic_band(s, sx - half_road - stop_w, sx - half_road, res, total,
                                      closed) * _band(d, -half_road, 0.0, res))
        stop = max(stop, _cyclic_band(s, sx + half_road, sx + half_road + stop_w, res, total,
                                      closed) * _band(d, 0.0, half_road, res))
    best_paint = 0.0
    best_label = 0
    best_virtual = 0.0
    virtual_label = 0
    for li in range(3):  # 0 right, 1 centre, 2 left
        dl = (li - 1) * lane_w
        across = _band(d, dl - 0.5 * line_w, dl + 0.5 * line_w, res)
        if across == 0.0:
            continue
        runs = across * (1.0 - cut)
        missing = 0.0
        for k in range(n_gaps):
            g = gap_ids[k]
            if gap_line[g] == li:
                missing += _cyclic_band(s, gap_lo[g], gap_hi[g], res, total, closed)
        paint = runs * max(0.0, 1.0 - missing)
        if li == 1:
            paint *= (_dash_integral(s + 0.5 * res, dash, period)
                      - _dash_integral(s - 0.5 * res, dash, period)) / res
        if paint > best_paint:
            best_paint = paint
            best_label = li + 1
        if runs > best_virtual:
            best_virtual = runs
            virtual_label = li + 1
    if special and start_s == start_s:  # a start line exists (near this pixel)
        paint = (_cyclic_band(s, start_s - 0.5 * start_w, start_s + 0.5 * start_w, res, total,
                              closed) * _band(d, -half_road, half_road, res))
        if paint > best_paint:
            best_paint = paint
            best_label = 4
    if stop > best_paint:
        best_paint = stop
        best_label = 5
    # Pixels painted by two chunks (joins, crossings) keep the larger coverage.
    value = int(min(1.0, best_paint) * 255.0 + 0.5)
    before = intensity[r, q]
    if value > before:
        intensity[r, q] = value
    if not with_labels:
        return
    if best_paint >= 0.5 and value >= before:
        labels[r, q] = best_label
    elif best_virtual >= 0.5 and labels[r, q] == 0:
        labels[r, q] = virtual_label | 0x80


@njit(cache=True)
def _turn_mod(x: float) -> float:
    """``x % (2π)`` for ``x`` in [−2π, 2π] (a difference of two atan2), Python's float
    modulo without its fmod: for such x that is x, x + 2π or x − 2π, exactly (only a −0.0
    stays −0.0, where Python gives +0.0: equal in every comparison and sum here)."""
    two_pi = 2.0 * math.pi
    if x < 0.0:
        return x + two_pi
    if x >= two_pi:
        return x - two_pi
    return x


@njit(cache=True)
def _in_zones(s: float, zones: np.ndarray, n_zones: int, total: float, closed: bool) -> bool:
    """Whether arc length ``s`` [m] lies in one of ``zones[:n_zones]`` (``[lo, hi]`` [m])
    or, on a closed track, one shifted by ± ``total`` (as ``_cyclic_band`` looks)."""
    for z in range(n_zones):
        if zones[z, 0] <= s <= zones[z, 1]:
            return True
        if closed and (zones[z, 0] - total <= s <= zones[z, 1] - total
                       or zones[z, 0] + total <= s <= zones[z, 1] + total):
            return True
    return False


@njit(cache=True)
def row_bit(k: int) -> int:
    """The bit of a tile's row mask (``TiledMarkingMap.nonzero_rows``) for its pixel row
    ``k``: ``1 << k``, or every bit for rows past the 64 a mask holds (a tile of more
    rows is then marked whole)."""
    return np.int64(1) << k if k < 64 else np.int64(-1)


@njit(cache=True)
def _near_line(d: float, lane_w: float, reach: float) -> bool:
    return abs(d + lane_w) <= reach or abs(d) <= reach or abs(d - lane_w) <= reach


@njit(cache=True)
def _segment_frame(x0: float, y0: float, h0: float, kappa: float
                   ) -> tuple[float, float, float, float, float, float, float]:
    """A segment's constants for painting: the cosine and sine of its start heading and,
    on an arc (``kappa`` ≠ 0), its turn's sign, radius [m], centre ``(cx, cy)`` [m] and
    the angle [rad] of its start seen from the centre (zeros on a straight)."""
    ch = math.cos(h0)
    sh = math.sin(h0)
    if kappa == 0.0:
        return ch, sh, 0.0, 0.0, 0.0, 0.0, 0.0
    inv = 1.0 / kappa
    cx = x0 - sh * inv
    cy = y0 + ch * inv
    return (ch, sh, 1.0 if kappa > 0.0 else -1.0, abs(inv), cx, cy,
            math.atan2(y0 - cy, x0 - cx))


@njit(cache=True)
def _chunk_span(length: float, c: int, n_chunks: int) -> tuple[float, float]:
    """Chunk ``c`` of ``n_chunks`` of a segment ``length`` [m] long: its ``(ua, ub)``
    [m] along the segment, the last ending at ``length`` itself (``length · n / n`` may
    be an ulp short, and a pixel centre on the segments' junction then belonged to
    neither segment: a hole in a solid line)."""
    ub = length if c == n_chunks - 1 else length * (c + 1) / n_chunks
    return length * c / n_chunks, ub


@njit(cache=True)
def _chunk_boxes(n_rows: int, n_cols: int, ox: float, oy: float, res: float, x0: np.ndarray,
                 y0: np.ndarray, h0: np.ndarray, kappa: np.ndarray, length: np.ndarray,
                 lane_w: float, line_w: float, chunk_m: float) -> np.ndarray:
    """Per chunk of road (segments in order, ``chunk_m`` [m] at most each), the pixel box
    ``(r_lo, r_hi, c_lo, c_hi)`` that holds every pixel ``_raster_kernel`` may paint for
    it, clipped to the map: the bounding box of the chunk's footprint (``|d| <= pad``
    across, ``ua <= u <= ub`` along: a rectangle, or a sector of an annulus on an arc)
    and a pixel of room for rounding. A box around the centre line padded by ``pad`` on
    every side held ~4× the rows of a chunk running up the map, each a row of spans for
    the kernel to find empty."""
    pad = lane_w + 0.5 * line_w + 2.0 * res  # as ``_raster_kernel``'s
    n = 0
    for j in range(len(length)):
        n += max(1, int(math.ceil(length[j] / chunk_m)))
    boxes = np.empty((n, 4), np.int64)
    xs = np.empty(8)
    ys = np.empty(8)
    k = 0
    for j in range(len(length)):
        n_chunks = max(1, int(math.ceil(length[j] / chunk_m)))
        arc = kappa[j] != 0.0
        ch, sh, sign, radius, cx, cy, phi0 = _segment_frame(x0[j], y0[j], h0[j], kappa[j])
        r_in = max(0.0, radius - pad)
        r_out = radius + pad
        for c in range(n_chunks):
            ua, ub = _chunk_span(length[j], c, n_chunks)
            m = 0
            if not arc:  # the rectangle's corners
                for u in (ua, ub):
                    for d in (-pad, pad):
                        xs[m] = x0[j] + u * ch - d * sh
                        ys[m] = y0[j] + u * sh + d * ch
                        m += 1
            else:  # the sector's corners, and its outer rim where it crosses an axis
                phi_a = phi0 + sign * ua / radius
                phi_b = phi0 + sign * ub / radius
                for phi in (phi_a, phi_b):
                    for rho in (r_in, r_out):
                        xs[m] = cx + rho * math.cos(phi)
                        ys[m] = cy + rho * math.sin(phi)
                        m += 1
                lo = min(phi_a, phi_b)
                hi = max(phi_a, phi_b)
                quarter = 0.5 * math.pi
                for q in range(int(math.ceil(lo / quarter)), int(math.floor(hi / quarter)) + 1):
                    if m == len(xs):  # a sector of a full turn or more: the whole annulus
                        xs[0], ys[0], xs[1], ys[1] = cx - r_out, cy - r_out, cx + r_out, cy + r_out
                        m = 2
                        break
                    axis = q % 4
                    xs[m] = cx + (r_out if axis == 0 else -r_out if axis == 2 else 0.0)
                    ys[m] = cy + (r_out if axis == 1 else -r_out if axis == 3 else 0.0)
                    m += 1
            x_lo = xs[:m].min() - res
            x_hi = xs[:m].max() + res
            y_lo = ys[:m].min() - res
            y_hi = ys[:m].max() + res
            boxes[k, 0] = max(0, int(math.floor((oy - y_hi) / res)))
            boxes[k, 1] = min(n_rows - 1, int(math.ceil((oy - y_lo) / res)))
            boxes[k, 2] = max(0, int(math.floor((x_lo - ox) / res)))
            boxes[k, 3] = min(n_cols - 1, int(math.ceil((x_hi - ox) / res)))
            k += 1
    return boxes


@njit(cache=True)
def _raster_kernel(
    intensity: np.ndarray,
    labels: np.ndarray,
    ox: float,
    oy: float,
    res: float,
    x0: np.ndarray,
    y0: np.ndarray,
    h0: np.ndarray,
    kappa: np.ndarray,
    length: np.ndarray,
    s0: np.ndarray,
    total: float,
    closed: bool,
    lane_w: float,
    line_w: float,
    dash: float,
    period: float,
    gap_line: np.ndarray,
    gap_lo: np.ndarray,
    gap_hi: np.ndarray,
    passes: np.ndarray,
    start_s: float,
    start_w: float,
    stop_w: float,
    chunk_m: float,
    boxes: np.ndarray,
    todo: np.ndarray,
    tile: int,
    with_labels: bool,
    nonzero_rows: np.ndarray,
    tr_min: int,
    tr_max: int,
    tc_min: int,
    tc_max: int,
) -> None:
    """Paint the pixels of the tiles marked in ``todo`` (``tile`` × ``tile`` px each),
    which lie in the tile rows ``tr_min … tr_max`` and columns ``tc_min … tc_max`` (the
    caller knows them from its list: a scan of ``todo`` cost ≈ 1 ns a tile of the map, a
    few µs a call, for the few tiles a view needs);
    ``labels`` only if ``with_labels`` (else any array: it is not touched). Every row of
    a tile whose intensity it may write gets its bit (``row_bit``) in ``nonzero_rows``
    (per tile of ``todo``, row-major): the rows left without one stay as they were (all
    zeros in a fresh map; a bit may also mark a row left zero). ``boxes``:
    ``_chunk_boxes`` of the same arguments (constants of the map: a view's few new tiles
    need not pay for every chunk's box again).

    Chunks and pixels are visited in the same order whatever the tiles, and every pixel's
    value depends only on its own centre, so a tile painted alone equals the same tile of
    the whole map, labels included."""
    half_road = lane_w + 0.5 * line_w
    pad = half_road + 2.0 * res
    # Beyond this distance [m] from a line's middle a pixel holds none of it: its band
    # ends half a pixel past the paint (``_band`` is exactly 0 there, the margin covers
    # rounding), so the spans below skip such pixels.
    line_reach = 0.5 * line_w + 0.5 * res + ZERO_MARGIN_M
    # The side-line shortcut below needs a side line's pixels to hold none of the centre
    # line: lanes wider than a line and a pixel (any real track; a toy may be narrower).
    lines_apart = lane_w - line_reach > line_reach
    # Arc lengths around which a crossing marking (start or stop line) may be painted.
    special = [start_s] if start_s == start_s else [0.0 for _ in range(0)]
    for sx in passes:
        special.append(sx)
    special_reach = half_road + stop_w + 0.5 * start_w + 2.0 * res
    # The arc-length bands [m] of the road where a crossing marking paints (its paint
    # ends half a pixel past them, two pixels of room here).
    n_bands = (1 if start_s == start_s else 0) + 2 * len(passes)
    bands = np.empty((n_bands, 2))
    m = 0
    if start_s == start_s:
        bands[0, 0] = start_s - 0.5 * start_w - 2.0 * res
        bands[0, 1] = start_s + 0.5 * start_w + 2.0 * res
        m = 1
    for sx in passes:
        bands[m, 0] = sx - half_road - stop_w - 2.0 * res
        bands[m, 1] = sx - half_road + 2.0 * res
        bands[m + 1, 0] = sx + half_road - 2.0 * res
        bands[m + 1, 1] = sx + half_road + stop_w + 2.0 * res
        m += 2
    iv = np.empty((3 * n_bands, 2))  # a chunk's share of them (u [m]), each shift
    iv_rays = np.empty((3 * n_bands, 4))  # on an arc: the rays to their ends
    # a row's column spans [lo, hi] (empty: lo > hi): two per line and band on an arc
    spans = np.empty((6 + 2 * len(iv), 2), np.int64)
    gap_ids = np.empty(len(gap_line), np.int64)  # the rule gaps near a chunk
    # A chunk's arc lengths [m] (cyclic) where a crossing marking or a rule gap may change
    # a pixel: outside them ``_paint_pixel`` adds exactly 0 for each, and a pixel near a
    # line gets the plain chunk's value (below).
    zones = np.empty((len(bands) + len(gap_line), 2))
    # Inside a crossing (``passes``), two pixels from its edges, the lines are cut to
    # exactly nothing (``_paint_pixel``: a share of ≈ 1e-13 at most, which rounds to 0).
    dead = np.empty((len(passes), 2))
    for m in range(len(passes)):
        dead[m, 0] = passes[m] - half_road + 2.0 * res
        dead[m, 1] = passes[m] + half_road - 2.0 * res
    # Most chunks are rejected by four comparisons with the tiles' rows and columns (a
    # view paints a few tiles of a map's ~10³).
    k_chunk = 0  # the chunk's row of ``boxes``
    for j in range(len(length)):
        n_chunks = max(1, int(math.ceil(length[j] / chunk_m)))
        arc = kappa[j] != 0.0
        ready = False  # the segment's constants, computed once a chunk of it is painted
        ch = sh = sign = radius = cx = cy = phi0 = turn = 0.0
        for c in range(n_chunks):
            r_lo = boxes[k_chunk, 0]
            r_hi = boxes[k_chunk, 1]
            c_lo = boxes[k_chunk, 2]
            c_hi = boxes[k_chunk, 3]
            k_chunk += 1
            if (r_hi // tile < tr_min or r_lo // tile > tr_max or c_hi // tile < tc_min
                    or c_lo // tile > tc_max
                    or not _any_tile(todo, tile, r_lo, r_hi, c_lo, c_hi)):
                continue
            if not ready:
                ready = True
                ch, sh, sign, radius, cx, cy, phi0 = _segment_frame(x0[j], y0[j], h0[j],
                                                                    kappa[j])
                turn = 2.0 * math.pi * radius  # an arc's length once round [m]
            ua, ub = _chunk_span(length[j], c, n_chunks)
            last = c == n_chunks - 1
            # A pixel centre on a junction of segments may come out a rounding error
            # outside both: the segment's ends take ``ZERO_MARGIN_M`` more (a pixel
            # painted by both keeps the larger value, as at any overlap).
            u_min = ua - ZERO_MARGIN_M if c == 0 else ua
            u_max = ub + ZERO_MARGIN_M if last else ub
            has_special = False
            for sp in special:
                lo_s = s0[j] + ua - special_reach
                hi_s = s0[j] + ub + special_reach
                for shift in (-total, 0.0, total):
                    if lo_s <= sp + shift <= hi_s:
                        has_special = True
            # The chunk's arc lengths (as u) where a crossing marking paints the road
            # band: the start line, the stop lines before and after each crossing (its
            # cut of the lines only changes line pixels, which the line spans hold).
            n_iv = 0
            if has_special:
                for m in range(len(bands)):
                    for shift in (-total, 0.0, total):
                        lo_u = max(ua, bands[m, 0] + shift - s0[j])
                        hi_u = min(ub, bands[m, 1] + shift - s0[j])
                        if lo_u <= hi_u:
                            iv[n_iv, 0], iv[n_iv, 1] = lo_u, hi_u
                            if arc:  # the rays to its ends, as for the chunk's sector
                                phi_lo = phi0 + sign * lo_u / radius
                                phi_hi = phi0 + sign * hi_u / radius
                                iv_rays[n_iv, 0] = math.cos(phi_lo)
                                iv_rays[n_iv, 1] = math.sin(phi_lo)
                                iv_rays[n_iv, 2] = math.cos(phi_hi)
                                iv_rays[n_iv, 3] = math.sin(phi_hi)
                            n_iv += 1
            n_gaps = 0
            for g in range(len(gap_line)):  # gaps whose pixels reach the chunk
                lo_s = s0[j] + ua - 2.0 * res
                hi_s = s0[j] + ub + 2.0 * res
                for shift in (-total, 0.0, total):
                    if gap_lo[g] + shift <= hi_s and gap_hi[g] + shift >= lo_s:
                        gap_ids[n_gaps] = g
                        n_gaps += 1
                        break
            # A plain chunk (no crossing marking, no rule gap, no labels): a pixel near
            # the right or left line holds that line's share across the road, whatever
            # its arc length (``_paint_pixel`` multiplies it by exactly 1.0 here); one near
            # the centre line holds its share across times the dashes' share along, and
            # nothing of the other lines. The same expressions as ``_paint_pixel``'s.
            plain = not has_special and n_gaps == 0 and not with_labels and lines_apart
            # Not plain: the pixels outside its zones get the plain values too (most of a
            # chunk's: ``_paint_pixel`` cost ≈ 6× as much a pixel).
            n_zones = 0
            if not plain and not with_labels and lines_apart:
                if has_special:
                    # The start and stop lines' bands (their paint ends half a pixel past
                    # them, two pixels of room), and a crossing's edges, where its cut
                    # of the lines is partial (the rest of a crossing is ``dead``).
                    for m in range(len(bands)):
                        zones[n_zones, 0] = bands[m, 0]
                        zones[n_zones, 1] = bands[m, 1]
                        n_zones += 1
                for k in range(n_gaps):
                    zones[n_zones, 0] = gap_lo[gap_ids[k]] - 2.0 * res
                    zones[n_zones, 1] = gap_hi[gap_ids[k]] + 2.0 * res
                    n_zones += 1
            zoned = not plain and n_zones > 0
            across = 0.0
            if arc:
                # The chunk's sector of the annulus |d| <= pad, as two half-planes through
                # the centre (when the sector is convex), loosened by ARC_CLIP_SLACK_PX.
                slack = ARC_CLIP_SLACK_PX * res
                wedge = (ub - ua) / radius < 0.9 * math.pi
                phi_a = phi0 + sign * ua / radius
                phi_b = phi0 + sign * ub / radius
                ax_, ay_ = math.cos(phi_a), math.sin(phi_a)
                bx_, by_ = math.cos(phi_b), math.sin(phi_b)
            tc_lo = c_lo // tile
            tc_hi = c_hi // tile
            # Row by row, but tile row by tile row first: the rows of a tile row with no
            # tile to paint inside the chunk's columns are skipped whole (a chunk's box is
            # ~4 tiles high, a view needs a few tiles).
            for tr in range(r_lo // tile, r_hi // tile + 1):
                tile_row = todo[tr]
                if not _span_live(tile_row, tile, tc_lo * tile, tc_hi * tile):
                    continue
                for r in range(max(r_lo, tr * tile), min(r_hi, (tr + 1) * tile - 1) + 1):
                    py = oy - (r + 0.5) * res
                    # The row's column spans that can hold a painted pixel: the bands around the
                    # three lines, and the road band where a crossing marking may be painted (the
                    # per-pixel test below rejects everything else anyway; a pixel in two spans
                    # is painted twice, the same value).
                    n_sp = 0
                    if arc:
                        # Most rows of a chunk's box reach no tile to paint (a view needs a
                        # few tiles; ~6 rows in 7 here): the road band's spans, which hold
                        # all the others (monotone bounds of wider radii), say so first.
                        r_in, r_out = radius - pad - slack, radius + pad + slack
                        a0, a1, b0, b1 = _arc_row_spans(py - cy, cx, ox, res, r_in, r_out, wedge,
                                                        ax_, ay_, bx_, by_, sign, slack, c_lo, c_hi)
                        if not (_span_live(tile_row, tile, a0, a1)
                                or _span_live(tile_row, tile, b0, b1)):
                            continue
                        for li in range(3 + n_iv):
                            if li < 3:  # a line's band, the chunk's sector
                                rc = radius - sign * (li - 1) * lane_w
                                a0, a1, b0, b1 = _arc_row_spans(
                                    py - cy, cx, ox, res, rc - line_reach - slack,
                                    rc + line_reach + slack, wedge, ax_, ay_, bx_, by_, sign, slack,
                                    c_lo, c_hi)
                            else:  # the road band, a crossing marking's sector
                                ray = iv_rays[li - 3]
                                a0, a1, b0, b1 = _arc_row_spans(
                                    py - cy, cx, ox, res, r_in, r_out, True, ray[0], ray[1], ray[2],
                                    ray[3], sign, slack, c_lo, c_hi)
                            spans[n_sp, 0], spans[n_sp, 1] = a0, a1
                            spans[n_sp + 1, 0], spans[n_sp + 1, 1] = b0, b1
                            n_sp += 2
                    else:
                        # u and d are linear in x along a row: clip the row to the chunk's band.
                        dy = py - y0[j]
                        u_lo, u_hi = _linear_span(ch, dy * sh, ua, ub, x0[j], ox, res, c_lo, c_hi)
                        q0, q1 = _linear_span(-sh, dy * ch, -pad, pad, x0[j], ox, res, u_lo, u_hi)
                        if not _span_live(tile_row, tile, q0, q1):  # as for arcs
                            continue
                        for li in range(3 + n_iv):
                            if li < 3:
                                dl = (li - 1) * lane_w
                                q0, q1 = _linear_span(-sh, dy * ch, dl - line_reach,
                                                      dl + line_reach, x0[j], ox, res, u_lo, u_hi)
                            else:
                                v_lo, v_hi = _linear_span(ch, dy * sh, iv[li - 3, 0], iv[li - 3, 1],
                                                          x0[j], ox, res, u_lo, u_hi)
                                q0, q1 = _linear_span(-sh, dy * ch, -pad, pad, x0[j], ox, res, v_lo,
                                                      v_hi)
                            spans[n_sp, 0], spans[n_sp, 1] = q0, q1
                            n_sp += 1
                    for span in range(n_sp):
                        q_run = spans[span, 0]
                        span_hi = spans[span, 1]
                        while q_run <= span_hi:  # the span's runs through one tile each
                            tc = q_run // tile
                            q_end = min(span_hi, (tc + 1) * tile - 1)
                            first = q_run
                            q_run = q_end + 1
                            if not tile_row[tc]:
                                continue
                            # The row may get paint here (a run of a span: it almost
                            # always does); the bit is set ahead, outside the pixel loop.
                            nonzero_rows[tr * todo.shape[1] + tc] |= row_bit(r - tr * tile)
                            for q in range(first, q_end + 1):
                                px = ox + (q + 0.5) * res
                                vx = vy = hv = dx = dy = 0.0
                                if arc:
                                    vx = px - cx
                                    vy = py - cy
                                    hv = math.sqrt(vx * vx + vy * vy)
                                    d = sign * (radius - hv)
                                else:
                                    dx = px - x0[j]
                                    dy = py - y0[j]
                                    d = -dx * sh + dy * ch
                                if abs(d) > pad or not (has_special
                                                        or _near_line(d, lane_w, line_reach)):
                                    continue
                                side = plain and abs(abs(d) - lane_w) <= line_reach
                                centre = plain and abs(d) <= line_reach
                                if centre:
                                    across = _band(d, -0.5 * line_w, 0.5 * line_w, res)
                                    if across == 0.0:
                                        continue  # nothing to paint: no arc length
                                if not arc:
                                    u = dx * ch + dy * sh
                                    if u < u_min or u > u_max or (u == ub and not last):
                                        continue
                                # Well inside the chunk's sector (by far more than rounding
                                # moves an angle), its arc length is inside [ua, ub): no
                                # atan2 for a pixel whose value does not depend on it.
                                elif not (side and wedge
                                          and sign * (ax_ * vy - ay_ * vx) > INSIDE_MARGIN * hv
                                          and sign * (vx * by_ - vy * bx_) > INSIDE_MARGIN * hv):
                                    u = _turn_mod(sign * (math.atan2(vy, vx) - phi0)) * radius
                                    if (c == 0 and u > u_max and u >= turn - ZERO_MARGIN_M
                                            and length[j] < turn - ZERO_MARGIN_M):
                                        u -= turn  # just before the start (not a full turn,
                                        # whose last chunk has the pixel at its end)
                                    if u < u_min or u > u_max or (u == ub and not last):
                                        continue
                                if side:  # ``_paint_pixel``'s value, its expressions as they are
                                    dl = lane_w if d > 0.0 else -lane_w
                                    across = _band(d, dl - 0.5 * line_w, dl + 0.5 * line_w, res)
                                    value = int(min(1.0, across) * 255.0 + 0.5)
                                    if value > intensity[r, q]:
                                        intensity[r, q] = value
                                    continue
                                s = s0[j] + u
                                if closed and s >= total:
                                    s -= total
                                elif closed and s < 0.0:  # a rounding error before the seam:
                                    s += total  # the last segment's end, as it paints it
                                if centre:  # likewise for the centre line's dashes
                                    along = (_dash_integral(s + 0.5 * res, dash, period)
                                             - _dash_integral(s - 0.5 * res, dash, period))
                                    paint = across * (along / res)
                                    value = int(min(1.0, max(0.0, paint)) * 255.0 + 0.5)
                                    if value > intensity[r, q]:
                                        intensity[r, q] = value
                                    continue
                                if zoned and not _in_zones(s, zones, n_zones, total, closed):
                                    if has_special and _in_zones(s, dead, len(dead), total, closed):
                                        continue  # inside a crossing: nothing
                                    # No crossing marking, no rule gap reaches the pixel:
                                    # the plain chunk's expressions (at most one line near).
                                    if abs(abs(d) - lane_w) <= line_reach:
                                        dl = lane_w if d > 0.0 else -lane_w
                                        across = _band(d, dl - 0.5 * line_w, dl + 0.5 * line_w,
                                                       res)
                                        value = int(min(1.0, across) * 255.0 + 0.5)
                                    elif abs(d) <= line_reach:
                                        across = _band(d, -0.5 * line_w, 0.5 * line_w, res)
                                        along = (_dash_integral(s + 0.5 * res, dash, period)
                                                 - _dash_integral(s - 0.5 * res, dash, period))
                                        paint = across * (along / res)
                                        value = int(min(1.0, max(0.0, paint)) * 255.0 + 0.5)
                                    else:
                                        continue  # near no line: nothing
                                    if value > intensity[r, q]:
                                        intensity[r, q] = value
                                    continue
                                _paint_pixel(intensity, labels, r, q, s, d, res, total, closed,
                                             lane_w, line_w, dash, period, gap_line, gap_lo,
                                             gap_hi, gap_ids, n_gaps, passes, start_s,
                                             start_w, stop_w, has_special, with_labels)


@njit(cache=True)
def _paint_listed(tiles: np.ndarray, filled: np.ndarray, todo: np.ndarray,
                  record: np.ndarray, n_record: np.ndarray,
                  intensity: np.ndarray, labels: np.ndarray, ox: float, oy: float, res: float,
                  x0: np.ndarray, y0: np.ndarray, h0: np.ndarray, kappa: np.ndarray,
                  length: np.ndarray, s0: np.ndarray, total: float, closed: bool,
                  lane_w: float, line_w: float, dash: float, period: float,
                  gap_line: np.ndarray, gap_lo: np.ndarray, gap_hi: np.ndarray,
                  passes: np.ndarray, start_s: float, start_w: float, stop_w: float,
                  chunk_m: float, boxes: np.ndarray, tile: int, with_labels: bool,
                  nonzero_rows: np.ndarray) -> int:
    """Paint the listed tiles (indices into the flat ``filled``; ones past its end are
    skipped: a scene's list of the tiles of all its levels, level 0 first and numbered
    as here) that are not painted yet, in one call: each marked in ``todo`` (the
    kernel's mask, all 0 between calls) and appended to ``record[:n_record[0]]`` (the
    painted tiles, recorded before they are painted: no Ctrl-C can land in between),
    then painted (``_raster_kernel``, which marks their rows with paint in
    ``nonzero_rows``), unmarked and set in ``filled``. A tile listed twice is painted and
    recorded once. Returns how many were painted."""
    mask = todo.reshape(-1)
    n_tile_cols = todo.shape[1]
    start = n_record[0]
    m = start
    tr_min, tr_max, tc_min, tc_max = todo.shape[0], -1, n_tile_cols, -1
    for k in range(len(tiles)):
        index = tiles[k]
        if 0 <= index < len(filled) and not filled[index] and not mask[index]:
            mask[index] = 1
            record[m] = index
            nonzero_rows[index] = 0
            m += 1
            tr, tc = divmod(index, n_tile_cols)
            tr_min, tr_max = min(tr_min, tr), max(tr_max, tr)
            tc_min, tc_max = min(tc_min, tc), max(tc_max, tc)
    n_record[0] = m
    if m == start:
        return 0
    _raster_kernel(intensity, labels, ox, oy, res, x0, y0, h0, kappa, length, s0, total,
                   closed, lane_w, line_w, dash, period, gap_line, gap_lo, gap_hi, passes,
                   start_s, start_w, stop_w, chunk_m, boxes, todo, tile, with_labels,
                   nonzero_rows, tr_min, tr_max, tc_min, tc_max)
    for k in range(start, m):
        mask[record[k]] = 0
        filled[record[k]] = 1
    return m - start


_LINE_INDEX = {"right": 0, "centre": 1, "left": 2}


INSIDE_MARGIN: float = 1e-9
"""How far inside a chunk's sector [rad] a pixel must lie for its arc length to be
known to fall inside the chunk without computing it (rounding moves it ~1e-15)."""

ZERO_MARGIN_M: float = 1e-9
"""Room [m] for rounding where a test skips pixels that hold exactly nothing (a
pixel's coordinates are ~1e-15 m off at most)."""

ARC_CLIP_SLACK_PX: float = 0.25
"""How far [px] the row spans of an arc chunk reach beyond its exact sector of the road:
the spans only skip pixels the exact per-pixel test would reject, rounding included."""


@njit(cache=True)
def _clip_half_plane(lo: float, hi: float, coef: float, rhs: float, cx: float,
                     reach: float) -> tuple[float, float]:
    """``[lo, hi]`` (x [m]) cut to ``coef · (x − cx) >= rhs``, for ``|x − cx| <= reach``."""
    if abs(coef) < 1e-12:
        if rhs > abs(coef) * reach:
            return 1.0, 0.0  # empty
        return lo, hi
    if coef > 0.0:
        return max(lo, cx + rhs / coef), hi
    return lo, min(hi, cx + rhs / coef)


@njit(cache=True)
def _linear_span(coef: float, base: float, lo_v: float, hi_v: float, x0: float, ox: float,
                 res: float, q_lo: int, q_hi: int) -> tuple[int, int]:
    """The columns ``q_lo … q_hi`` of a row whose pixel centres ``px`` can have
    ``coef · (px − x0) + base`` in ``[lo_v, hi_v]`` (half a pixel of rounding room; a
    ``coef`` of rounding noise, e.g. cos(π/2), moves the value by less than
    ``ZERO_MARGIN_M`` across a map: a row that far outside is kept, or a pixel row on a
    chunk boundary of a road running up the map fell in neither chunk's spans)."""
    if abs(coef) < 1e-12:
        if base < lo_v - ZERO_MARGIN_M or base > hi_v + ZERO_MARGIN_M:
            return 0, -1
        return q_lo, q_hi
    xa = x0 + (lo_v - base) / coef
    xb = x0 + (hi_v - base) / coef
    return (max(q_lo, int(math.floor((min(xa, xb) - ox) / res - 0.5))),
            min(q_hi, int(math.ceil((max(xa, xb) - ox) / res - 0.5))))


@njit(cache=True)
def _arc_row_spans(vy: float, cx: float, ox: float, res: float, r_in: float, r_out: float,
                   wedge: bool, ax: float, ay: float, bx: float, by: float, sign: float,
                   slack: float, c_lo: int, c_hi: int) -> tuple[int, int, int, int]:
    """The one or two column spans of a map row (``vy`` [m] above the arc's centre) that
    can hold pixels of an arc chunk: inside the annulus ``r_in … r_out`` [m] around the
    centre and, with ``wedge``, between the rays to the chunk's ends ``(ax, ay)`` and
    ``(bx, by)`` (each loosened by ``slack`` [m]). Empty spans have lo > hi."""
    if vy * vy > r_out * r_out:
        return 0, -1, 0, -1
    w_out = math.sqrt(r_out * r_out - vy * vy)
    lo = cx - w_out
    hi = cx + w_out
    if wedge:  # sign · cross(a, v) >= −slack and sign · cross(v, b) >= −slack
        lo, hi = _clip_half_plane(lo, hi, -sign * ay, -slack - sign * ax * vy, cx, r_out)
        lo, hi = _clip_half_plane(lo, hi, sign * by, -slack + sign * bx * vy, cx, r_out)
    if lo > hi:
        return 0, -1, 0, -1
    lo2 = 1.0
    hi2 = 0.0
    if r_in > 0.0 and vy * vy < r_in * r_in:
        w_in = math.sqrt(r_in * r_in - vy * vy)
        lo2 = max(lo, cx + w_in)
        hi2 = hi
        hi = min(hi, cx - w_in)
    q1 = (0, -1)
    q2 = (0, -1)
    if lo <= hi:
        q1 = (max(c_lo, int(math.floor((lo - ox) / res - 0.5))),
              min(c_hi, int(math.ceil((hi - ox) / res - 0.5))))
    if lo2 <= hi2:
        q2 = (max(c_lo, int(math.floor((lo2 - ox) / res - 0.5))),
              min(c_hi, int(math.ceil((hi2 - ox) / res - 0.5))))
    return q1[0], q1[1], q2[0], q2[1]


@njit(cache=True)
def _span_live(tile_row: np.ndarray, tile: int, lo: int, hi: int) -> bool:
    """Whether the columns ``lo … hi`` (empty if lo > hi) of a row meet a tile of
    ``tile_row`` (a row of ``todo``)."""
    if lo > hi:
        return False
    for tc in range(lo // tile, hi // tile + 1):
        if tile_row[tc]:
            return True
    return False


@njit(cache=True)
def _any_tile(todo: np.ndarray, tile: int, r_lo: int, r_hi: int, c_lo: int, c_hi: int) -> bool:
    """Whether a tile of ``todo`` meets the pixel box ``[r_lo, r_hi] × [c_lo, c_hi]``."""
    for tr in range(r_lo // tile, r_hi // tile + 1):
        for tc in range(c_lo // tile, c_hi // tile + 1):
            if todo[tr, tc]:
                return True
    return False


def untouched_zeros(shape: tuple[int, ...], memory: mmap.mmap | None = None, *,
                    reserve_bytes: int = 0) -> np.ndarray:
    """A uint8 array of zeros whose pages cost nothing until written: anonymous memory
    straight from the kernel. (``np.zeros`` is calloc, and once large blocks have been
    freed, glibc serves the next ones from its heap and clears them in full.)

    ``memory``: all-zero anonymous memory to take instead of new memory if it is large
    enough (its pages already written once cost no page fault again, ≈ 2 µs each here);
    the caller hands it over (see ``memory_of``). ``reserve_bytes``: new memory is at
    least this large, for a caller that hands it on to larger arrays later (a page never
    written takes no memory, though all of it counts in the kernel's commit charge)."""
    size = max(1, math.prod(shape))
    if memory is None or len(memory) < size:
        memory = mmap.mmap(-1, max(size, reserve_bytes))
    return np.frombuffer(memory, np.uint8, math.prod(shape)).reshape(shape)


def paintable_zeros(shape: tuple[int, int]) -> np.ndarray:
    """``untouched_zeros`` of ``shape`` (rows, cols) seen through one spare column per row:
    the paint kernels then get the array type they get for a scene's atlas (numba's layout
    "A", not contiguous) and are compiled once, not once per layout. A map painting into
    its own memory (one whose scene's atlas went to another scene) otherwise compiled a
    second set, ≈ 8 s the first time in an install, in the middle of a run."""
    rows, cols = shape
    return untouched_zeros((rows, cols + 1))[:, :cols]


def memory_of(array: np.ndarray) -> mmap.mmap | None:
    """The anonymous memory under an ``untouched_zeros`` array (None for other arrays,
    e.g. one restored from a pickle)."""
    base: object = array
    while isinstance(base, np.ndarray | memoryview):
        base = base.base if isinstance(base, np.ndarray) else base.obj
    return base if isinstance(base, mmap.mmap) else None


_NO_LABELS = np.zeros((1, 1), np.uint8)  # the kernel's labels argument when there are none

TILE_PX: int = 64
"""Edge of a tile of a ``TiledMarkingMap`` [px] (25.6 cm at 4 mm/px): the unit painted on
demand."""


def map_geometry(track: Track, resolution_m: float = DEFAULT_RESOLUTION_M,
                 margin_m: float = dimensions.MAT_EDGE_MARGIN_M
                 ) -> tuple[tuple[float, float], tuple[int, int]]:
    """Where the marking map of ``track`` lies: the world ``(x, y)`` [m] of its top-left
    corner and its ``(rows, cols)`` (at most ``MAX_MAP_PIXELS``)."""
    if not (math.isfinite(resolution_m) and resolution_m > 0):
        raise ValueError(f"resolution_m must be > 0, got {resolution_m!r}")
    xmin, ymin, xmax, ymax = track.bounds(margin_m)
    n_cols = int(math.ceil((xmax - xmin) / resolution_m))
    n_rows = int(math.ceil((ymax - ymin) / resolution_m))
    if n_cols * n_rows > MAX_MAP_PIXELS:
        raise ValueError(f"a {n_cols}×{n_rows} map is too large (more than MAX_MAP_PIXELS = "
                         f"{MAX_MAP_PIXELS}: {math.sqrt(MAX_MAP_PIXELS) * resolution_m:.0f} m "
                         f"square at {resolution_m * 1000:g} mm/px); use a coarser "
                         "resolution_m")
    return (xmin, ymax), (n_rows, n_cols)


class TiledMarkingMap:
    """A marking map painted tile by tile on demand (``fill``): a camera sees a few metres
    of a track, so painting only what it looks at makes a new track cheap to show.

    ``intensity`` and ``labels`` are full-size arrays of ``untouched_zeros`` (pages never
    written cost no memory); a tile once painted holds exactly the values ``rasterize``
    gives there. ``filled`` marks the painted tiles, ``(ceil(H / tile_px),
    ceil(W / tile_px))`` uint8. ``labels=False``: no label map (``labels`` is None): a
    rendered scene reads only the intensity, and each page of labels written costs a
    page fault (≈ 2.8 µs here)."""

    def __init__(self, track: Track, resolution_m: float = DEFAULT_RESOLUTION_M,
                 margin_m: float = dimensions.MAT_EDGE_MARGIN_M,
                 tile_px: int = TILE_PX, *, labels: bool = True,
                 intensity: np.ndarray | None = None) -> None:
        if not (isinstance(tile_px, int) and tile_px > 0):
            raise ValueError(f"tile_px must be a positive int, got {tile_px!r}")
        (xmin, ymax), (n_rows, n_cols) = map_geometry(track, resolution_m, margin_m)
        if intensity is not None and (intensity.shape != (n_rows, n_cols)
                                      or intensity.dtype != np.uint8):
            raise ValueError(f"intensity must be uint8 of shape {(n_rows, n_cols)}, got "
                             f"{intensity.dtype} {intensity.shape}")
        self.track = track
        self.origin_m = (xmin, ymax)
        self.resolution_m = float(resolution_m)
        self.tile_px = tile_px
        # ``intensity``: paint into this zero array instead (a scene's atlas level 0).
        self._shape = (n_rows, n_cols)
        self.intensity = paintable_zeros((n_rows, n_cols)) if intensity is None else intensity
        self.labels = untouched_zeros((n_rows, n_cols)) if labels else None
        self.filled = np.zeros((-(-n_rows // tile_px), -(-n_cols // tile_px)), np.uint8)
        self._todo = np.zeros_like(self.filled)  # the kernel's tiles to paint: all 0 between calls
        # The tiles painted, in order: ``_record[:_n_record[0]]``, appended to by the kernel
        # (a tile is painted once until ``detach``, so the grid's size is room enough).
        self._record = np.empty(self.filled.size, np.int64)
        self._n_record = np.zeros(1, np.int64)
        self.nonzero_rows = np.zeros(self.filled.size, np.int64)
        """Per tile (row-major, as ``filled``), a bit per pixel row (``row_bit``) that may
        hold paint: a row whose bit is clear holds only zeros (~4 rows in 5 of the tiles a
        camera sees), so a lazy scene neither reads nor clears it."""
        self._boxes: np.ndarray | None = None  # ``_chunk_boxes``, on the first fill
        self._paint_args: tuple | None = None  # ``paint_args``, made on first use
        t = track.table
        gaps = track.gaps
        passes = np.array([s for x in track.intersections for s in (x.s1_m, x.s2_m)],
                          dtype=np.float64)
        self._args = (
            xmin, ymax, self.resolution_m,
            t.x0, t.y0, t.h0, t.kappa, t.length, t.s0, track.length_m, track.closed,
            track.lane_width_m, dimensions.LINE_WIDTH_M, dimensions.CENTRE_DASH_M,
            dimensions.CENTRE_DASH_M + dimensions.CENTRE_DASH_GAP_M,
            np.array([_LINE_INDEX[g.line.value] for g in gaps], dtype=np.int64),
            np.array([g.s_m for g in gaps], dtype=np.float64),
            np.array([g.s_m + g.length_m for g in gaps], dtype=np.float64),
            passes,
            math.nan if track.start_line_s_m is None else float(track.start_line_s_m),
            dimensions.START_LINE_WIDTH_M, dimensions.STOP_LINE_WIDTH_M, CHUNK_M,
        )

    @property
    def shape(self) -> tuple[int, int]:
        return self._shape

    @property
    def intensity(self) -> np.ndarray:
        """The painted intensity, ``shape``, uint8 (fresh zeros after ``detach``, mapped
        only when asked for: a retired scene's map is rarely painted again, and a mapping
        costs ~60 µs of a reset in the env)."""
        if self._intensity is None:
            self._intensity = paintable_zeros(self._shape)
        return self._intensity

    @intensity.setter
    def intensity(self, value: np.ndarray) -> None:
        self._intensity = value
        self._paint_args = None  # they hold the intensity

    @property
    def complete(self) -> bool:
        return bool(self.filled.all())

    def detach(self) -> None:
        """Start again on fresh memory, nothing painted: the memory painted so far (an
        atlas's level 0) was handed over to another scene. Nothing counts as painted
        before the memory changes: a Ctrl-C in between leaves a map that repaints into
        its old memory (the same values), never one that counts fresh zeros as paint."""
        self.filled[:] = 0
        self.nonzero_rows[:] = 0
        self._n_record[0] = 0
        self._intensity = None  # fresh zeros when next asked for
        self._paint_args = None  # they hold the old memory
        if self.labels is not None:
            self.labels = untouched_zeros(self.shape)

    def fill(self, tiles: np.ndarray) -> None:
        """Paint the tiles marked in ``tiles`` (a mask shaped like ``filled``) that are not
        painted yet."""
        mask = np.asarray(tiles, dtype=bool)
        if mask.shape != self.filled.shape:
            raise ValueError(f"tiles must be a mask of shape {self.filled.shape}, got "
                             f"{mask.shape}")
        self.fill_listed(np.flatnonzero(mask))

    def fill_listed(self, tiles: np.ndarray) -> None:
        """Paint the tiles listed in ``tiles`` (a 1-D int array of indices into
        ``filled``, row-major, ``0 ≤ i < filled.size``: a TypeError or IndexError
        otherwise, before anything is painted) that are not painted yet: a view needs a few
        of ~10⁴ tiles, so nothing here scans the whole grid."""
        tiles = np.asarray(tiles)
        flat = self.filled.reshape(-1)
        if tiles.ndim != 1 or tiles.dtype.kind not in "iu":
            raise TypeError(f"tiles must be a 1-D array of tile indices (ints), got "
                            f"{tiles.dtype} of shape {tiles.shape}")
        if len(tiles) and not (tiles.min() >= 0 and tiles.max() < len(flat)):
            raise IndexError(f"a listed tile is outside the map's tile grid of {len(flat)} "
                             "tiles")
        self.paint_level0(tiles.astype(np.int64, copy=False))

    def paint_level0(self, tiles: np.ndarray) -> int:
        """``fill_listed`` for a caller that vouches for its list (a lazy scene, every
        frame): an int64 1-D array, unchecked; indices past the grid are skipped (a
        scene's list of its levels' tiles: level 0 first, numbered as here). Returns how
        many tiles were painted."""
        return _paint_listed(tiles, *self.paint_args)

    @property
    def paint_args(self) -> tuple:
        """``_paint_listed``'s arguments after the list of tiles, for a kernel that paints
        tiles itself (a lazy scene's fill inside its renderer's kernel). The same tuple
        until the map's memory changes (``detach``, a new ``intensity``): a caller keeping
        it checks ``is`` against this property before each use."""
        if self._paint_args is None:
            if self._boxes is None:
                ox, oy, res, x0, y0, h0, kappa, length = self._args[:8]
                lane_w, line_w, chunk_m = self._args[11], self._args[12], self._args[-1]
                self._boxes = _chunk_boxes(*self.shape, ox, oy, res, x0, y0, h0, kappa,
                                           length, lane_w, line_w, chunk_m)
            self._paint_args = (
                self.filled.reshape(-1), self._todo, self._record, self._n_record,
                self.intensity, self.labels if self.labels is not None else _NO_LABELS,
                *self._args, self._boxes, self.tile_px, self.labels is not None,
                self.nonzero_rows)
        return self._paint_args

    def __getstate__(self) -> dict[str, object]:
        state = self.__dict__.copy()
        state["_paint_args"] = None  # views of the state's arrays: a copy makes its own
        return state

    def painted_tiles(self) -> np.ndarray:
        """The painted tiles' indices into ``filled`` (row-major, each once), in the order
        they were painted, without a scan of it."""
        return self._record[:self._n_record[0]].copy()

    def __setstate__(self, state: dict[str, object]) -> None:
        self.__dict__.update(state)
        self._paint_args = None  # pickled before them, or they held the old arrays
        if "intensity" in state:  # pickled before the lazy intensity
            self._intensity = self.__dict__.pop("intensity")
            self._shape = self._intensity.shape
        if self._intensity is not None and self._intensity.flags.c_contiguous:
            # A pickle holds the intensity contiguous: back into the kernels' array type.
            # Only the painted texels are written: the others stay untouched zero pages.
            own = paintable_zeros(self._shape)
            np.copyto(own, self._intensity, where=self._intensity != 0)
            self._intensity = own
        if "nonzero_rows" not in state:  # pickled before the row masks: every row may
            self.nonzero_rows = np.full(self.filled.size, -1, np.int64)  # hold paint
        if "_record" not in state:
            # Pickled before the record array: with a list of arrays ("_painted"), which
            # may hold a tile twice or one a Ctrl-C kept from being painted, or before
            # that with no list at all. The record holds each filled tile once (what the
            # kernel relies on to stay inside it), listed ones first, in their order.
            painted = self.__dict__.pop("_painted", [])
            listed = np.concatenate(painted).astype(np.int64) if painted else np.zeros(0, np.int64)
            flat = self.filled.reshape(-1)
            listed = listed[(listed >= 0) & (listed < len(flat))]
            listed = listed[flat[listed] != 0]
            listed = listed[np.sort(np.unique(listed, return_index=True)[1])]
            rest = np.setdiff1d(np.flatnonzero(flat), listed)
            self._record = np.empty(flat.size, np.int64)
            self._n_record = np.array([len(listed) + len(rest)], np.int64)
            self._record[:self._n_record[0]] = np.concatenate((listed, rest))

    def fill_all(self) -> MarkingMap:
        """Paint every tile; the whole map (one without labels is no ``MarkingMap``)."""
        if self.labels is None:
            raise ValueError("a TiledMarkingMap made with labels=False has no labels to give "
                             "a MarkingMap; make it with labels=True")
        self.fill(np.ones(self.filled.shape, bool))
        return MarkingMap(self.intensity, self.labels, self.origin_m, self.resolution_m)


def rasterize(track: Track, resolution_m: float = DEFAULT_RESOLUTION_M,
              margin_m: float = dimensions.MAT_EDGE_MARGIN_M) -> MarkingMap:
    """Paint the track's markings top-down at ``resolution_m`` [m/px].

    The map covers the road plus ``margin_m`` [m] of mat on every side (the rules' 300 mm
    to the mat's edge by default).
    """
    return TiledMarkingMap(track, resolution_m, margin_m).fill_all()
