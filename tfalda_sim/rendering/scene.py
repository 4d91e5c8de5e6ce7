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

from tfalda_sim.tracks import MarkingMap, Track, rasterize
from tfalda_sim.tracks.rules import obstacle_corners

from .effects import Effects

LIGHT_RES_M: float = 0.05
"""Resolution of the light map (shadows, glare spots) [m/px]."""

WALL_TEXEL_M: float = 0.02
"""Resolution of the wall texture [m/texel]."""

ATLAS_GUARD: int = 4
"""Zero texels around every mip level in the atlas, so bilinear taps never bleed."""

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

    @property
    def levels(self) -> int:
        return len(self.level_origin)


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
    coarse = (max(2, shape[0] // 25), max(2, shape[1] // 25))  # ~10 cm patches at 4 mm
    noise = cv2.GaussianBlur(rng.random(coarse).astype(np.float32), (0, 0), 1.5)
    noise = (noise - noise.min()) / max(1e-6, float(noise.max() - noise.min()))
    worn = amount * np.clip(2.0 * noise - 0.5, 0.0, 1.0)
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


def build_scene(track: Track, effects: Effects | None = None,
                rng: np.random.Generator | None = None, hall: Hall | None = None,
                marking_map: MarkingMap | None = None) -> Scene:
    """Prepare ``track`` for rendering; random layout (shadows, glare, wear, walls) from
    ``rng``. Pass a cached ``marking_map`` to skip rasterising the track again."""
    fx = effects or Effects()
    rng = rng if rng is not None else np.random.default_rng(0)
    hall = hall or Hall()
    m = marking_map if marking_map is not None else rasterize(track)
    level0 = m.intensity
    if fx.wear > 0:
        level0 = np.rint(level0 * _wear(rng, level0.shape, fx.wear)).astype(np.uint8)
    wall = _wall_texture(rng, hall)
    atlas, origins, wall_origin = _atlas(level0, wall)
    light = None
    if fx.shadows > 0 or fx.glare_spots > 0:
        rows = max(1, int(math.ceil(level0.shape[0] * m.resolution_m / LIGHT_RES_M)))
        cols = max(1, int(math.ceil(level0.shape[1] * m.resolution_m / LIGHT_RES_M)))
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
        level0_size=(level0.shape[1], level0.shape[0]), resolution_m=m.resolution_m,
        origin=m.origin_m, light=light, wall_origin=wall_origin,
        wall_size=(wall.shape[1], wall.shape[0]), boxes=boxes,
    )
