"""What the camera can see, prepared once per track (and per appearance draw).

A ``Scene`` holds the track's marking map as a mip pyramid (for footprint-correct
anti-aliasing), a coarse light map on the mat (shadows, glare spots, worn paint), the
hall's walls as a texture along their perimeter, and the obstacle boxes. Everything
random (where shadows and glare fall, which paint is worn, what hangs on the walls)
is drawn from the ``numpy.random.Generator`` passed in.
"""

from __future__ import annotations

import math
import mmap
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np
from numba import njit

from tfalda_sim.tracks import MarkingMap, Track, rasterize
from tfalda_sim.tracks.raster import (
    DEFAULT_RESOLUTION_M,
    TILE_PX,
    TiledMarkingMap,
    _paint_listed,
    map_geometry,
    memory_of,
    row_bit,
    untouched_zeros,
)
from tfalda_sim.tracks.rules import obstacle_corners

from .effects import Effects

LIGHT_RES_M: float = 0.05
"""Resolution of the light map (shadows, glare spots) [m/px]."""

WALL_TEXEL_M: float = 0.02
"""Resolution of the wall texture [m/texel]."""

ATLAS_GUARD: int = 4
"""Zero texels around every mip level in the atlas, so bilinear taps never bleed."""

TILE_TEXELS: int = TILE_PX
"""Edge of a level-0 tile of a lazy scene's atlas [texels] (the marking map's tile);
level L's tiles cover the same ground, ``max(1, TILE_TEXELS >> L)`` texels."""

ATLAS_RESERVE_BYTES: int = 32 << 20
"""Smallest memory [bytes] a lazy scene's atlas takes when it needs new memory: the env
hands an atlas's memory on to the next track's scene (``build_scene(reuse=…)``), whose
already written pages cost no page fault (≈ 2 µs per 4 KiB page here), but memory too
small for a larger atlas is replaced, and every page of the new one faults again. The
default generated tracks' atlases take 5.5–29.1 MiB (median 9.5; seeds 0–999): in a
random order each new largest one replaced the memory (8–14 times per process in 24,000
steps of a 2-env vector env, whose envs keep two memories each). Pages never written
take no memory; the kernel counts the whole reserve in its commit charge
(``Committed_AS``), which refuses it only under strict overcommit (``vm.overcommit_memory``
= 2), where each memory counts 32 MiB instead of its atlas's size."""

MAX_ATLAS_SIDE_TEXELS: int = 32767
"""Longest side of the mip atlas [texels]: OpenCV's remap needs images below
32767 × 32767 (a documented limitation; 131 m of mat at 4 mm per texel)."""


@dataclass(frozen=True)
class Hall:
    """The room: walls on a cylinder ``distance_m`` around the car, ``height_m`` high, a
    ceiling above. (Walls move with the car, like a sky box: the thesis' detector only
    looks at the road, and this keeps wall pixels as cheap as a texture fetch.)"""

    distance_m: float = 4.0
    height_m: float = 2.6

    def __post_init__(self) -> None:
        if not (self.distance_m > 0 and self.height_m > 0):
            raise ValueError("Hall.distance_m and Hall.height_m must be > 0")


@dataclass(frozen=True, eq=False)  # array fields: identity equality, hashable
class Scene:
    """Render-ready data of one track. Build with ``build_scene``."""

    track: Track
    effects: Effects
    hall: Hall
    atlas: np.ndarray  # uint8: all mip levels of the (worn) marking map and the wall texture
    level_origin: np.ndarray  # (L, 2) float32: atlas (x, y) of each level's texel (0, 0)
    wall_origin: tuple[int, int]  # atlas (x, y) of the wall texture's texel (0, 0)
    wall_size: tuple[int, int]  # wall texture (cols around the cylinder, rows up) [texels]
    level0_size: tuple[int, int]  # level 0 (cols, rows) [texels]
    resolution_m: float  # level-0 texel [m]
    origin: tuple[float, float]  # world (x, y) of level 0's top-left corner [m]
    light: np.ndarray | None  # (h, w, 2) uint8: shadow gain ×255, glare [DN]; None: no light
    boxes: np.ndarray  # (n, 8, 3) obstacle corners [m]: 4 on the ground, 4 on top
    tiles: MipTiles | None = None  # lazy scene: the marking tiles filled so far; None: all

    @property
    def levels(self) -> int:
        return len(self.level_origin)

    def prepare(self, bounds: np.ndarray, affines: np.ndarray,
                wall_rows: tuple[float, float] = (-math.inf, math.inf)) -> None:
        """Fill the atlas under a view before it is sampled (a no-op once all is filled):
        ``bounds`` ``(n, 5)`` rows ``(level, x_min, x_max, y_min, y_max)``, car-frame boxes
        [m] of the ground hits read at a mip level; ``affines`` ``(k, 6)`` the car poses'
        maps car frame → level-0 texels (see ``Renderer``); ``wall_rows`` the range of
        wall texture rows [texels] read (all by default; inf, −inf: none)."""
        if self.tiles is not None and not self.tiles.complete:  # retired: not complete
            self.tiles.ensure(bounds, affines)
            self.tiles.ensure_walls(*wall_rows)

    def fill_all(self) -> None:
        """Fill every tile: the atlas becomes the eager scene's."""
        if self.tiles is not None:
            self.tiles.fill_all()


def _atlas(level0: np.ndarray, wall: np.ndarray, min_size: int = 8
           ) -> tuple[np.ndarray, np.ndarray, tuple[int, int]]:
    """Mip levels (2×2 box averages) and the wall texture packed into one image: level 0 on
    the left, the other levels and then the walls stacked in a column to its right, each
    inside a zero guard band. The wall texture gets its first column repeated after its
    last, so bilinear taps wrap around the cylinder."""
    levels = [level0]
    while min(levels[-1].shape) // 2 >= min_size and len(levels) < 10:
        prev = levels[-1]
        rows, cols = prev.shape[0] // 2 * 2, prev.shape[1] // 2 * 2
        levels.append(cv2.resize(prev[:rows, :cols], (cols // 2, rows // 2),
                                 interpolation=cv2.INTER_AREA))
    wall = np.concatenate([wall, wall[:, :1]], axis=1)
    g = ATLAS_GUARD
    column = [*levels[1:], wall]
    right_w = max(t.shape[1] for t in column) + 2 * g
    right_h = sum(t.shape[0] + 2 * g for t in column)
    height = max(level0.shape[0] + 2 * g, right_h)
    width = level0.shape[1] + 2 * g + right_w
    if max(height, width) >= MAX_ATLAS_SIDE_TEXELS:
        raise ValueError(f"marking map too large for the renderer ({width}×{height} texels); "
                         "use a coarser resolution")
    atlas = np.zeros((height, width), np.uint8)
    origins = [(g, g)]
    atlas[g:g + level0.shape[0], g:g + level0.shape[1]] = level0
    x, y = level0.shape[1] + 3 * g, g
    for tex in column:
        atlas[y:y + tex.shape[0], x:x + tex.shape[1]] = tex
        origins.append((x, y))
        y += tex.shape[0] + 2 * g
    return atlas, np.array(origins[:-1], np.float32), origins[-1]


def _level_sizes(shape0: tuple[int, int], min_size: int = 8) -> list[tuple[int, int]]:
    """``(rows, cols)`` of every mip level, as ``_atlas`` makes them."""
    sizes = [shape0]
    while min(sizes[-1]) // 2 >= min_size and len(sizes) < 10:
        sizes.append((sizes[-1][0] // 2, sizes[-1][1] // 2))
    return sizes


def _atlas_layout(shape0: tuple[int, int], wall_shape: tuple[int, int]
                  ) -> tuple[tuple[int, int], list[tuple[int, int]], list[tuple[int, int]],
                             tuple[int, int]]:
    """``_atlas``'s packing without the data: atlas ``(height, width)``, level sizes
    ``(rows, cols)``, level origins ``(x, y)`` and the wall texture's origin."""
    sizes = _level_sizes(shape0)
    g = ATLAS_GUARD
    column = [*sizes[1:], (wall_shape[0], wall_shape[1] + 1)]
    right_w = max(c for _, c in column) + 2 * g
    right_h = sum(r + 2 * g for r, _ in column)
    height = max(shape0[0] + 2 * g, right_h)
    width = shape0[1] + 2 * g + right_w
    if max(height, width) >= MAX_ATLAS_SIDE_TEXELS:
        raise ValueError(f"marking map too large for the renderer ({width}×{height} texels); "
                         "use a coarser resolution")
    origins = [(g, g)]
    x, y = shape0[1] + 3 * g, g
    for r, _ in column:
        origins.append((x, y))
        y += r + 2 * g
    return (height, width), sizes, origins[:-1], origins[-1]


@njit(cache=True)
def _mark_needed(bounds: np.ndarray, affines: np.ndarray, size0_x: float, size0_y: float,
                 sizes: np.ndarray, tile_shift: np.ndarray, grids: np.ndarray,
                 offsets: np.ndarray, filled: np.ndarray, need: np.ndarray,
                 queue: np.ndarray) -> int:
    """Mark in ``need`` the unfilled tiles that bilinear taps of a view may read (see
    ``Scene.prepare``) and list them in ``queue``; returns how many (a list, not a scan
    of ``need``: a map has ~10⁵ tiles and a step needs a few). Conservative: per box, the
    level-0 texel box of its image under every pose (interval arithmetic: each term's
    extremes), clamped like the renderer's maps, then two texels more at its level. Runs
    every frame of a lazy scene, so it reads only scalars (no row views) and divides by
    shifts (tiles of ``1 << tile_shift`` texels)."""
    count = 0
    for n in range(bounds.shape[0]):
        lv = int(bounds[n, 0])
        gx0, gx1, gy0, gy1 = bounds[n, 1], bounds[n, 2], bounds[n, 3], bounds[n, 4]
        x_lo = math.inf
        x_hi = -math.inf
        y_lo = math.inf
        y_hi = -math.inf
        for k in range(affines.shape[0]):
            ax0, ay0 = affines[k, 0] * gx0, affines[k, 3] * gx0
            ax1, ay1 = affines[k, 0] * gx1, affines[k, 3] * gx1
            bx0, by0 = affines[k, 1] * gy0, affines[k, 4] * gy0
            bx1, by1 = affines[k, 1] * gy1, affines[k, 4] * gy1
            x_lo = min(x_lo, min(ax0, ax1) + min(bx0, bx1) + affines[k, 2])
            x_hi = max(x_hi, max(ax0, ax1) + max(bx0, bx1) + affines[k, 2])
            y_lo = min(y_lo, min(ay0, ay1) + min(by0, by1) + affines[k, 5])
            y_hi = max(y_hi, max(ay0, ay1) + max(by0, by1) + affines[k, 5])
        x_lo = min(max(x_lo, -2.0), size0_x + 1.0)
        x_hi = min(max(x_hi, -2.0), size0_x + 1.0)
        y_lo = min(max(y_lo, -2.0), size0_y + 1.0)
        y_hi = min(max(y_hi, -2.0), size0_y + 1.0)
        scale = 0.5**lv
        bias = 0.5 * scale - 0.5
        rows, cols = sizes[lv, 0], sizes[lv, 1]
        c_lo = max(0, int(math.floor(x_lo * scale + bias)) - 2)
        c_hi = min(cols - 1, int(math.floor(x_hi * scale + bias)) + 3)
        r_lo = max(0, int(math.floor(y_lo * scale + bias)) - 2)
        r_hi = min(rows - 1, int(math.floor(y_hi * scale + bias)) + 3)
        sh = tile_shift[lv]
        for tr in range(r_lo >> sh, (r_hi >> sh) + 1):
            row = offsets[lv] + tr * grids[lv, 1]
            for tc in range(c_lo >> sh, (c_hi >> sh) + 1):
                if not filled[row + tc] and not need[row + tc]:
                    need[row + tc] = 1
                    queue[count] = row + tc
                    count += 1
    return count


@njit(cache=True)
def _tile_level(index: int, offsets: np.ndarray) -> int:
    """The mip level of tile ``index`` (levels' tiles are numbered one after the other)."""
    lv = len(offsets) - 1
    while offsets[lv] > index:
        lv -= 1
    return lv


@njit(cache=True)
def _propagate(queue: np.ndarray, n: int, need: np.ndarray, filled: np.ndarray,
               sizes: np.ndarray, tile: np.ndarray, grids: np.ndarray, offsets: np.ndarray
               ) -> int:
    """A needed tile of level L needs the unfilled tiles of level L − 1 under it: add them
    to ``need`` and to the ``n`` tiles listed in ``queue``, then sort the list (by level,
    level 0 first, the order in which they are filled); returns its new length."""
    i = 0
    while i < n:
        index = queue[i]
        i += 1
        lv = _tile_level(index, offsets)
        if lv == 0:
            continue
        tr, tc = divmod(index - offsets[lv], grids[lv, 1])
        t = tile[lv]
        tp = tile[lv - 1]
        r1 = min((tr + 1) * t, sizes[lv, 0])
        c1 = min((tc + 1) * t, sizes[lv, 1])
        for pr in range(2 * tr * t // tp, (2 * r1 - 1) // tp + 1):
            for pc in range(2 * tc * t // tp, (2 * c1 - 1) // tp + 1):
                j = offsets[lv - 1] + pr * grids[lv - 1, 1] + pc
                if not filled[j] and not need[j]:
                    need[j] = 1
                    queue[n] = j
                    n += 1
    queue[:n].sort()
    return n


@njit(cache=True)
def _needed_tiles(bounds: np.ndarray, affines: np.ndarray, size0_x: float, size0_y: float,
                  sizes: np.ndarray, tile_shift: np.ndarray, tile: np.ndarray,
                  grids: np.ndarray, offsets: np.ndarray, filled: np.ndarray,
                  need: np.ndarray, queue: np.ndarray) -> int:
    """``_mark_needed`` and, if a tile is missing, ``_propagate``: one call a frame (a
    call from Python costs µs). Returns how many tiles ``queue`` lists, sorted."""
    n = _mark_needed(bounds, affines, size0_x, size0_y, sizes, tile_shift, grids, offsets,
                     filled, need, queue)
    if n == 0:
        return 0
    return _propagate(queue, n, need, filled, sizes, tile, grids, offsets)


@njit(cache=True)
def _store_level0(atlas: np.ndarray, guard: int, intensity: np.ndarray, wear: np.ndarray,
                  use_wear: bool, queue: np.ndarray, n_level0: int, grid_cols: int, t: int,
                  painted_rows: np.ndarray, nonzero_rows: np.ndarray) -> None:
    """Copy the level-0 tiles listed in ``queue`` (those below ``n_level0``, numbered
    row-major, ``grid_cols`` a row) of the marking map into the atlas, worn as
    ``build_scene`` wears them: ``rint(paint × remaining)`` in float32. Only the rows
    that may hold paint (``painted_rows``, the map's ``nonzero_rows``) are copied: the
    others are zeros in the map and in the atlas alike; ``nonzero_rows`` (the scene's)
    gets the same bits."""
    rows, cols = intensity.shape
    for index in queue:
        if index >= n_level0:
            continue
        tr, tc = divmod(index, grid_cols)
        painted = painted_rows[index]
        nonzero_rows[index] = painted
        for r in range(tr * t, min((tr + 1) * t, rows)):
            if not painted & row_bit(r - tr * t):
                continue
            for c in range(tc * t, min((tc + 1) * t, cols)):
                v = intensity[r, c]
                if use_wear:
                    v = np.uint8(np.rint(np.float32(v) * wear[r, c]))
                atlas[guard + r, guard + c] = v


@njit(cache=True)
def _tile_rows(index: int, offsets: np.ndarray, rows0: np.ndarray, rows: np.ndarray) -> int:
    """The row mask of tile ``index`` (``TiledMarkingMap.nonzero_rows``' bits): from
    ``rows0`` for level 0 (its tiles are numbered first), else from ``rows``."""
    return rows0[index] if index < len(rows0) else rows[index]


@njit(cache=True)
def _mip_tiles(atlas: np.ndarray, origins: np.ndarray, tiles: np.ndarray, sizes: np.ndarray,
               tile: np.ndarray, grids: np.ndarray, offsets: np.ndarray, rows0: np.ndarray,
               rows: np.ndarray) -> None:
    """The listed tiles of levels 1… (``tiles``, sorted: a level after the one below) as
    2×2 box averages of the level below, rounded like OpenCV's INTER_AREA halving:
    ``(a + b + c + d + 2) >> 2``. A row whose two rows below hold only zeros is zero and
    left as it is (the atlas holds zeros there: the row masks ``rows0`` of level 0,
    ``rows`` of the others, which get each tile's bits here; a tile of 1 texel covers
    more than one below, and is marked whole)."""
    for index in tiles:
        lv = _tile_level(index, offsets)
        if lv == 0:
            continue
        tr, tc = divmod(index - offsets[lv], grids[lv, 1])
        t = tile[lv]
        sx, sy = origins[lv - 1, 0], origins[lv - 1, 1]
        dx, dy = origins[lv, 0], origins[lv, 1]
        # The tile below (the same ground) when it has twice the rows; else unknown.
        below = np.int64(-1)
        if tile[lv - 1] == 2 * t:
            below = _tile_rows(offsets[lv - 1] + tr * grids[lv - 1, 1] + tc, offsets, rows0,
                               rows)
        mask = np.int64(0)
        for r in range(tr * t, min((tr + 1) * t, sizes[lv, 0])):
            k = r - tr * t
            if not below & (row_bit(2 * k) | row_bit(2 * k + 1)):
                continue
            mask |= row_bit(k)
            for c in range(tc * t, min((tc + 1) * t, sizes[lv, 1])):
                a = (np.int32(atlas[sy + 2 * r, sx + 2 * c])
                     + np.int32(atlas[sy + 2 * r, sx + 2 * c + 1])
                     + np.int32(atlas[sy + 2 * r + 1, sx + 2 * c])
                     + np.int32(atlas[sy + 2 * r + 1, sx + 2 * c + 1]))
                atlas[dy + r, dx + c] = np.uint8((a + 2) >> 2)
        rows[index] = mask


@njit(cache=True)
def _finish_fill(atlas: np.ndarray, origins: np.ndarray, queue: np.ndarray,
                 sizes: np.ndarray, tile: np.ndarray, grids: np.ndarray, offsets: np.ndarray,
                 filled: np.ndarray, need: np.ndarray, rows0: np.ndarray, rows: np.ndarray
                 ) -> None:
    """The last step of a fill, in one call: ``_mip_tiles`` of the queue's tiles of
    levels 1… (level 0 is painted already), then every listed tile marked filled and no
    longer needed."""
    _mip_tiles(atlas, origins, queue, sizes, tile, grids, offsets, rows0, rows)
    for index in queue:
        filled[index] = 1
        need[index] = 0


@njit(cache=True)
def _fill_tiles(n: int, fill: tuple) -> None:
    """Fill the ``n`` tiles listed first in the queue (sorted, level 0 first: what
    ``_needed_tiles`` lists), with ``fill`` = ``MipTiles.fill_args``, in one call (one
    kernel: a Ctrl-C finds a fill done or not begun): log them for ``retire``
    (``written[:n_written[0]]``, each tile once: only unfilled ones are listed), paint
    level 0 (``_paint_listed``; into the atlas, or copied in worn by ``_store_level0``),
    then ``_finish_fill``."""
    (queue, written, n_written, paint, in_atlas, atlas, guard, intensity, remaining,
     use_wear, n_level0, grid_cols, t0, painted_rows, own_rows, rows0, origins, sizes,
     tile, grids, offsets, filled, need) = fill
    tiles = queue[:n]
    m = n_written[0]
    written[m:m + n] = tiles
    n_written[0] = m + n
    _paint_listed(tiles, *paint)
    if not in_atlas:
        _store_level0(atlas, guard, intensity, remaining, use_wear, tiles, n_level0,
                      grid_cols, t0, painted_rows, own_rows)
    _finish_fill(atlas, origins, tiles, sizes, tile, grids, offsets, filled, need, rows0,
                 own_rows)


@njit(cache=True)
def _zero_tiles(atlas: np.ndarray, origins: np.ndarray, tiles: np.ndarray, sizes: np.ndarray,
                tile: np.ndarray, grids: np.ndarray, offsets: np.ndarray, rows0: np.ndarray,
                rows: np.ndarray) -> None:
    """Zero the listed tiles (of any level) in the atlas: the rows their masks mark
    (``rows0`` for level 0, ``rows`` for the others); the other rows hold zeros."""
    for index in tiles:
        lv = _tile_level(index, offsets)
        tr, tc = divmod(index - offsets[lv], grids[lv, 1])
        t = tile[lv]
        x, y = origins[lv, 0], origins[lv, 1]
        mask = _tile_rows(index, offsets, rows0, rows)
        c0, c1 = x + tc * t, x + min((tc + 1) * t, sizes[lv, 1])
        for r in range(tr * t, min((tr + 1) * t, sizes[lv, 0])):
            if mask & row_bit(r - tr * t):
                atlas[y + r, c0:c1] = 0


_NO_WEAR = np.ones((1, 1), np.float32)
"""``_store_level0``'s wear argument for a scene without wear (not read then)."""

RETIRED_MESSAGE = ("this scene was retired: build_scene(reuse=scene) handed its memory to a "
                   "newer scene; build it again to render it")


class MipTiles:
    """The marking levels of a lazy scene's atlas, filled tile by tile as views need
    them: a tile of level 0 is painted by the marking map, a tile of level L is the box
    average of the tiles of level L − 1 under it. Filled tiles hold exactly the eager
    atlas's texels; the rest of the atlas is untouched zeros (no memory). The wall
    texture is copied in row by row as views read it (the ROIs see no wall: every atlas
    row written costs a page fault).

    ``level0_in_atlas``: the marking map paints straight into the atlas's level 0 (its
    ``intensity`` is a view of it: a scene without wear), so nothing is copied. A later
    scene on the same track shares that map and copies from it."""

    def __init__(self, marking: TiledMarkingMap, atlas: np.ndarray, sizes: list[tuple[int, int]],
                 origins: list[tuple[int, int]], worn: np.ndarray | None,
                 wall: np.ndarray, wall_origin: tuple[int, int], *,
                 level0_in_atlas: bool = False) -> None:
        if level0_in_atlas and worn is not None:
            raise ValueError("worn paint needs its own level 0 (intensity × wear)")
        self.marking = marking
        self.level0_in_atlas = level0_in_atlas
        self.atlas = atlas
        self.wall = wall
        self.wall_origin = wall_origin
        self.wall_filled = np.zeros(wall.shape[0], bool)
        self._worn = worn  # coarse worn share (``_wear_noise``); resized on first use
        self._remaining: np.ndarray | None = None
        t0 = marking.tile_px
        if t0 & (t0 - 1):
            raise ValueError(f"a lazy scene needs tiles of 2^k px, got {t0}")
        self.sizes = np.array(sizes, np.int64)
        self.origins = np.array(origins, np.int64)
        self.tile = np.array([max(1, t0 >> lv) for lv in range(len(sizes))], np.int64)
        self.tile_shift = np.array([int(t).bit_length() - 1 for t in self.tile], np.int64)
        self.grids = -(-self.sizes // self.tile[:, None])
        counts = self.grids[:, 0] * self.grids[:, 1]
        self.offsets = np.concatenate(([0], np.cumsum(counts)[:-1])).astype(np.int64)
        self._level0_tiles = int(counts[0])
        self.filled = np.zeros(int(counts.sum()), np.uint8)
        self.need = np.zeros_like(self.filled)
        # Per tile a bit per texel row that may be non-zero (``row_bit``); the rest of a
        # tile is zeros, neither read for the levels above nor cleared by ``retire``.
        # Level 0 painted in the atlas: the marking map's (``_level0_rows``).
        self.nonzero_rows = np.zeros(len(self.filled), np.int64)
        self._queue = np.empty(len(self.filled), np.int64)  # scratch: the tiles to fill
        self._need_args = self._needed_tiles_args()
        # The tiles written to the atlas, fill by fill: ``_written[:_n_written[0]]``,
        # appended to by the fill kernel (each tile once: a fill lists unfilled tiles and
        # fills them all), so it also counts the filled tiles.
        self._written = np.empty(len(self.filled), np.int64)
        self._n_written = np.zeros(1, np.int64)
        # More tiles ``retire`` zeroes: logged by a fill that raised before it filled
        # them (``_after_error``), or listed by an old pickle's fills.
        self._retire_extra = np.zeros(0, np.int64)
        self._fill_args: tuple | None = None  # ``fill_args``, made on first use
        self._walls_complete = False
        self.retired = False

    def _needed_tiles_args(self) -> tuple:
        """``_needed_tiles``' arguments after the view's (the same arrays every frame,
        gathered once: µs a frame)."""
        rows, cols = self.marking.shape
        return (float(cols), float(rows), self.sizes, self.tile_shift, self.tile, self.grids,
                self.offsets, self.filled, self.need, self._queue)

    @property
    def n_filled(self) -> int:
        """How many tiles are filled."""
        return int(self._n_written[0])

    @property
    def complete(self) -> bool:
        """Everything filled, walls too: nothing left to check (False once retired)."""
        return self._walls_complete and self._n_written[0] == len(self.filled)

    def __getstate__(self) -> dict[str, object]:
        state = self.__dict__.copy()
        del state["_queue"]  # scratch (≈ 1 MB of garbage): a copy makes its own
        del state["_need_args"]  # views of the state's arrays: a copy makes its own
        state["_fill_args"] = None  # the same
        state["_written"] = self._written[:self._n_written[0]].copy()  # not its spare room
        state["_n_written"] = self._n_written.copy()  # a shallow copy's own count
        return state

    def __setstate__(self, state: dict[str, object]) -> None:
        # A copy (pickle, deepcopy) holds the painted level 0 twice, in the atlas and in
        # the marking map's own copy of it: point the map back at the atlas, or tiles it
        # paints later would never reach the atlas.
        self.__dict__.update(state)
        self._queue = np.empty(len(self.filled), np.int64)
        self._level0_tiles = int(self.grids[0, 0] * self.grids[0, 1])  # pickled before it
        if "nonzero_rows" not in state:  # pickled before the row masks: every row may
            self.nonzero_rows = np.full(len(self.filled), -1, np.int64)  # be non-zero
        if "_written" not in state:  # pickled before the fill log
            self._log_from_before(state)
        elif len(self._written) < len(self.filled):  # pickled without its spare room
            written = np.empty(len(self.filled), np.int64)
            written[:len(self._written)] = self._written
            self._written = written
        self._fill_args = None
        if self.level0_in_atlas:
            g, (rows, cols) = ATLAS_GUARD, self.marking.shape
            self.marking.intensity = self.atlas[g:g + rows, g:g + cols]
        self._need_args = self._needed_tiles_args()

    def _log_from_before(self, state: dict[str, object]) -> None:
        """The fill log of a scene pickled with a list of fills (``_written_runs``, which
        may list a tile twice, or one an interrupted fill listed and left unfilled), or
        before that with none: the filled tiles (the log counts them); the others listed
        kept apart for ``retire`` to zero too."""
        for name in ("n_filled", "complete", "_tiles_complete"):
            self.__dict__.pop(name, None)
        runs = self.__dict__.pop("_written_runs", None)
        filled = np.flatnonzero(self.filled)
        listed = np.unique(np.concatenate(runs)) if runs else np.zeros(0, np.int64)
        extra = np.setdiff1d(listed, filled)
        self._written = np.empty(len(self.filled), np.int64)
        self._written[:len(filled)] = filled
        self._n_written = np.array([len(filled)], np.int64)
        self._retire_extra = extra.astype(np.int64)  # unfilled, written maybe
        # A scene retired before kept its fill marks: never complete (it must not render).
        self._walls_complete = bool(self.wall_filled.all()) and not state.get("retired")
        if "retired" not in state:
            self.retired = False

    def _level0_rows(self) -> np.ndarray:
        """The row masks of level 0: the marking map's if it paints into the atlas (it
        marks what it paints there, for other scenes too), else this scene's own."""
        if self.level0_in_atlas:
            return self.marking.nonzero_rows
        return self.nonzero_rows[:self._level0_tiles]

    def retire(self) -> mmap.mmap | None:
        """Hand this scene's memory over to a new scene (``build_scene(reuse=…)``): zero
        everything written to the atlas and return its memory, all zeros again (None if
        it is not an ``untouched_zeros`` atlas: a copy from a pickle). The scene can no
        longer render (a clear error). A marking map painting into this atlas starts
        again on fresh memory, so scenes sharing it stay right."""
        if self.retired:
            return None
        self.retired = True
        self._walls_complete = False  # not complete: the renderer asks ``ensure``: raises
        memory = memory_of(self.atlas)
        if memory is None:
            return None
        # Lists, not scans of ``filled`` (~10⁵ tiles): each fill's tiles; level 0 also
        # holds what a map painting into it painted for other scenes. One call: a kernel
        # call from Python costs µs, and a scene has had ~30 fills.
        runs = [self._written[:self._n_written[0]], self._retire_extra]
        rows0 = self._level0_rows()
        if self.level0_in_atlas:
            # The map leaves this memory before it is cleared (its list and row marks
            # taken first): a Ctrl-C past this point leaves no map that counts as painted
            # what is cleared below, for a scene sharing it or the next on this track.
            runs = [*runs, self.marking.painted_tiles()]
            rows0 = rows0.copy()
            if _last_marking and _last_marking[0] is self.marking:
                _last_marking.clear()
            self.marking.detach()
        _zero_tiles(self.atlas, self.origins, np.concatenate(runs), self.sizes,
                    self.tile, self.grids, self.offsets, rows0, self.nonzero_rows)
        (wx, wy), width = self.wall_origin, self.wall.shape[1] + 1  # + the wrap column
        for r in np.flatnonzero(self.wall_filled):
            self.atlas[wy + r, wx:wx + width] = 0
        return memory

    def _check_live(self) -> None:
        if self.retired:
            raise RuntimeError(RETIRED_MESSAGE)

    def ensure(self, bounds: np.ndarray, affines: np.ndarray) -> None:
        """Fill what a view reads (``Scene.prepare``)."""
        self._check_live()
        start = int(self._n_written[0])
        try:
            n = _needed_tiles(bounds, affines, *self._need_args)
            if n:
                self._fill(n)
        except BaseException:
            self._after_error(start)
            raise

    @property
    def need_args(self) -> tuple:
        """``_needed_tiles``' arguments after the view's, for a kernel that checks a view
        itself (``Renderer``'s ``_render_lazy``, run by ``run_view``)."""
        self._check_live()
        return self._need_args

    @property
    def fill_args(self) -> tuple:
        """``_fill_tiles``' arguments after the count, for a kernel that fills tiles
        itself (``Renderer``'s ``_fill_render``, run by ``run_view``): the same tuple while
        the marking map's memory stays (its ``paint_args``)."""
        self._check_live()
        paint = self.marking.paint_args
        if self._fill_args is None or self._fill_args[3] is not paint:
            self._fill_args = self._make_fill_args(paint)
        return self._fill_args

    def _make_fill_args(self, paint: tuple) -> tuple:
        use_wear = self._worn is not None
        if use_wear and self._remaining is None:
            self._remaining = _wear_remaining(self._worn, self.marking.shape)
        remaining = self._remaining if use_wear else _NO_WEAR
        # The marking map's intensity: ``paint``'s own (the array it paints into).
        intensity = paint[4]
        return (self._queue, self._written, self._n_written, paint, self.level0_in_atlas,
                self.atlas, ATLAS_GUARD, intensity, remaining, use_wear, self._level0_tiles,
                int(self.grids[0, 1]), int(self.tile[0]), self.marking.nonzero_rows,
                self.nonzero_rows, self._level0_rows(), self.origins, self.sizes, self.tile,
                self.grids, self.offsets, self.filled, self.need)

    def run_view(self, check: Callable[..., int], check_args: tuple,
                 fill_then: Callable[..., int], then_args: tuple) -> int:
        """``check(*check_args)``, a kernel that lists the tiles a view still needs with
        ``_needed_tiles`` (its ``need_args``) and returns how many, n, before it reads
        any (else it goes on, and returns 0, or −1 for walls to copy in first); if n > 0,
        ``fill_then(n, fill_args, *then_args)``, a kernel that fills them with
        ``_fill_tiles`` and goes on. Returns n."""
        start = int(self._n_written[0])
        try:
            n = check(*check_args)
            if n > 0:
                fill_then(n, self.fill_args, *then_args)
        except BaseException:
            self._after_error(start)
            raise
        return n

    def _after_error(self, start: int) -> None:
        """Make the books right after an exception in a view's check or fill (the log was
        ``start`` tiles long before it). Nothing may stay listed in ``need`` (those tiles
        would never be listed again). A Ctrl-C lands between kernels, where a fill is done
        or not begun; an error raised inside the fill kernel (a MemoryError) may leave
        tiles it logged (and maybe wrote) unfilled: those go to the tiles ``retire`` zeroes
        besides the log, which keeps only filled tiles (its length is the filled count,
        and its room one entry a tile)."""
        self.need[:] = 0
        end = int(self._n_written[0])
        if end == start:
            return
        logged = self._written[start:end].copy()
        done = self.filled[logged] != 0
        self._retire_extra = np.concatenate((self._retire_extra, logged[~done]))
        self._written[start:start + int(done.sum())] = logged[done]
        self._n_written[0] = start + int(done.sum())

    def ensure_walls(self, lo: float, hi: float) -> None:
        """Copy in the wall texture rows that bilinear taps of rows ``lo … hi`` [texels]
        read (a row more on each side for rounding)."""
        self._check_live()
        if not lo <= hi:
            return
        rows = self.wall.shape[0]
        lo, hi = max(lo, -1.0), min(hi, float(rows))  # infinite bounds: every row
        r0 = min(max(int(math.floor(lo)) - 1, 0), rows)
        r1 = min(max(int(math.floor(hi)) + 3, 0), rows)
        if self.wall_filled[r0:r1].all():
            return
        wall, (wx, wy) = self.wall, self.wall_origin
        self.atlas[wy + r0:wy + r1, wx:wx + wall.shape[1]] = wall[r0:r1]
        self.atlas[wy + r0:wy + r1, wx + wall.shape[1]] = wall[r0:r1, 0]  # wraps (_atlas)
        self.wall_filled[r0:r1] = True
        self._walls_complete = bool(self.wall_filled.all())

    def fill_all(self) -> None:
        self._check_live()
        todo = np.flatnonzero(self.filled == 0)
        start = int(self._n_written[0])
        try:
            self.need[todo] = 1
            self._queue[:len(todo)] = todo
            if len(todo):
                self._fill(_propagate(self._queue, len(todo), self.need, self.filled,
                                      self.sizes, self.tile, self.grids, self.offsets))
        except BaseException:
            self._after_error(start)  # as in ``ensure``
            raise
        self.ensure_walls(0.0, float(self.wall.shape[0]))

    def _fill(self, n: int) -> None:
        """Fill the ``n`` tiles listed in the queue (marked in ``need``; with those under
        them, sorted: ``_propagate``): one kernel call (``_fill_tiles``)."""
        _fill_tiles(n, self.fill_args)


def _blobs(rng: np.random.Generator, shape: tuple[int, int], count: int,
           radius_px: tuple[float, float]) -> np.ndarray:
    """Sum of ``count`` soft elliptical blobs (peak 1) at random places."""
    out = np.zeros(shape, np.float32)
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float32)
    for _ in range(count):
        cy, cx = rng.uniform(0, shape[0]), rng.uniform(0, shape[1])
        ry, rx = rng.uniform(*radius_px, 2)
        angle = rng.uniform(0, math.pi)
        dy, dx = yy - cy, xx - cx
        c, s = math.cos(angle), math.sin(angle)
        u, v = (c * dx + s * dy) / rx, (-s * dx + c * dy) / ry
        out += np.exp(-(u * u + v * v)).astype(np.float32)
    return np.minimum(out, 1.0)


def _wear(rng: np.random.Generator, shape: tuple[int, int], amount: float) -> np.ndarray:
    """Paint remaining [0, 1] per texel: smooth patches where up to ``amount`` is worn."""
    return _wear_remaining(_wear_noise(rng, shape, amount), shape)


def _wear_noise(rng: np.random.Generator, shape: tuple[int, int], amount: float) -> np.ndarray:
    """``_wear``'s random part: the worn share on a coarse grid (the draws)."""
    coarse = (max(2, shape[0] // 25), max(2, shape[1] // 25))  # ~10 cm patches at 4 mm
    noise = cv2.GaussianBlur(rng.random(coarse).astype(np.float32), (0, 0), 1.5)
    noise = (noise - noise.min()) / max(1e-6, float(noise.max() - noise.min()))
    return amount * np.clip(2.0 * noise - 0.5, 0.0, 1.0)


def _wear_remaining(worn: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """``_wear``'s per-texel part: the coarse worn share resized to the map, subtracted
    from 1 (float32)."""
    return 1.0 - cv2.resize(worn, (shape[1], shape[0]), interpolation=cv2.INTER_LINEAR)


def _wall_texture(rng: np.random.Generator, hall: Hall) -> np.ndarray:
    """Procedural walls around the cylinder: plaster, skirting board, doors, radiators,
    windows; a brighter ceiling above the walls (up to 3× the wall height)."""
    perimeter_m = 2.0 * math.pi * hall.distance_m
    cols = max(8, int(math.ceil(perimeter_m / WALL_TEXEL_M)))
    rows = max(8, int(math.ceil(3.0 * hall.height_m / WALL_TEXEL_M)))
    tex = np.full((rows, cols), 128, np.float32)
    tex += rng.normal(0.0, 4.0, (rows, cols)).astype(np.float32)
    col_m = np.arange(cols) * WALL_TEXEL_M
    row_m = np.arange(rows) * WALL_TEXEL_M
    for _ in range(int(perimeter_m / 2.5)):
        kind = int(rng.integers(3))
        x0 = rng.uniform(0, perimeter_m)
        width = (0.9, 1.4, 1.8)[kind] * rng.uniform(0.8, 1.2)
        z0, z1, tone = ((0.0, 2.0, 85.0), (0.25, 0.85, 165.0), (1.0, 2.2, 215.0))[kind]
        in_x = (col_m >= x0) & (col_m <= x0 + width)
        in_z = (row_m >= z0) & (row_m <= min(z1, hall.height_m))
        tex[np.ix_(in_z, in_x)] = tone + rng.normal(0.0, 3.0)
        if kind == 1:  # radiator fins
            fins = in_x & ((col_m * 25).astype(int) % 2 == 0)
            tex[np.ix_(in_z, fins)] -= 35
    tex[row_m < 0.10, :] = 45.0  # skirting board
    tex[row_m >= hall.height_m, :] = 160.0  # ceiling
    tex = cv2.GaussianBlur(tex, (0, 0), 0.8)
    return np.clip(tex, 0, 255).astype(np.uint8)


WALL_CACHE_SIZE: int = 4
"""Wall textures kept for reuse (keyed by the hall and the generator's state)."""

_wall_cache: dict[tuple, tuple[np.ndarray, dict]] = {}
_last_marking: list[TiledMarkingMap] = []  # the last track's map: one entry at most


def _cached_wall_texture(rng: np.random.Generator, hall: Hall) -> np.ndarray:
    """``_wall_texture``, reused when the same hall is drawn from the same generator
    state (every scene without randomisation: ``default_rng(0)``); the generator ends in
    the state the drawing leaves it in, so later draws do not change."""
    state = rng.bit_generator.state
    if state.get("bit_generator") != "PCG64":
        return _wall_texture(rng, hall)
    key = (hall, state["state"]["state"], state["state"]["inc"], state["has_uint32"],
           state["uinteger"])
    hit = _wall_cache.get(key)
    if hit is None:
        tex = _wall_texture(rng, hall)
        tex.flags.writeable = False  # shared by scenes
        if len(_wall_cache) >= WALL_CACHE_SIZE:
            _wall_cache.pop(next(iter(_wall_cache)))
        hit = _wall_cache[key] = (tex, rng.bit_generator.state)
    else:
        rng.bit_generator.state = hit[1]
    return hit[0]


def _marking_for(track: Track) -> TiledMarkingMap | None:
    """The lazily painted marking map of the last scene built on an equal track (a new
    appearance on the same track repaints nothing), or None."""
    if _last_marking and (_last_marking[0].track is track or _last_marking[0].track == track):
        return _last_marking[0]
    return None


def build_scene(track: Track, effects: Effects | None = None,
                rng: np.random.Generator | None = None, hall: Hall | None = None,
                marking_map: MarkingMap | None = None, *, lazy: bool = True,
                reuse: Scene | None = None) -> Scene:
    """Prepare ``track`` for rendering; random layout (shadows, glare, wear, walls) from
    ``rng``. Pass a cached ``marking_map`` to skip rasterising the track again.

    ``lazy`` (without a ``marking_map``): the markings are painted tile by tile as the
    renderer looks at them (``Scene.prepare``), so a scene costs little until it is seen;
    the frames are those of the eager scene (``lazy=False``) bit for bit.

    ``reuse``: the scene this one replaces, if the caller is done with it. A lazy scene of
    another track is retired (``MipTiles.retire``: it can no longer render) and the new
    lazy scene takes over its atlas memory: its pages were written once already, and a
    fresh page costs a page fault (≈ 1.5–2 µs here, ~0.9 ms of a reset onto a new track).
    Otherwise ``reuse`` is left as it is. The frames are the same either way."""
    if reuse is not None and not isinstance(reuse, Scene):
        raise TypeError(f"reuse must be a Scene or None, got {type(reuse).__name__}")
    fx = effects or Effects()
    rng = rng if rng is not None else np.random.default_rng(0)
    hall = hall or Hall()
    tiles = None
    if lazy and marking_map is None:
        marking = _marking_for(track)
        if marking is None:
            origin_m, shape = map_geometry(track)
            resolution_m = DEFAULT_RESOLUTION_M
        else:
            shape, resolution_m, origin_m = marking.shape, marking.resolution_m, marking.origin_m
        worn = _wear_noise(rng, shape, fx.wear) if fx.wear > 0 else None
        wall = _cached_wall_texture(rng, hall)
        (height, width), sizes, level_xy, wall_origin = _atlas_layout(shape, wall.shape)
        memory = None  # retired only now: every check that can refuse the track is done
        if (reuse is not None and reuse.tiles is not None
                and not (reuse.track is track or reuse.track == track)):
            memory = reuse.tiles.retire()
        # Unfilled tiles and walls cost nothing; retired memory is all zeros again.
        atlas = untouched_zeros((height, width), memory, reserve_bytes=ATLAS_RESERVE_BYTES)
        origins = np.array(level_xy, np.float32)
        in_atlas = False
        if marking is None:
            # Without wear level 0 is the paint itself: painted straight into the atlas.
            in_atlas = worn is None
            g = ATLAS_GUARD
            marking = TiledMarkingMap(
                track, labels=False,  # a scene reads only the intensity
                intensity=atlas[g:g + shape[0], g:g + shape[1]] if in_atlas else None)
            _last_marking[:] = [marking]
        tiles = MipTiles(marking, atlas, sizes, level_xy, worn, wall, wall_origin,
                         level0_in_atlas=in_atlas)
    else:
        m = marking_map if marking_map is not None else rasterize(track)
        shape, resolution_m, origin_m = m.shape, m.resolution_m, m.origin_m
        level0 = m.intensity
        if fx.wear > 0:
            level0 = np.rint(level0 * _wear(rng, level0.shape, fx.wear)).astype(np.uint8)
        wall = _cached_wall_texture(rng, hall)
        atlas, origins, wall_origin = _atlas(level0, wall)
    light = None
    if fx.shadows > 0 or fx.glare_spots > 0:
        rows = max(1, int(math.ceil(shape[0] * resolution_m / LIGHT_RES_M)))
        cols = max(1, int(math.ceil(shape[1] * resolution_m / LIGHT_RES_M)))
        light = np.zeros((rows, cols, 2), np.uint8)
        shadow = 1.0 - fx.shadow_depth * _blobs(rng, (rows, cols), fx.shadows, (6.0, 25.0))
        glare = fx.glare_spot_dn * _blobs(rng, (rows, cols), fx.glare_spots, (3.0, 10.0))
        light[..., 0] = np.clip(np.rint(255.0 * shadow), 0, 255)
        light[..., 1] = np.clip(np.rint(glare), 0, 255)
    boxes = np.zeros((len(track.obstacles), 8, 3))
    for k, ob in enumerate(track.obstacles):
        boxes[k, :4, :2] = boxes[k, 4:, :2] = obstacle_corners(track, k)
        boxes[k, 4:, 2] = ob.height_m
    return Scene(
        track=track, effects=fx, hall=hall, atlas=atlas, level_origin=origins,
        level0_size=(shape[1], shape[0]), resolution_m=resolution_m,
        origin=origin_m, light=light, wall_origin=wall_origin,
        wall_size=(wall.shape[1], wall.shape[0]), boxes=boxes, tiles=tiles,
    )
