"""The camera image: per-pixel inverse mapping onto the ground, footprint-filtered.

The ground is flat and the camera rigid on the car, so every pixel's ray, its ground hit
in the car frame, its footprint on the ground and therefore its mip level are constants,
computed once (``PixelGeometry``). Per frame and pixel:

1. *maps* (numba, vectorised): the ground hit moved to the world by the car pose and
   turned into a texel coordinate of the pixel's own mip level inside the mip atlas
   (walls: a column of the wall texture, shifted by the car's yaw);
2. *sampling* (numba): bilinear samples of the atlas, the arithmetic bit for bit that of
   OpenCV's ``cv2.remap``, which did this before; far dashes are pre-filtered, so they
   fade instead of shimmering or vanishing;
3. *combine* (numba, vectorised): floor sheen, shadows and glare, the bonnet with its
   faint reflection, obstacles, exposure × vignetting, sensor noise, 8-bit rounding.

Every step depends only on the pixel and the frame (the noise is read from a fixed bank
at a per-frame offset), so any window rendered alone equals the same crop of the full
frame bit for bit — perception renders only its ROIs.
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

import cv2
import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from ..camera import Camera, FisheyeCamera
from ..kernels import LITTLE_ENDIAN, load_pair
from .effects import Effects
from .obstacles import BoxFaces, draw_faces, visible_faces
from .pixels import Bonnet, pixel_geometry
from .scene import LIGHT_RES_M, WALL_TEXEL_M, Scene, _fill_tiles, _needed_tiles

_T = TypeVar("_T")

MOTION_BLUR_SAMPLES: int = 5
"""Sub-frame poses averaged for motion blur."""

CEILING_FACTOR: float = 1.25
"""Ceiling brightness relative to ``Effects.wall_dn`` [-]."""

NOISE_BANK_SIZE: int = 1 << 21
"""Entries of the fixed table of standard-normal sensor noise (int8, 1/16 σ steps)."""

_NOISE_SCALE = 1.0 / 16.0


_PAD = -8.0
"""Map coordinate for padding pixels: outside the atlas (reads 0)."""

_pixel_layout_ids = itertools.count()
"""Serial numbers of pixel layouts (``_PixelLayout.uid``): cheap keys of window packings."""


@njit(cache=True)
def _texel_transform(affine: np.ndarray, size_x: float, size_y: float) -> tuple:
    """``affine``'s six entries as float32, then the clamp range of level-0 texel
    coordinates: a zero guard band of 2 texels below and 1 above the level's size."""
    f = np.float32
    return (f(affine[0]), f(affine[1]), f(affine[2]), f(affine[3]), f(affine[4]),
            f(affine[5]), f(-2.0), f(size_x + 1.0), f(size_y + 1.0))


@intrinsic
def _fma32(typingctx, a, b, c):  # type: ignore[no-untyped-def]  # numba's signature
    """``a · b + c`` rounded once (float32): what OpenCV's SIMD remap computes."""
    if not all(t == types.float32 for t in (a, b, c)):
        return None

    def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
        f32 = ir.FloatType()
        fma = cgutils.get_or_insert_function(builder.module, ir.FunctionType(f32, [f32] * 3),
                                             "llvm.fma.f32")
        return builder.call(fma, args)

    return types.float32(types.float32, types.float32, types.float32), codegen


@njit(cache=True, error_model="numpy")
def _taps_at_border(flat: np.ndarray, h: int, w: int, ix: int, iy: int) -> tuple[int, int]:
    """``load_pair`` of rows ``iy`` and ``iy + 1`` at column ``ix`` for a sample that is
    not inside the atlas: taps outside read 0."""
    shift = 8 if LITTLE_ENDIAN else 0  # of the right tap: its byte comes second
    a = 0
    b = 0
    for dy in range(2):
        y = iy + dy
        for dx in range(2):
            x = ix + dx
            if 0 <= x < w and 0 <= y < h:
                v = np.int64(flat[y * w + x]) << (shift if dx else 8 - shift)
                if dy == 0:
                    a |= v
                else:
                    b |= v
    return a, b


@njit(cache=True, error_model="numpy", inline="always")  # called per row piece
def _bilinear(out: np.ndarray, flat: np.ndarray, h: np.int32, w: np.int32, mx: np.ndarray,
              my: np.ndarray, frac_x: np.ndarray, frac_y: np.ndarray, at: np.ndarray,
              top: np.ndarray, bottom: np.ndarray) -> None:
    """``out[j]`` = the ``h`` × ``w`` image ``flat`` (uint8, row-major) at ``(mx[j],
    my[j])`` [texels, centres at integers], bilinear, taps outside reading 0: what
    ``cv2.remap(INTER_LINEAR, BORDER_CONSTANT, 0)`` of OpenCV 5 (5.0, 5.1) computes for a uint8
    image and float maps (float32 weights, fused multiply-adds, rounded half to even),
    the renderer's sampler before (``tests`` compare the two). Three loops, so that the
    arithmetic ones vectorise and only the loads (two 16-bit pairs per sample) stay
    scalar: scratch of at least ``len(mx)`` float32 ``frac_x``, ``frac_y``, int32 ``at``,
    uint16 ``top``, ``bottom``."""
    n = len(mx)
    last_x = np.float32(w - 1)  # exact: the atlas has < 2^24 texels a side
    last_y = np.float32(h - 1)
    for j in range(n):
        fx = np.floor(mx[j])  # x may be negative (padding)
        fy = np.floor(my[j])
        frac_x[j] = mx[j] - fx
        frac_y[j] = my[j] - fy
        inside = (fx >= 0) & (fx < last_x) & (fy >= 0) & (fy < last_y)
        at[j] = np.int32(fy) * w + np.int32(fx) if inside else np.int32(-1)
    for j in range(n):
        k = at[j]
        if k >= 0:
            top[j] = load_pair(flat, k)
            bottom[j] = load_pair(flat, k + w)
        else:
            top[j], bottom[j] = _taps_at_border(flat, h, w, int(math.floor(mx[j])),
                                                int(math.floor(my[j])))
    magic = np.float32(1 << 23)  # x + 2^23 − 2^23 rounds 0 ≤ x < 2^22 half to even
    top8 = top.view(np.uint8)  # per sample its taps' bytes: left, right
    bottom8 = bottom.view(np.uint8)
    for j in range(n):
        p00 = np.float32(top8[2 * j])
        p01 = np.float32(top8[2 * j + 1])
        p10 = np.float32(bottom8[2 * j])
        p11 = np.float32(bottom8[2 * j + 1])
        v0 = _fma32(frac_x[j], p01 - p00, p00)
        v1 = _fma32(frac_x[j], p11 - p10, p10)
        v = _fma32(frac_y[j], v1 - v0, v0)  # in [0, 255]
        out[j] = np.uint8(np.int32((v + magic) - magic))


@njit(cache=True, error_model="numpy")
def _sample_atlas(tex: np.ndarray, atlas: np.ndarray, rows: np.ndarray, cols: np.ndarray,
                  widths: np.ndarray, offsets: np.ndarray, codes: np.ndarray,
                  coord_a: np.ndarray, coord_b: np.ndarray, wall_row: np.ndarray,
                  piece_table: np.ndarray, levels: int, wall_y: float, affine: np.ndarray,
                  size_x: float, size_y: float, wall_shift: float, wall_cols: float) -> None:
    """The atlas sampled (``_bilinear``) at every pixel of the requested row pieces,
    packed back to back: piece t is image row ``rows[t]``, columns ``cols[t]`` … +
    ``widths[t]``, written to the flat ``tex`` from ``offsets[t]`` on. A piece's atlas
    coordinates (pixel centres at integers) go to a small scratch first, in a loop that
    vectorises; sampling reads it while it is in cache.

    Every pixel of a piece has the same code ``codes[t]`` (the pieces are cut where it
    changes): a mip level on the ground, ``levels`` on the walls, ``levels + 1`` for the
    ceiling; ``piece_table[code]`` holds its scale (``2^-level``, 0 off the ground) and its
    atlas offsets (x, y). So a pixel reads only its two coordinates.

    Ground: ``(coord_a, coord_b)`` is the ground hit in the car frame [m], moved to level-0
    texels by ``affine`` and into the level by the scale and offsets. Walls: ``coord_a`` is
    the wall column at yaw 0, which turns with the car and wraps around the cylinder; the
    atlas row is ``wall_row`` [texels] + ``wall_y`` (summed in float64, rounded once).
    Ceiling (never sampled alone): the wall column and the padding row ``coord_b``."""
    a00, a01, a02, a10, a11, a12, lo, hx, hy = _texel_transform(affine, size_x, size_y)
    shift = np.float32(wall_shift)
    wrap = np.float32(wall_cols)
    h32, w32 = np.int32(atlas.shape[0]), np.int32(atlas.shape[1])  # < 2^31 texels
    flat = atlas.reshape(-1)
    n = coord_a.shape[1]  # the widest piece: scratch for one piece at a time
    mx, my = np.empty(n, np.float32), np.empty(n, np.float32)
    frac_x, frac_y = np.empty(n, np.float32), np.empty(n, np.float32)
    at, top, bottom = np.empty(n, np.int32), np.empty(n, np.uint16), np.empty(n, np.uint16)
    for t in range(len(rows)):
        r = rows[t]
        c0 = cols[t]
        width = widths[t]
        code = codes[t]
        scale = piece_table[code, 0]
        bx = piece_table[code, 1]
        by = piece_table[code, 2]
        ar = coord_a[r, c0:c0 + width]
        if code < levels:
            br = coord_b[r, c0:c0 + width]
            for j in range(width):
                # Level-0 texel coordinates, clamped into the level's zero guard band.
                x = min(max(a00 * ar[j] + a01 * br[j] + a02, lo), hx)
                y = min(max(a10 * ar[j] + a11 * br[j] + a12, lo), hy)
                mx[j] = x * scale + bx
                my[j] = y * scale + by
        else:
            for j in range(width):
                w = ar[j] + shift  # both in [0, wrap): one subtraction wraps it
                mx[j] = w - wrap * np.float32(w >= wrap) + bx
            if code == levels:
                for j in range(width):
                    my[j] = np.float32(wall_row[r, c0 + j] + wall_y)
            else:
                for j in range(width):
                    my[j] = coord_b[r, c0 + j]
        _bilinear(tex[offsets[t]:offsets[t] + width], flat, h32, w32, mx[:width], my[:width],
                  frac_x, frac_y, at, top, bottom)


@njit(cache=True, error_model="numpy")
def _light_maps(light_x: np.ndarray, light_y: np.ndarray, rows: np.ndarray, cols: np.ndarray,
                widths: np.ndarray, offsets: np.ndarray, coord_a: np.ndarray,
                coord_b: np.ndarray, affine: np.ndarray, size_x: float, size_y: float,
                light_scale: float) -> None:
    """Light-map coordinates of the pieces' ground hits, packed as in ``_atlas_maps``
    (level-0 texel coordinates scaled by ``light_scale``, texel centres at integers)."""
    a00, a01, a02, a10, a11, a12, lo, hx, hy = _texel_transform(affine, size_x, size_y)
    ls = np.float32(light_scale)
    half = np.float32(0.5)
    end = 0
    for t in range(len(rows)):
        ar = coord_a[rows[t], cols[t]:cols[t] + widths[t]]
        br = coord_b[rows[t], cols[t]:cols[t] + widths[t]]
        lx = light_x[offsets[t]:offsets[t] + widths[t]]
        ly = light_y[offsets[t]:offsets[t] + widths[t]]
        for j in range(widths[t]):
            lx[j] = min(max(a00 * ar[j] + a01 * br[j] + a02, lo), hx) * ls - half
            ly[j] = min(max(a10 * ar[j] + a11 * br[j] + a12, lo), hy) * ls - half
        end = max(end, offsets[t] + widths[t])
    _pad_tail(light_x, light_y, end)


@njit(cache=True)
def _pad_tail(map_x: np.ndarray, map_y: np.ndarray, end: int) -> None:
    """The tail that rounds the buffers up to whole rows reads 0."""
    pad = np.float32(_PAD)
    for j in range(end, len(map_x)):
        map_x[j] = pad
        map_y[j] = pad


def _combine_params(params: np.ndarray) -> tuple:
    """The combine passes' constants from ``params`` (mat, line, wall, bonnet [DN],
    bonnet reflectivity [-], noise σ [DN], ceiling [DN]) as float32."""
    f32 = np.float32
    return (f32(params[0]), f32((params[1] - params[0]) / 255.0), f32(params[2] / 128.0),
            f32(params[3]), f32(params[4]), f32(params[5] / 16.0), f32(params[6]))


_combine_params_jit = njit(cache=True)(_combine_params)


@njit(cache=True, error_model="numpy")
def _combine(out: np.ndarray, out_offsets: np.ndarray, rows: np.ndarray, cols: np.ndarray,
             widths: np.ndarray, tex_offsets: np.ndarray, piece_flags: np.ndarray,
             tex: np.ndarray, gain: np.ndarray, sheen: np.ndarray, noise: np.ndarray,
             noise_offset: int, image_width: int, params: np.ndarray) -> None:
    """Final grey levels of the row pieces, written to the flat ``out`` from
    ``out_offsets[t]`` on, from the sampled atlas ``tex`` (paint coverage on the ground, wall
    texture elsewhere) read from ``tex_offsets[t]`` on. Every pixel of piece t has the
    flags ``piece_flags[t]`` (1 ground, 2 bonnet, 4 ceiling): one branch per piece picks
    the formula, and each loop is short and vectorises. The rare cases have their own
    passes (``_combine_lit``, ``_paint_obstacles``).

    The loops index the whole arrays at unsigned offsets (no wrap-around of negative
    indices: they vectorise) instead of slicing them per piece: each slice of an array
    takes and drops a reference to it (two atomic operations), which numba could not prune
    in this branching loop — half of the kernel's time for ≈ 350 pieces of ≈ 145 pixels."""
    mat, k_line, wall_k, bonnet_dn, refl, sigma, ceiling = _combine_params_jit(params)
    zero = np.float32(0.0)
    top = np.float32(255.0)
    half = np.float32(0.5)
    u = np.uint64
    gain_flat = gain.reshape(-1)  # C-contiguous maps: views, made once a call
    sheen_flat = sheen.reshape(-1)
    for t in range(len(rows)):
        n = u(widths[t])
        at = u(rows[t] * image_width + cols[t])  # into gain and sheen
        nz = u(noise_offset) + at
        tx = u(tex_offsets[t])
        o = u(out_offsets[t])
        f = piece_flags[t]
        # Paint on the mat, the wall texture or the ceiling's grey, then the bonnet with
        # its reflection of that; exposure × vignetting and noise; 8-bit rounding.
        if f & 1:
            if f & 2:
                for j in range(n):
                    v = bonnet_dn + refl * (mat + k_line * np.float32(tex[tx + j])
                                            + np.float32(sheen_flat[at + j]))
                    v = v * gain_flat[at + j] + sigma * np.float32(noise[nz + j])
                    out[o + j] = np.uint8(np.int32(min(max(v, zero), top) + half))
            else:
                for j in range(n):
                    v = mat + k_line * np.float32(tex[tx + j]) + np.float32(sheen_flat[at + j])
                    v = v * gain_flat[at + j] + sigma * np.float32(noise[nz + j])
                    out[o + j] = np.uint8(np.int32(min(max(v, zero), top) + half))
        elif f & 4:
            base = bonnet_dn + refl * ceiling if f & 2 else ceiling
            for j in range(n):
                v = base * gain_flat[at + j] + sigma * np.float32(noise[nz + j])
                out[o + j] = np.uint8(np.int32(min(max(v, zero), top) + half))
        elif f & 2:
            for j in range(n):
                v = bonnet_dn + refl * (wall_k * np.float32(tex[tx + j]))
                v = v * gain_flat[at + j] + sigma * np.float32(noise[nz + j])
                out[o + j] = np.uint8(np.int32(min(max(v, zero), top) + half))
        else:
            for j in range(n):
                v = wall_k * np.float32(tex[tx + j])
                v = v * gain_flat[at + j] + sigma * np.float32(noise[nz + j])
                out[o + j] = np.uint8(np.int32(min(max(v, zero), top) + half))


@njit(cache=True, error_model="numpy")
def _combine_lit(out: np.ndarray, out_offsets: np.ndarray, rows: np.ndarray,
                 cols: np.ndarray, widths: np.ndarray, tex_offsets: np.ndarray,
                 tex: np.ndarray, light: np.ndarray, flags: np.ndarray, gain: np.ndarray,
                 sheen: np.ndarray, noise: np.ndarray, noise_offset: int, image_width: int,
                 params: np.ndarray) -> None:
    """``_combine`` with the light map: the flat ``light`` holds per sampled pixel the
    multiplier (×255) and the additive glare [DN] of the floor (shadows, glare spots)."""
    mat, k_line, wall_k, bonnet_dn, refl, sigma, ceiling = _combine_params_jit(params)
    zero = np.float32(0.0)
    top = np.float32(255.0)
    half = np.float32(0.5)
    inv255 = np.float32(1.0 / 255.0)
    for t in range(len(rows)):
        r = rows[t]
        c0 = cols[t]
        li = tex_offsets[t]
        start = noise_offset + r * image_width + c0
        o0 = out_offsets[t]
        for j in range(widths[t]):
            f = flags[r, c0 + j]
            value = np.float32(tex[li + j])
            if f & 1:
                v = (mat + k_line * value) * (np.float32(light[2 * (li + j)]) * inv255)
                v = v + np.float32(light[2 * (li + j) + 1]) + np.float32(sheen[r, c0 + j])
            elif f & 4:
                v = ceiling
            else:
                v = wall_k * value
            if f & 2:
                v = bonnet_dn + refl * v
            v = v * gain[r, c0 + j] + sigma * np.float32(noise[start + j])
            out[o0 + j] = np.uint8(min(max(v, zero), top) + half)


@njit(cache=True, error_model="numpy")
def _paint_obstacles(out: np.ndarray, out_offsets: np.ndarray, rows: np.ndarray,
                     cols: np.ndarray, widths: np.ndarray, ids: np.ndarray,
                     shades: np.ndarray, x0: int, y0: int, flags: np.ndarray,
                     gain: np.ndarray, noise: np.ndarray, noise_offset: int,
                     image_width: int, params: np.ndarray) -> None:
    """Write the obstacles over the combined pieces: ``ids`` (image pixel ``(x0, y0)`` on)
    holds the index of the face seen at a pixel into ``shades`` [DN], 0 for none. The
    bonnet stays in front of them."""
    sigma = _combine_params_jit(params)[5]
    zero = np.float32(0.0)
    top = np.float32(255.0)
    half = np.float32(0.5)
    for t in range(len(rows)):
        ir = rows[t] - y0
        c0 = cols[t]
        if not 0 <= ir < ids.shape[0]:
            continue
        j0 = max(x0 - c0, 0)
        j1 = min(x0 + ids.shape[1] - c0, widths[t])
        start = noise_offset + rows[t] * image_width + c0
        for j in range(j0, j1):
            face = ids[ir, c0 + j - x0]
            if face and not flags[rows[t], c0 + j] & 2:
                v = shades[face] * gain[rows[t], c0 + j] + sigma * np.float32(noise[start + j])
                out[out_offsets[t] + j] = np.uint8(min(max(v, zero), top) + half)


@njit(cache=True)
def _pack_pieces(boxes: np.ndarray, cuts: np.ndarray, seg_reads: np.ndarray,
                 seg_code: np.ndarray, seg_flags: np.ndarray, pack: int
                 ) -> tuple[np.ndarray, np.ndarray, int]:
    """Cut every row of the windows ``boxes`` ``(k, 4)`` (x, y, w, h) [px] into pieces of
    one pixel code (``_sample_atlas``) and flags: ``cuts[r]`` lists the columns where row r
    changes them, padded with the image width, and segment i of row r (up to column
    ``cuts[r, i]``) has code ``seg_code[r, i]``, flags ``seg_flags[r, i]`` and reads the
    atlas if ``seg_reads[r, i]`` (ceiling pixels are a constant grey, not sampled).
    Per-row tables, not lookups in the image-sized arrays: those are cold in cache here
    and cost µs.

    Returns ``(6, n)``: row, first column, width, offset in the output, offset in the
    sampled buffer (ceiling runs: the zero tail after the sampled pixels, rounded up to
    whole rows of ``pack``) and flags of each piece; ``(5, m)``: row, first column, width, sampled
    offset and code of the m sampled pieces; the rows of ``pack`` sampled. One call: the
    ROIs move every frame, so this runs every frame."""
    n_cuts = cuts.shape[1]
    n = 0
    for k in range(boxes.shape[0]):
        x0, y0, w, h = boxes[k, 0], boxes[k, 1], boxes[k, 2], boxes[k, 3]
        for r in range(y0, y0 + h):
            n += 1
            for i in range(n_cuts):
                n += x0 < cuts[r, i] < x0 + w
    out = np.empty((6, n), np.int64)
    seg = np.empty(n, np.int64)
    t = 0
    out_at = 0
    tex_at = 0
    n_sampled = 0
    for k in range(boxes.shape[0]):
        x0, y0, w, h = boxes[k, 0], boxes[k, 1], boxes[k, 2], boxes[k, 3]
        for r in range(y0, y0 + h):
            start = x0
            for i in range(n_cuts + 1):
                c = x0 + w if i == n_cuts else cuts[r, i]
                if c <= start:
                    continue
                end = min(c, x0 + w)
                width = end - start
                sampled = seg_reads[r, i]
                out[0, t], out[1, t], out[2, t], out[3, t] = r, start, width, out_at
                out[4, t] = tex_at if sampled else -1
                out[5, t] = seg_flags[r, i]
                seg[t] = i
                tex_at += width if sampled else 0
                n_sampled += sampled
                out_at += width
                t += 1
                start = end
                if start == x0 + w:
                    break
    tex_rows = (tex_at + pack - 1) // pack
    s_out = np.empty((5, n_sampled), np.int64)
    m = 0
    for t in range(n):
        if out[4, t] >= 0:
            for q in range(3):
                s_out[q, m] = out[q, t]
            s_out[3, m] = out[4, t]
            s_out[4, m] = seg_code[out[0, t], seg[t]]
            m += 1
        else:
            out[4, t] = tex_rows * pack
    return out, s_out, tex_rows


FOOTPRINT_BLOCK_PX: int = 16
"""Edge of the image blocks [px] whose ground hits are boxed separately for a lazy scene:
boxes of small blocks hug the frame's footprint (one box per window would also cover the
ground between the ROIs)."""


@njit(cache=True)
def _block_bounds(coord_a: np.ndarray, coord_b: np.ndarray, level: np.ndarray,
                  flags: np.ndarray, wall_row: np.ndarray, levels: int, block: int
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per image block of ``block`` × ``block`` px and mip level, the car-frame box of
    the ground hits of all its pixels that read that level — constants of the pixel
    layout, computed once. Returns ``(start, bounds)``: the rows of block ``b`` (numbered
    row-major) are ``bounds[start[b]:start[b + 1]]``, each ``(level, x_min, x_max, y_min,
    y_max)`` [m]. Also per block ``(min, max)`` of its wall pixels' rows in the wall
    texture [texels] (inf, −inf: none)."""
    h, w = flags.shape
    nbr = (h + block - 1) // block
    nbc = (w + block - 1) // block
    box = np.empty((nbr, nbc, levels, 4))
    box[..., 0] = box[..., 2] = math.inf
    box[..., 1] = box[..., 3] = -math.inf
    walls = np.empty((nbr * nbc, 2))
    walls[:, 0] = math.inf
    walls[:, 1] = -math.inf
    for r in range(h):
        for c in range(w):
            if not flags[r, c] & 5:  # a wall
                b = (r // block) * nbc + c // block
                walls[b, 0] = min(walls[b, 0], wall_row[r, c])
                walls[b, 1] = max(walls[b, 1], wall_row[r, c])
            if not flags[r, c] & 1:
                continue
            b = box[r // block, c // block, level[r, c]]
            x = coord_a[r, c]
            y = coord_b[r, c]
            b[0] = min(b[0], x)
            b[1] = max(b[1], x)
            b[2] = min(b[2], y)
            b[3] = max(b[3], y)
    start = np.zeros(nbr * nbc + 1, np.int64)
    for i in range(nbr):
        for j in range(nbc):
            used = 0
            for lv in range(levels):
                used += box[i, j, lv, 0] <= box[i, j, lv, 1]
            start[i * nbc + j + 1] = start[i * nbc + j] + used
    bounds = np.empty((start[-1], 5))
    k = 0
    for i in range(nbr):
        for j in range(nbc):
            for lv in range(levels):
                if box[i, j, lv, 0] <= box[i, j, lv, 1]:
                    bounds[k, 0] = lv
                    for q in range(4):  # not a slice assignment: see resample_into
                        bounds[k, 1 + q] = box[i, j, lv, q]
                    k += 1
    return start, bounds, walls


@njit(cache=True)
def _view_bounds(boxes: np.ndarray, start: np.ndarray, bounds: np.ndarray,
                 walls: np.ndarray, block: int, n_block_cols: int
                 ) -> tuple[np.ndarray, float, float]:
    """The rows of ``_block_bounds`` of every block that the windows ``boxes`` ``(k, 4)``
    (x, y, w, h) [px] touch, and the range of wall texture rows their wall pixels read
    (inf, −inf: none): what a lazy scene must have filled before the windows are sampled
    (whole blocks: a few pixels more than the windows, never fewer)."""
    wall_lo = math.inf
    wall_hi = -math.inf
    n = 0
    for k in range(boxes.shape[0]):
        x0, y0, w, h = boxes[k, 0], boxes[k, 1], boxes[k, 2], boxes[k, 3]
        for i in range(y0 // block, (y0 + h - 1) // block + 1):
            for j in range(x0 // block, (x0 + w - 1) // block + 1):
                n += start[i * n_block_cols + j + 1] - start[i * n_block_cols + j]
                wall_lo = min(wall_lo, walls[i * n_block_cols + j, 0])
                wall_hi = max(wall_hi, walls[i * n_block_cols + j, 1])
    out = np.empty((n, 5))
    t = 0
    for k in range(boxes.shape[0]):
        x0, y0, w, h = boxes[k, 0], boxes[k, 1], boxes[k, 2], boxes[k, 3]
        for i in range(y0 // block, (y0 + h - 1) // block + 1):
            for j in range(x0 // block, (x0 + w - 1) // block + 1):
                for m in range(start[i * n_block_cols + j], start[i * n_block_cols + j + 1]):
                    for q in range(5):  # element-wise: row slices cost more here
                        out[t, q] = bounds[m, q]
                    t += 1
    return out, wall_lo, wall_hi


@njit(cache=True)
def _pack_windows(boxes: np.ndarray, cuts: np.ndarray, seg_reads: np.ndarray,
                  seg_code: np.ndarray, seg_flags: np.ndarray, pack: int, start: np.ndarray,
                  bounds: np.ndarray, walls: np.ndarray, block: int, n_block_cols: int
                  ) -> tuple:
    """``_pack_pieces`` and ``_view_bounds`` of the windows ``boxes`` in one call (each
    call from Python costs µs, and this runs every frame)."""
    pieces, s_pieces, tex_rows = _pack_pieces(boxes, cuts, seg_reads, seg_code, seg_flags,
                                              pack)
    level_bounds, wall_lo, wall_hi = _view_bounds(boxes, start, bounds, walls, block,
                                                  n_block_cols)
    return pieces, s_pieces, tex_rows, level_bounds, wall_lo, wall_hi


@njit(cache=True, error_model="numpy")
def _render_lean(out: np.ndarray, tex: np.ndarray, boxes: np.ndarray, cuts: np.ndarray,
                 seg_reads: np.ndarray, seg_code: np.ndarray, seg_flags: np.ndarray,
                 pack: int, atlas: np.ndarray, coord_a: np.ndarray, coord_b: np.ndarray,
                 wall_row: np.ndarray, piece_table: np.ndarray, levels: int, wall_y: float,
                 affine: np.ndarray, size_x: float, size_y: float, wall_shift: float,
                 wall_cols: float, gain: np.ndarray, sheen: np.ndarray, noise: np.ndarray,
                 noise_offset: int, image_width: int, params: np.ndarray) -> int:
    """``Renderer.render_windows`` of one pose without light maps or obstacles in view, in
    one call (the Python between the four kernels it replaces cost 4–6 % of a "lanes" env
    step: an interpreter whose caches the kernels keep evicting): the windows' packing
    (``_pack_pieces``), ``_sample_atlas`` into the scratch ``tex`` (room for the windows'
    pixels, ``pack`` and the widest window) and ``_combine`` into ``out``. Returns 0."""
    pieces, s_pieces, tex_rows = _pack_pieces(boxes, cuts, seg_reads, seg_code, seg_flags,
                                              pack)
    n_tex = tex_rows * pack
    zero_len = 0
    for k in range(boxes.shape[0]):
        zero_len = max(zero_len, boxes[k, 2])
    tex[n_tex:n_tex + zero_len] = 0  # ceiling pieces read this tail (``_buffers``)
    if tex_rows:
        _sample_atlas(tex, atlas, s_pieces[0], s_pieces[1], s_pieces[2], s_pieces[3],
                      s_pieces[4], coord_a, coord_b, wall_row, piece_table, levels, wall_y,
                      affine, size_x, size_y, wall_shift, wall_cols)
    _combine(out, pieces[3], pieces[0], pieces[1], pieces[2], pieces[4], pieces[5], tex,
             gain, sheen, noise, noise_offset, image_width, params)
    return 0


@njit(cache=True, error_model="numpy")
def _render_lazy(block_start: np.ndarray, block_bounds: np.ndarray, block_walls: np.ndarray,
                 block: int, block_cols: int, need_args: tuple, wall_filled: np.ndarray,
                 view: tuple) -> int:
    """``_render_lean(*view)`` on a lazy scene, after the check that everything the view
    reads is filled (``_view_bounds`` of its windows, ``_needed_tiles`` with the scene's
    ``need_args``, the wall rows in ``wall_filled``), in one call. Returns 0 when
    rendered; n > 0: nothing done but the n tiles listed by ``_needed_tiles``, to be
    filled first (``_fill_render``); −1: wall rows must be copied in first
    (``MipTiles.ensure_walls``), nothing listed."""
    boxes, affine = view[2], view[15]
    bounds, wall_lo, wall_hi = _view_bounds(boxes, block_start, block_bounds, block_walls,
                                            block, block_cols)
    if wall_lo <= wall_hi:
        rows = wall_filled.shape[0]
        lo, hi = max(wall_lo, -1.0), min(wall_hi, float(rows))
        r0 = min(max(int(math.floor(lo)) - 1, 0), rows)
        r1 = min(max(int(math.floor(hi)) + 3, 0), rows)
        for r in range(r0, r1):
            if not wall_filled[r]:
                return -1
    n = _needed_tiles(bounds, affine.reshape(1, 6), *need_args)
    if n:
        return n
    return _render_lean(*view)


@njit(cache=True, error_model="numpy")
def _fill_render(n: int, fill: tuple, view: tuple) -> int:
    """What ``_render_lazy`` listed (``n`` tiles) filled by ``_fill_tiles`` (``fill``: the
    scene's ``fill_args``), then ``_render_lean(*view)``, in one call instead of three
    with Python between them. Only here: the fill's ≈ 50 arguments cost µs to pass
    (≈ 0.1 µs each), which a step that fills nothing does not pay. Returns 0."""
    _fill_tiles(n, fill)
    return _render_lean(*view)


_PACK = 1024
"""Pixels per row of the packed sample buffers (the light map is sampled by one
``cv2.remap`` of these rows)."""


@dataclass(slots=True, eq=False)  # not frozen: frozen fields cost µs to set, every frame
class _Stack:
    """The requested windows' row pieces, packed back to back (no padding): piece t is
    image row ``rows[t]``, columns ``cols[t]`` … + ``widths[t]``; its output starts at
    ``out_offsets[t]``, its atlas sample at ``tex_offsets[t]``. The ``s_*`` arrays list the
    pieces that sample the atlas (pieces of nothing but ceiling do not). Read-only once
    made (cached and shared)."""

    rows: np.ndarray
    cols: np.ndarray
    widths: np.ndarray
    out_offsets: np.ndarray
    tex_offsets: np.ndarray
    flags: np.ndarray  # of each piece (one value per piece: they are cut where it changes)
    s_rows: np.ndarray
    s_cols: np.ndarray
    s_widths: np.ndarray
    s_offsets: np.ndarray
    s_codes: np.ndarray  # pixel code of each sampled piece (``_sample_atlas``)
    tex_rows: int
    zero_len: int
    out_len: int
    views: list[tuple[int, int, tuple[int, int]]]  # per window: its slice of ``out``, shape
    level_bounds: np.ndarray  # (n, 5): level and car-frame box of the ground hits per block
    wall_rows: tuple[float, float]  # range of wall texture rows read (inf, −inf: none)


@dataclass(frozen=True)
class _PixelLayout:
    """Per-pixel constants that do not depend on where the atlas puts its levels and walls
    (cached per resolution, level count, hall and wall height)."""

    coord_a: np.ndarray  # ground: car-frame x [m]; walls: wall column at yaw 0 [texels]
    coord_b: np.ndarray  # ground: car-frame y [m]; elsewhere the padding coordinate
    wall_row: np.ndarray  # walls: row in the wall texture [texels] (float64); else 0
    flags: np.ndarray  # uint8: 1 ground, 2 bonnet, 4 ceiling
    cuts: np.ndarray  # per row: columns where the pixel code or the flags change (+ width)
    seg_code: np.ndarray  # per row and segment between cuts: its code (level on the
    seg_flags: np.ndarray  # ground, levels on the walls, levels + 1 ceiling), its flags
    seg_reads: np.ndarray  # … and whether it reads the atlas (not ceiling alone)
    block_start: np.ndarray  # ``_block_bounds``
    block_bounds: np.ndarray
    block_walls: np.ndarray
    block_cols: int  # image blocks per row
    uid: int  # serial number (``_pixel_layout_ids``): what window packings depend on


@dataclass(frozen=True)
class _Layout:
    """One atlas layout and hall (cached by the renderer): the pixel layout, and the few
    numbers that depend on where the atlas puts its levels and walls. A new track moves
    the atlas's levels and costs no per-pixel work."""

    pixel: _PixelLayout
    levels: int  # mip levels: the code of the walls
    piece_table: np.ndarray  # (levels + 2, 3) float32 per code: scale, atlas offsets x, y
    wall_y: float  # atlas row of the wall texture's row 0


def _segments(switch: np.ndarray, code: np.ndarray, flags: np.ndarray, reads: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per row, the columns c where ``switch[:, c - 1]`` (a change between columns c − 1
    and c) holds, padded with the width; and per segment between them (segment i ends at
    cut i) the ``code``, ``flags`` and ``reads`` of its first pixel."""
    h, w = code.shape
    cuts = np.full((h, max(1, int(switch.sum(axis=1).max()))), w, np.int16)  # cache-small
    seg_code = np.zeros((h, cuts.shape[1] + 1), np.uint8)
    seg_flags = np.zeros((h, cuts.shape[1] + 1), np.uint8)
    seg_reads = np.zeros((h, cuts.shape[1] + 1), np.bool_)
    for r in range(h):
        found = np.flatnonzero(switch[r]) + 1
        cuts[r, :len(found)] = found
        first = np.concatenate(([0], found))
        seg_code[r, :len(first)] = code[r, first]
        seg_flags[r, :len(first)] = flags[r, first]
        seg_reads[r, :len(first)] = reads[r, first]
    return cuts, seg_code, seg_flags, seg_reads


class Renderer:
    """Renders 752×480 grayscale frames of a ``Scene`` from a car pose.

    ``render(scene, pose)`` gives the full frame; ``render_windows(scene, pose, windows)``
    only the requested ``(x, y, width, height)`` windows [px], identical to crops of it.
    """

    def __init__(self, camera: Camera | None = None, bonnet: Bonnet | None = None) -> None:
        self.camera = camera or FisheyeCamera.default()
        self.bonnet = bonnet or self.camera.bonnet
        self.geometry = pixel_geometry(self.camera, self.bonnet)
        # Caches. Only the current scene is held (a new scene per episode must not pile
        # up atlases); layouts and window packings are keyed by value and bounded.
        self._current: tuple[Scene, _Layout, BoxFaces, tuple] | None = None
        self._layouts: dict[tuple, _Layout] = {}
        self._pixel_layouts: dict[tuple, _PixelLayout] = {}
        self._stacks: dict[tuple, _Stack] = {}
        self._effect_maps: dict[Effects, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._scratch: dict[tuple, np.ndarray] = {}
        self._pass_buffers: dict[bool, tuple[np.ndarray, ...]] = {}  # with light or not
        self._windows: dict[tuple, tuple[tuple[int, int, int, int], ...]] = {}
        self._last_effect_maps: tuple[Effects, tuple] | None = None
        self._noise = _noise_bank()
        self._lean_tex = np.empty(0, np.uint8)  # ``_render_lean``'s sample buffer

    def __setstate__(self, state: dict[str, object]) -> None:
        self.__dict__.update(state)
        if "_lean_tex" not in state:  # pickled before ``_render_lean``
            self._lean_tex = np.empty(0, np.uint8)

    @property
    def shape(self) -> tuple[int, int]:
        return self.camera.height, self.camera.width

    # ------------------------------------------------------------------ caches
    def _scene_data(self, scene: Scene) -> tuple[_Layout, BoxFaces, tuple]:
        """Layout, obstacle faces and layout key of ``scene`` (the current scene is kept)."""
        if self._current is None or self._current[0] is not scene:
            layout, key = self._layout_of(scene)
            self._current = (scene, layout, BoxFaces.of(scene.boxes), key)
        return self._current[1], self._current[2], self._current[3]

    def _layout_of(self, scene: Scene) -> tuple[_Layout, tuple]:
        """The layout of ``scene`` and its key (cached: a few; ``scene`` does not become
        the current one)."""
        key = (scene.resolution_m, scene.level_origin.tobytes(), scene.hall,
               scene.wall_origin, scene.wall_size)
        return _cached(self._layouts, key, lambda: self._build_layout(scene)), key

    def _layout(self, scene: Scene) -> _Layout:
        return self._scene_data(scene)[0]

    def _pixel_layout(self, scene: Scene) -> _PixelLayout:
        key = (scene.resolution_m, scene.levels, scene.hall, scene.wall_size[1])
        return _cached(self._pixel_layouts, key, lambda: self._build_pixel_layout(scene))

    def _build_pixel_layout(self, scene: Scene) -> _PixelLayout:
        g = self.geometry
        hall = scene.hall
        is_ground = g.rho < hall.distance_m
        z = self.camera.mount.height_m + hall.distance_m * g.tan_el.astype(np.float64)
        ceiling = ~is_ground & (z >= hall.height_m + 0.05)
        flags = (is_ground.astype(np.uint8) | (g.bonnet << 1)
                 | (ceiling.astype(np.uint8) << 2)).astype(np.uint8)
        levels = scene.levels
        level = np.clip(np.rint(g.log2_fp - math.log2(scene.resolution_m)), 0,
                        levels - 1).astype(np.int64)
        wall = ~is_ground & ~ceiling
        wall_col = np.mod(g.azimuth.astype(np.float64), 2 * math.pi) * (
            hall.distance_m / WALL_TEXEL_M)
        wall_row = np.clip(z / WALL_TEXEL_M, 0.0, scene.wall_size[1] - 1.0)
        f32 = np.float32
        code = np.where(is_ground, level, np.where(ceiling, levels + 1, levels)).astype(np.uint8)
        wall_row = np.where(wall, wall_row, 0.0)
        block_start, block_bounds, block_walls = _block_bounds(
            g.gx, g.gy, level, flags, wall_row, levels, FOOTPRINT_BLOCK_PX)
        # Pieces end where the code or the flags change (``reads_atlas`` with them), so
        # every piece has one of each.
        switches = (code[:, 1:] != code[:, :-1]) | (flags[:, 1:] != flags[:, :-1])
        cuts, seg_code, seg_flags, seg_reads = _segments(switches, code, flags, flags != 4)
        return _PixelLayout(
            coord_a=np.where(is_ground, g.gx, wall_col).astype(f32),
            coord_b=np.where(is_ground, g.gy, _PAD).astype(f32),
            wall_row=wall_row,
            flags=flags,
            cuts=cuts,
            seg_code=seg_code,
            seg_flags=seg_flags,
            seg_reads=seg_reads,
            block_start=block_start,
            block_bounds=block_bounds,
            block_walls=block_walls,
            block_cols=-(-flags.shape[1] // FOOTPRINT_BLOCK_PX),
            uid=next(_pixel_layout_ids),
        )

    def _build_layout(self, scene: Scene) -> _Layout:
        """The scene's layout: the cached pixel layout plus where this atlas puts its
        levels and walls (the same float64 sums as ever, rounded to float32 once)."""
        base = self._pixel_layout(scene)
        levels = scene.levels
        origin = scene.level_origin
        bias = np.zeros((2, levels + 2))
        # Per level 2^-L / 2 − 1/2 + the float32 origin, in float64: whole columns at once
        # (a loop of numpy scalars cost ~60 µs, once per new track).
        half_scale = 0.5 * 0.5 ** np.arange(levels, dtype=np.int64) - 0.5
        bias[:, :levels] = half_scale + origin[:levels].T.astype(np.float64)
        bias[0, levels] = scene.wall_origin[0]
        bias[0, levels + 1] = _PAD
        table = np.zeros((levels + 2, 3), np.float32)
        table[:levels, 0] = 0.5 ** np.arange(levels, dtype=np.int64)
        table[:, 1:] = bias.T  # rounded to float32 once, as the offsets always were
        return _Layout(pixel=base, levels=levels, piece_table=table,
                       wall_y=float(scene.wall_origin[1]))

    def _buffers(self, st: _Stack, with_light: bool
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Scratch arrays for a packing: planar light maps, the sampled light and the
        sampled atlas, whose tail past the sampled pixels is 0 (ceiling pieces read it).
        Views of buffers that only grow: the ROIs' packings differ every frame, and fresh
        arrays cost allocations and page faults."""
        rows, tail = st.tex_rows, st.zero_len
        n_tex = rows * _PACK
        bufs = self._pass_buffers.get(with_light)
        if bufs is None or len(bufs[2]) < n_tex + tail or (
                with_light and bufs[0].shape[1] < rows):
            cap = max(rows, len(bufs[2]) // _PACK if bufs is not None else 0)
            size = cap * _PACK + max(tail, self.camera.width)
            bufs = self._pass_buffers[with_light] = (
                np.empty((2, cap, _PACK) if with_light else (2, 1, 1), np.float32),
                np.empty((size, 2) if with_light else (1, 2), np.uint8),
                np.empty(size, np.uint8))
        tex = bufs[2][:n_tex + tail]
        tex[n_tex:] = 0  # an earlier, larger packing may have sampled there
        if not with_light:
            return bufs[0], bufs[1], tex
        return bufs[0][:, :rows], bufs[1][:n_tex + tail], tex

    def _buffer(self, name: str, shape: tuple[int, ...], dtype: type) -> np.ndarray:
        """A reusable scratch array (fresh large arrays cost page faults every frame)."""
        key = (name, shape, dtype)
        buf = self._scratch.get(key)
        if buf is None:
            if len(self._scratch) > 64:
                self._scratch.clear()
            buf = self._scratch[key] = np.empty(shape, dtype)
        return buf

    def _maps_for(self, fx: Effects) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per-pixel gain (exposure × vignetting), floor sheen [DN] and the scalar
        parameters of the combine pass, for ``fx``."""
        last = self._last_effect_maps
        if last is not None and last[0] is fx:  # hashing a dataclass costs more than this
            return last[1]
        if fx not in self._effect_maps:
            g = self.geometry
            gain = (fx.gain * (1.0 - fx.vignetting * g.radius2)).astype(np.float32)
            sheen = np.clip(np.rint(fx.glare * g.sheen), 0, 255).astype(np.uint8)
            params = np.array([fx.mat_dn, fx.line_dn, fx.wall_dn, fx.bonnet_dn,
                               fx.bonnet_reflectivity, fx.noise_dn, CEILING_FACTOR * fx.wall_dn])
            if len(self._effect_maps) > 16:
                self._effect_maps.clear()
            self._effect_maps[fx] = (gain, sheen, params)
        self._last_effect_maps = (fx, self._effect_maps[fx])
        return self._effect_maps[fx]

    # ------------------------------------------------------------------ render
    def render(self, scene: Scene, pose: tuple[float, float, float], *, speed_m_s: float = 0.0,
               frame_seed: int = 0) -> np.ndarray:
        """Full ``(480, 752)`` uint8 frame for a car at ``pose = (x [m], y [m], yaw [rad])``
        moving at ``speed_m_s`` (motion blur); ``frame_seed`` selects the sensor noise."""
        (frame,) = self.render_windows(
            scene, pose, [(0, 0, self.camera.width, self.camera.height)],
            speed_m_s=speed_m_s, frame_seed=frame_seed)
        return frame

    def prefill(self, scene: Scene, pose: tuple[float, float, float],
                windows: list[tuple[int, int, int, int]]) -> None:
        """Fill what ``render_windows(scene, pose, windows)`` will read of a lazy scene
        (without motion blur: a blurred render fills the rest itself), and render nothing:
        a caller with time to spare does a first frame's paint ahead (a vector env's lane
        preparing its next episode while another resets). The renders stay the same: a
        filled tile holds the eager scene's texels, whoever filled it. The scene's layout
        is made and kept too, and the scene last rendered stays this renderer's current
        one. A no-op on an eager scene or a lazy one filled whole."""
        x, y, yaw = (float(v) for v in pose)
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(yaw)):
            raise ValueError(f"pose must be finite, got {pose}")
        boxes = self._check_windows(windows)
        if not boxes or scene.tiles is None or scene.tiles.complete:
            return
        layout, _ = self._layout_of(scene)
        st = self._stack(boxes, layout.pixel)
        scene.prepare(st.level_bounds, self._affine(scene, x, y, yaw)[None], st.wall_rows)

    def render_windows(self, scene: Scene, pose: tuple[float, float, float],
                       windows: list[tuple[int, int, int, int]], *, speed_m_s: float = 0.0,
                       frame_seed: int = 0) -> list[np.ndarray]:
        """Render only the windows ``(x, y, width, height)`` [px] (inside the image).

        All windows of a call are rendered together, row by row, so four small ROIs cost
        little more than their pixels."""
        x, y, yaw = pose  # every frame: no generators (µs each)
        x, y, yaw = float(x), float(y), float(yaw)
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(yaw)
                and math.isfinite(speed_m_s)):
            raise ValueError(f"pose and speed must be finite, got {pose}, {speed_m_s}")
        width, height = self.camera.width, self.camera.height
        boxes = self._windows.get(key := tuple(map(tuple, windows)))
        if boxes is None:
            boxes = self._check_windows(windows)
            if len(self._windows) >= 32:
                self._windows.clear()
            self._windows[key] = boxes
        if not boxes:
            return []
        fx = scene.effects
        layout, box_faces, _ = self._scene_data(scene)
        gain, sheen, params = self._maps_for(fx)
        full_frame = len(boxes) == 1 and boxes[0] == (0, 0, width, height)
        if not full_frame and scene.light is None and not (speed_m_s * fx.motion_blur_s > 0):
            # Windows (the ROIs, a new packing every frame) without blur or light: one
            # kernel call, unless obstacles are in view. A full frame keeps its packing
            # (cached) and its glue is a small share of its time.
            uv = visible_faces(self.camera, box_faces, (x, y, yaw), scene.hall.distance_m,
                               boxes)[0]
            if not len(uv):
                crops = self._render_lean(scene, layout, boxes, x, y, yaw, gain, sheen,
                                          params, frame_seed)
                if crops is not None:
                    return crops
        return self._render_staged(scene, layout, box_faces, boxes, x, y, yaw, gain, sheen,
                                   params, speed_m_s, frame_seed, full_frame)

    def _render_lean(self, scene: Scene, layout: _Layout, boxes: tuple, x: float, y: float,
                     yaw: float, gain: np.ndarray, sheen: np.ndarray, params: np.ndarray,
                     frame_seed: int) -> list[np.ndarray] | None:
        """``render_windows`` through ``_render_lean`` (the kernel): the crops, or None
        where wall rows must be copied in first (the staged path does that)."""
        width, height = self.camera.width, self.camera.height
        px = layout.pixel
        views, area, widest = _window_views(boxes)
        tex = self._lean_tex
        if len(tex) < area + _PACK + widest:  # grows only (fresh arrays cost page faults)
            tex = self._lean_tex = np.empty(area + _PACK + max(widest, width), np.uint8)
        out = np.empty(area, np.uint8)
        args = (out, tex, np.array(boxes, np.int64), px.cuts, px.seg_reads, px.seg_code,
                px.seg_flags, _PACK, scene.atlas, px.coord_a, px.coord_b, px.wall_row,
                layout.piece_table, layout.levels, layout.wall_y,
                self._affine(scene, x, y, yaw), float(scene.level0_size[0]),
                float(scene.level0_size[1]),
                (yaw % (2 * math.pi)) * (scene.hall.distance_m / WALL_TEXEL_M),
                float(scene.wall_size[0]), gain, sheen, self._noise,
                _noise_offset(frame_seed, width * height), width, params)
        tiles = scene.tiles
        if tiles is None or tiles.complete:
            _render_lean(*args)
        elif tiles.run_view(_render_lazy, (px.block_start, px.block_bounds, px.block_walls,
                                           FOOTPRINT_BLOCK_PX, px.block_cols,
                                           tiles.need_args, tiles.wall_filled, args),
                            _fill_render, (args,)) < 0:
            return None  # wall rows to copy in: the staged path does that
        return [out[a:b].reshape(shape) for a, b, shape in views]

    def _render_staged(self, scene: Scene, layout: _Layout, box_faces: BoxFaces, boxes: tuple,
                       x: float, y: float, yaw: float, gain: np.ndarray, sheen: np.ndarray,
                       params: np.ndarray, speed_m_s: float, frame_seed: int,
                       full_frame: bool) -> list[np.ndarray]:
        """``render_windows`` kernel by kernel: motion blur, light maps, obstacles."""
        width, height = self.camera.width, self.camera.height
        fx = scene.effects
        st = self._stack(boxes, layout.pixel)
        px = layout.pixel
        blur_m = speed_m_s * fx.motion_blur_s
        shifts = np.linspace(0.0, blur_m, MOTION_BLUR_SAMPLES) if blur_m > 0 else (0.0,)
        blur = len(shifts) > 1
        with_light = scene.light is not None
        n_tex = st.tex_rows * _PACK  # sampled pixels, rounded up to whole rows of _PACK
        light_maps, light, tex = self._buffers(st, with_light)
        if blur:
            total = self._buffer("tex_sum", (n_tex + st.zero_len,), np.float32)
            total.fill(0.0)
        c, s = math.cos(yaw), math.sin(yaw)
        affines = [self._affine(scene, x - back * c, y - back * s, yaw) for back in shifts]
        if scene.tiles is not None and not scene.tiles.complete:
            # A lazy scene fills what this view reads: the poses of the first and the last
            # blur sample bound the boxes of all of them (one straight shift).
            scene.prepare(st.level_bounds, np.stack((affines[0], affines[-1])) if blur
                          else affines[0][None], st.wall_rows)
        wall_shift = (yaw % (2 * math.pi)) * (scene.hall.distance_m / WALL_TEXEL_M)
        size_x, size_y = float(scene.level0_size[0]), float(scene.level0_size[1])
        for k, affine in enumerate(affines):
            if not st.tex_rows:
                break
            maps_args = (st.s_rows, st.s_cols, st.s_widths, st.s_offsets)
            _sample_atlas(tex, scene.atlas, *maps_args, st.s_codes, px.coord_a, px.coord_b,
                          px.wall_row, layout.piece_table, layout.levels,
                          layout.wall_y, affine, size_x, size_y, wall_shift,
                          float(scene.wall_size[0]))
            if with_light and k == 0:
                _light_maps(light_maps[0].reshape(-1), light_maps[1].reshape(-1), *maps_args,
                            px.coord_a, px.coord_b, affine, size_x, size_y,
                            scene.resolution_m / LIGHT_RES_M)
            if blur:
                total += tex
            if with_light and k == 0:
                cv2.remap(scene.light, light_maps[0], light_maps[1], cv2.INTER_LINEAR,
                          dst=light[:n_tex].reshape(st.tex_rows, _PACK, 2),
                          borderMode=cv2.BORDER_REPLICATE)
        sampled = total * np.float32(1.0 / len(shifts)) if blur else tex
        uv, bbox, shading = visible_faces(self.camera, box_faces, (x, y, yaw),
                                          scene.hall.distance_m, None if full_frame else boxes)
        drawn = draw_faces(uv, bbox, fx.line_dn * shading, width, height) if len(uv) else None
        out = np.empty(st.out_len, np.uint8)
        noise_offset = _noise_offset(frame_seed, width * height)
        pieces = (out, st.out_offsets, st.rows, st.cols, st.widths)
        if with_light:
            _combine_lit(*pieces, st.tex_offsets, sampled, light.reshape(-1), px.flags,
                         gain, sheen, self._noise, noise_offset, width, params)
        else:
            _combine(*pieces, st.tex_offsets, st.flags, sampled, gain, sheen, self._noise,
                     noise_offset, width, params)
        if drawn is not None:
            (ox0, oy0), ids, shades = drawn
            _paint_obstacles(*pieces, ids, shades, ox0, oy0, px.flags, gain, self._noise,
                             noise_offset, width, params)
        return [out[a:b].reshape(shape) for a, b, shape in st.views]

    def _check_windows(self, windows: list[tuple[int, int, int, int]]
                       ) -> tuple[tuple[int, int, int, int], ...]:
        """The windows as int tuples, each checked to lie inside the image."""
        width, height = self.camera.width, self.camera.height
        boxes = []
        for win in windows:
            if len(win) != 4:
                raise ValueError(f"window {win} must be (x, y, width, height) [px]")
            wx0, wy0, ww, wh = map(int, win)
            if ww <= 0 or wh <= 0 or wx0 < 0 or wy0 < 0 or wx0 + ww > width or (
                    wy0 + wh > height):
                raise ValueError(f"window {win} is not inside the {width}×{height} image")
            boxes.append((wx0, wy0, ww, wh))
        return tuple(boxes)

    def _stack(self, boxes: tuple, px: _PixelLayout) -> _Stack:
        """How the windows' pixels are packed (cached per window list and pixel layout:
        the same for every track)."""
        key = (px.uid, boxes)
        cached = self._stacks.get(key)
        if cached is not None:
            return cached
        pieces, s_pieces, tex_rows, level_bounds, wall_lo, wall_hi = _pack_windows(
            np.array(boxes, np.int64), px.cuts, px.seg_reads, px.seg_code, px.seg_flags,
            _PACK, px.block_start, px.block_bounds, px.block_walls, FOOTPRINT_BLOCK_PX,
            px.block_cols)
        views, out_len, zero_len = _window_views(boxes)
        stack = _Stack(rows=pieces[0], cols=pieces[1], widths=pieces[2],
                       out_offsets=pieces[3], tex_offsets=pieces[4], flags=pieces[5],
                       s_rows=s_pieces[0],
                       s_cols=s_pieces[1], s_widths=s_pieces[2], s_offsets=s_pieces[3],
                       s_codes=s_pieces[4], tex_rows=tex_rows, zero_len=zero_len,
                       out_len=out_len, views=views,
                       level_bounds=level_bounds, wall_rows=(wall_lo, wall_hi))
        if len(self._stacks) >= 32:  # the ROIs move every frame: few packings come back
            self._stacks.clear()  # (popping the oldest of a dict of tuples costs µs)
        self._stacks[key] = stack
        return stack

    def _affine(self, scene: Scene, x: float, y: float, yaw: float) -> np.ndarray:
        """Car-frame ground point → level-0 texel coordinates (centres at integers)."""
        c, s = math.cos(yaw), math.sin(yaw)
        inv = 1.0 / scene.resolution_m
        ox, oy = scene.origin
        return np.array([c * inv, -s * inv, (x - ox) * inv - 0.5,
                         -s * inv, -c * inv, (oy - y) * inv - 0.5])


def _cached(cache: dict, key: object, make: Callable[[], _T], size: int = 4) -> _T:
    """``cache[key]``, made by ``make()`` when missing; past ``size`` entries the oldest
    goes (a few layouts: the current scene's, a prepared one's, …)."""
    value = cache.get(key)
    if value is None:
        value = make()
        if len(cache) >= size:
            cache.pop(next(iter(cache)))
        cache[key] = value
    return value


def _window_views(boxes: tuple[tuple[int, int, int, int], ...]
                  ) -> tuple[list[tuple[int, int, tuple[int, int]]], int, int]:
    """Where each window's crop lies in the flat output, back to back: per window its
    slice ``(start, stop)`` and shape ``(h, w)``; the total pixel count and the widest
    window [px]."""
    views = []
    area = widest = 0
    for _, _, ww, wh in boxes:
        views.append((area, area + ww * wh, (wh, ww)))
        area += ww * wh
        widest = max(widest, ww)
    return views, area, widest


@functools.cache
def _noise_bank() -> np.ndarray:
    """A fixed table of sensor noise [DN] (N(0, 16²), rounded, int8, read-only); each frame
    reads it at its own offset. Made once per process: ≈ 70 ms here, every renderer's."""
    bank = np.random.default_rng(0x7FA1DA).normal(0.0, 16.0, NOISE_BANK_SIZE)
    noise = np.clip(np.rint(bank), -127, 127).astype(np.int8)
    noise.flags.writeable = False
    return noise


def _noise_offset(frame_seed: int, pixels: int) -> int:
    """Where a frame reads the noise bank: a splitmix64 hash of its seed. The same offset
    for every window of a frame keeps the noise a function of the pixel."""
    z = (int(frame_seed) + 0x9E3779B97F4A7C15) & 0xFFFFFFFFFFFFFFFF  # int: no int64 wrap
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & 0xFFFFFFFFFFFFFFFF
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & 0xFFFFFFFFFFFFFFFF
    return (z ^ (z >> 31)) % (NOISE_BANK_SIZE - pixels)
