"""What the camera can see, prepared once per track (and per appearance draw).

A ``Scene`` holds the track's marking map as a mip pyramid (for footprint-correct
anti-aliasing), a coarse light map on the mat (shadows, glare spots, worn paint), the
hall's walls as a texture along their perimeter, and the obstacle boxes. Everything
random (where shadows and glare fall, which paint is worn, what hangs on the walls)
is drawn from the ``numpy.random.Generator`` passed in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from tracks import MarkingMap, Track, rasterize
from tracks.rules import obstacle_corners

from .effects import Effects

LIGHT_RES_M: float = 0.05
"""Resolution of the light map (shadows, glare spots, wear) [m/px]."""

WALL_TEXEL_M: float = 0.02
"""Resolution of the wall texture [m/texel]."""


@dataclass(frozen=True)
class Hall:
    """The room around the mat: walls ``margin_m`` beyond the mat's edge, ``height_m`` high."""

    margin_m: float = 1.5
    height_m: float = 2.6


@dataclass(frozen=True)
class Scene:
    """Render-ready data of one track. Build with ``build_scene``."""

    track: Track
    effects: Effects
    pyramid: np.ndarray  # all mip levels, flattened, uint8
    level_offset: np.ndarray  # (L,) start of each level in ``pyramid``
    level_shape: np.ndarray  # (L, 2) rows, cols
    level_res: np.ndarray  # (L,) metres per texel
    origin: tuple[float, float]  # world (x, y) of the maps' top-left corner [m]
    light: np.ndarray  # (h, w, 3) float32: shadow gain, glare add [DN], wear [-]
    hall: tuple[float, float, float, float]  # wall rectangle xmin, ymin, xmax, ymax [m]
    wall_height_m: float
    wall_texture: np.ndarray  # (rows, cols) uint8, along the perimeter, bottom row first
    boxes: np.ndarray  # (n, 8, 3) obstacle corners [m]: 4 on the ground, 4 on top


def _pyramid(m: MarkingMap, min_size: int = 8) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                        np.ndarray]:
    """Mip levels by 2×2 box averaging; level 0 is padded so every level halves exactly."""
    base = m.intensity
    levels_n = 1
    while min(base.shape) >> levels_n >= min_size and levels_n < 10:
        levels_n += 1
    step = 1 << (levels_n - 1)
    rows = -(-base.shape[0] // step) * step
    cols = -(-base.shape[1] // step) * step
    level = np.zeros((rows, cols), np.uint8)
    level[: base.shape[0], : base.shape[1]] = base
    levels = [level]
    for _ in range(levels_n - 1):
        level = cv2.resize(level, (level.shape[1] // 2, level.shape[0] // 2),
                           interpolation=cv2.INTER_AREA)
        levels.append(level)
    offsets = np.cumsum([0] + [lv.size for lv in levels[:-1]]).astype(np.int64)
    shapes = np.array([lv.shape for lv in levels], dtype=np.int64)
    res = m.resolution_m * (1 << np.arange(levels_n)).astype(np.float64)
    return np.concatenate([lv.ravel() for lv in levels]), offsets, shapes, res


def _blobs(rng: np.random.Generator, shape: tuple[int, int], count: int,
           radius_px: tuple[float, float]) -> np.ndarray:
    """Sum of ``count`` soft elliptical blobs (peak 1) at random places."""
    out = np.zeros(shape, np.float32)
    for _ in range(count):
        cy, cx = rng.uniform(0, shape[0]), rng.uniform(0, shape[1])
        ry, rx = rng.uniform(*radius_px, 2)
        angle = rng.uniform(0, math.pi)
        yy, xx = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float32)
        dy, dx = yy - cy, xx - cx
        c, s = math.cos(angle), math.sin(angle)
        u, v = (c * dx + s * dy) / rx, (-s * dx + c * dy) / ry
        out += np.exp(-(u * u + v * v)).astype(np.float32)
    return np.minimum(out, 1.0)


def _light_map(rng: np.random.Generator, shape: tuple[int, int], fx: Effects) -> np.ndarray:
    light = np.zeros((*shape, 3), np.float32)
    light[..., 0] = 1.0 - fx.shadow_depth * _blobs(rng, shape, fx.shadows, (6.0, 25.0))
    light[..., 1] = fx.glare_spot_dn * _blobs(rng, shape, fx.glare_spots, (3.0, 10.0))
    # Worn paint: smooth noise, so whole stretches of a line fade together.
    noise = rng.random(shape).astype(np.float32)
    noise = cv2.GaussianBlur(noise, (0, 0), 3.0)
    noise = (noise - noise.min()) / max(1e-6, float(noise.max() - noise.min()))
    light[..., 2] = fx.wear * np.clip(2.0 * noise - 0.5, 0.0, 1.0)
    return light


def _wall_texture(rng: np.random.Generator, perimeter_m: float, height_m: float) -> np.ndarray:
    """Procedural hall walls: plaster, a dark skirting board, doors, radiators, windows."""
    cols = max(8, int(math.ceil(perimeter_m / WALL_TEXEL_M)))
    rows = max(8, int(math.ceil(height_m / WALL_TEXEL_M)))
    tex = np.full((rows, cols), 128, np.float32)
    tex += rng.normal(0.0, 4.0, (rows, cols)).astype(np.float32)
    col_m = np.arange(cols) * WALL_TEXEL_M
    row_m = np.arange(rows) * WALL_TEXEL_M
    for _ in range(int(perimeter_m / 3.0)):
        kind = rng.integers(3)
        x0 = rng.uniform(0, perimeter_m)
        width = {0: 0.9, 1: 1.4, 2: 1.8}[int(kind)] * rng.uniform(0.8, 1.2)
        z0, z1, tone = {0: (0.0, 2.0, 85.0), 1: (0.25, 0.85, 165.0), 2: (1.0, 2.2, 215.0)}[
            int(kind)]
        in_x = (col_m >= x0) & (col_m <= x0 + width)
        in_z = (row_m >= z0) & (row_m <= z1)
        tex[np.ix_(in_z, in_x)] = tone + rng.normal(0.0, 3.0)
        if kind == 1:  # radiator fins
            fins = in_x & ((col_m * 25).astype(int) % 2 == 0)
            tex[np.ix_(in_z, fins)] -= 35
    tex[row_m < 0.10, :] = 45.0  # skirting board
    tex = cv2.GaussianBlur(tex, (0, 0), 0.8)
    return np.clip(tex, 0, 255).astype(np.uint8)


def build_scene(track: Track, effects: Effects | None = None,
                rng: np.random.Generator | None = None, hall: Hall | None = None,
                marking_map: MarkingMap | None = None) -> Scene:
    """Prepare ``track`` for rendering. Pass a cached ``marking_map`` to skip rasterising."""
    fx = effects or Effects()
    rng = rng if rng is not None else np.random.default_rng(0)
    hall = hall or Hall()
    m = marking_map if marking_map is not None else rasterize(track)
    pyramid, offsets, shapes, res = _pyramid(m)
    extent = (shapes[0][0] * res[0], shapes[0][1] * res[0])  # rows, cols in metres
    light_shape = (max(1, int(math.ceil(extent[0] / LIGHT_RES_M))),
                   max(1, int(math.ceil(extent[1] / LIGHT_RES_M))))
    ox, oy = m.origin_m
    walls = (ox - hall.margin_m, oy - extent[0] - hall.margin_m,
             ox + extent[1] + hall.margin_m, oy + hall.margin_m)
    perimeter = 2.0 * ((walls[2] - walls[0]) + (walls[3] - walls[1]))
    boxes = np.zeros((len(track.obstacles), 8, 3))
    for k, ob in enumerate(track.obstacles):
        ground = obstacle_corners(track, k)
        boxes[k, :4, :2] = ground
        boxes[k, 4:, :2] = ground
        boxes[k, 4:, 2] = ob.height_m
    return Scene(
        track=track, effects=fx, pyramid=pyramid, level_offset=offsets, level_shape=shapes,
        level_res=res, origin=(ox, oy), light=_light_map(rng, light_shape, fx),
        hall=walls, wall_height_m=hall.height_m,
        wall_texture=_wall_texture(rng, perimeter, hall.height_m), boxes=boxes,
    )
