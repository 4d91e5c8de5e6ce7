"""The camera image: per-pixel inverse mapping onto the ground, footprint-filtered.

The ground is flat and the camera rigid on the car, so every pixel's ray, its ground hit
in the car frame, its footprint on the ground and therefore its mip level are constants,
computed once (``PixelGeometry``). Per frame and pixel:

1. *maps* (numba, vectorised): the ground hit moved to the world by the car pose and
   turned into a texel coordinate of the pixel's own mip level inside the mip atlas;
2. *ground*: one ``cv2.remap`` (bilinear, SIMD) of the atlas for all ground pixels: far
   dashes are pre-filtered, so they fade instead of shimmering or vanishing;
3. *walls*: one ``cv2.remap`` of the wall texture, shifted by the car's yaw;
4. *combine* (numba, vectorised): floor sheen, shadows and glare, the bonnet with its
   faint reflection, obstacles, exposure × vignetting, sensor noise, 8-bit rounding.

Every step depends only on the pixel and the frame (the noise is read from a fixed bank
at a per-frame offset), so any window rendered alone equals the same crop of the full
frame bit for bit — perception renders only its ROIs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numba import njit

from ..camera import FisheyeCamera
from .effects import Effects
from .scene import LIGHT_RES_M, WALL_TEXEL_M, Hall, Scene

MOTION_BLUR_SAMPLES: int = 5
"""Sub-frame poses averaged for motion blur."""

OBSTACLE_EDGE_STEPS: int = 12
"""Points per box edge when projecting an obstacle's faces (fisheye bends straight edges)."""

CEILING_FACTOR: float = 1.25
"""Ceiling brightness relative to ``Effects.wall_dn`` [-]."""

NOISE_BANK_SIZE: int = 1 << 21
"""Entries of the fixed table of standard-normal sensor noise (int8, 1/16 σ steps)."""

_NOISE_SCALE = 1.0 / 16.0


@dataclass(frozen=True)
class Bonnet:
    """The car's bonnet in the bottom rows: its edge is at ``top_row`` [px] in the image
    middle and ``edge_drop_px`` lower at the left and right borders (a parabola)."""

    top_row: float = 440.0
    edge_drop_px: float = 22.0
    enabled: bool = True

    def edge(self, u: np.ndarray, width: int) -> np.ndarray:
        """Row of the bonnet edge [px] at columns ``u``."""
        t = (np.asarray(u, dtype=np.float64) - (width - 1) / 2) / ((width - 1) / 2)
        return self.top_row + self.edge_drop_px * t * t


@dataclass(frozen=True)
class PixelGeometry:
    """Per-pixel constants of a camera on the car, ``(height, width)`` arrays. On the
    bonnet they describe the mirrored pixel (the reflection)."""

    gx: np.ndarray  # ground hit, car frame x [m] (0 where the ray does not go down)
    gy: np.ndarray  # ground hit, car frame y [m]
    rho: np.ndarray  # horizontal distance camera → ground hit [m] (inf: no hit)
    azimuth: np.ndarray  # ray azimuth in the car frame [rad], left positive
    tan_el: np.ndarray  # rise of the ray per metre of horizontal travel [-]
    log2_fp: np.ndarray  # log2 of the pixel's footprint on the ground [log2 m]
    radius2: np.ndarray  # squared distance from the image centre, 1 in the corners [-]
    sheen: np.ndarray  # floor sheen weight, largest at grazing view [-]
    bonnet: np.ndarray  # uint8: 1 on the bonnet


def pixel_geometry(camera: FisheyeCamera, bonnet: Bonnet | None = None) -> PixelGeometry:
    """Compute the per-pixel constants of ``camera`` (once per camera and bonnet)."""
    bonnet = bonnet or Bonnet()
    h, w = camera.height, camera.width
    pos = camera.mount.position()
    rot = camera.mount.rotation()

    def ground(u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        rays = camera.unproject(np.column_stack([u.ravel(), v.ravel()])) @ rot
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(rays[:, 2] < -1e-9, -pos[2] / rays[:, 2], np.nan)
        return rays, pos[0] + t * rays[:, 0], pos[1] + t * rays[:, 1]

    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    on_bonnet = (v >= bonnet.edge(u, w)) if bonnet.enabled else np.zeros_like(v, dtype=bool)
    v_geo = np.where(on_bonnet, 2.0 * bonnet.edge(u, w) - v, v)  # mirrored about the edge
    rays, gx, gy = ground(u, v_geo)
    horiz = np.hypot(rays[:, 0], rays[:, 1])
    rho = np.hypot(gx - pos[0], gy - pos[1])
    rho = np.where(np.isfinite(rho), rho, np.inf)
    # Footprint: geometric mean of the ground steps to the neighbouring half-pixels.
    _, ax, ay = ground(u + 0.5, v_geo)
    _, bx, by = ground(u - 0.5, v_geo)
    _, cx, cy = ground(u, v_geo + 0.5)
    _, ex, ey = ground(u, v_geo - 0.5)
    fp = np.sqrt(np.hypot(ax - bx, ay - by) * np.hypot(cx - ex, cy - ey))
    ok = np.isfinite(fp) & (fp > 0)
    log2_fp = np.where(ok, np.log2(np.where(ok, fp, 1.0)), 30.0)
    cu, cv_ = (w - 1) / 2, (h - 1) / 2
    radius2 = ((u - cu) ** 2 + (v - cv_) ** 2) / (cu**2 + cv_**2)
    depression = np.arctan2(-rays[:, 2], horiz)
    sheen = np.where(np.isfinite(rho), np.exp(-np.maximum(depression, 0.0) / 0.08), 0.0)
    f32 = np.float32
    shape = (h, w)
    return PixelGeometry(
        gx=np.nan_to_num(gx).reshape(shape).astype(f32),
        gy=np.nan_to_num(gy).reshape(shape).astype(f32),
        rho=rho.reshape(shape).astype(f32),
        azimuth=np.arctan2(rays[:, 1], rays[:, 0]).reshape(shape).astype(f32),
        tan_el=(rays[:, 2] / np.maximum(horiz, 1e-12)).reshape(shape).astype(f32),
        log2_fp=log2_fp.reshape(shape).astype(f32), radius2=radius2.astype(f32),
        sheen=sheen.reshape(shape).astype(f32), bonnet=on_bonnet.astype(np.uint8),
    )


_PAD = -8.0
"""Map coordinate for padding pixels: outside the atlas (reads 0)."""


@njit(cache=True, error_model="numpy")
def _atlas_maps(map_x: np.ndarray, map_y: np.ndarray, light_x: np.ndarray,
                light_y: np.ndarray, rows: np.ndarray, cols: np.ndarray,
                widths: np.ndarray, offsets: np.ndarray, coord_a: np.ndarray,
                coord_b: np.ndarray, scale: np.ndarray, bias_x: np.ndarray,
                bias_y: np.ndarray, flags: np.ndarray, affine: np.ndarray, size_x: float,
                size_y: float, wall_shift: float, wall_cols: float, light_scale: float,
                with_light: bool) -> None:
    """Atlas coordinates (pixel centres at integers) of the requested row pieces, packed
    back to back: piece t is image row ``rows[t]``, columns ``cols[t]`` … + ``widths[t]``,
    written to the flat ``map_x`` and ``map_y`` from pixel ``offsets[t]`` on (planar maps:
    contiguous stores here, and OpenCV's remap reads them faster than interleaved ones).

    Ground pixels (flag 1): ``(coord_a, coord_b)`` is the ground hit in the car frame [m],
    moved to level-0 texels by ``affine`` and into the pixel's mip level by ``scale`` and
    ``bias``. Other pixels: ``coord_a`` is the wall column at yaw 0, ``coord_b`` the atlas
    row; the column turns with the car and wraps around the cylinder. Both are computed
    and one is selected, so the loop has no branch and vectorises."""
    a00, a01, a02, a10, a11, a12 = (np.float32(affine[0]), np.float32(affine[1]),
                                    np.float32(affine[2]), np.float32(affine[3]),
                                    np.float32(affine[4]), np.float32(affine[5]))
    lo = np.float32(-2.0)
    hx = np.float32(size_x + 1.0)
    hy = np.float32(size_y + 1.0)
    shift = np.float32(wall_shift)
    wrap = np.float32(wall_cols)
    one = np.float32(1.0)
    ls = np.float32(light_scale)
    half = np.float32(0.5)
    pad = np.float32(_PAD)
    end = 0
    for t in range(len(rows)):
        r = rows[t]
        c0 = cols[t]
        width = widths[t]
        ar = coord_a[r, c0:c0 + width]
        br = coord_b[r, c0:c0 + width]
        sr = scale[r, c0:c0 + width]
        bxr = bias_x[r, c0:c0 + width]
        byr = bias_y[r, c0:c0 + width]
        fr = flags[r, c0:c0 + width]
        start = offsets[t]
        mx = map_x[start:start + width]  # slices of flat views: no per-row reshape
        my = map_y[start:start + width]
        for j in range(width):
            g = np.float32(fr[j] & 1)  # 0/1 factors blend exactly and keep this branch-free
            # Level-0 texel coordinates, clamped into the level's zero guard band.
            x = min(max(a00 * ar[j] + a01 * br[j] + a02, lo), hx)
            y = min(max(a10 * ar[j] + a11 * br[j] + a12, lo), hy)
            w = ar[j] + shift  # both in [0, wrap): one subtraction wraps it
            w = w - wrap * np.float32(w >= wrap)
            mx[j] = g * (x * sr[j]) + (one - g) * w + bxr[j]
            my[j] = g * (y * sr[j] + byr[j]) + (one - g) * br[j]
        if with_light:
            lx = light_x[start:start + width]
            ly = light_y[start:start + width]
            for j in range(width):
                lx[j] = min(max(a00 * ar[j] + a01 * br[j] + a02, lo), hx) * ls - half
                ly[j] = min(max(a10 * ar[j] + a11 * br[j] + a12, lo), hy) * ls - half
        end = max(end, start + width)
    for j in range(end, len(map_x)):  # the tail that rounds the buffer up: reads 0
        map_x[j] = pad
        map_y[j] = pad
    if with_light:
        for j in range(end, len(light_x)):
            light_x[j] = pad
            light_y[j] = pad


@njit(cache=True, error_model="numpy")
def _combine(out: np.ndarray, out_offsets: np.ndarray, rows: np.ndarray, cols: np.ndarray,
             widths: np.ndarray, tex_offsets: np.ndarray, tex: np.ndarray, light: np.ndarray,
             with_light: bool,
             overlay: np.ndarray, overlay_mask: np.ndarray, overlay_x0: int, overlay_y0: int,
             with_overlay: bool, flags: np.ndarray, gain: np.ndarray, sheen: np.ndarray,
             noise: np.ndarray, noise_offset: int, image_width: int, params: np.ndarray) -> None:
    """Final grey levels of the row pieces, written to the flat ``out`` from
    ``out_offsets[t]`` on, from the sampled atlas ``tex`` (paint coverage on the ground, wall
    texture elsewhere) read from ``tex_offsets[t]`` on (flat ``light`` alike).
    ``flags``: 1 ground, 2 bonnet, 4 ceiling."""
    mat = np.float32(params[0])
    k_line = np.float32((params[1] - params[0]) / 255.0)
    wall_k = np.float32(params[2] / 128.0)
    bonnet_dn = np.float32(params[3])
    refl = np.float32(params[4])
    sigma = np.float32(params[5] / 16.0)
    ceiling = np.float32(params[6])
    zero = np.float32(0.0)
    one = np.float32(1.0)
    top = np.float32(255.0)
    half = np.float32(0.5)
    inv255 = np.float32(1.0 / 255.0)
    for t in range(len(rows)):
        r = rows[t]
        c0 = cols[t]
        width = widths[t]
        fl = flags[r, c0:c0 + width]
        ga = gain[r, c0:c0 + width]
        sh = sheen[r, c0:c0 + width]
        start = noise_offset + r * image_width + c0
        nz = noise[start:start + width]
        li = tex_offsets[t]
        tx = tex[li:li + width]
        o = out[out_offsets[t]:out_offsets[t] + width]
        o_row = r - overlay_y0
        o_hit = with_overlay and 0 <= o_row < overlay_mask.shape[0] and (
            c0 < overlay_x0 + overlay_mask.shape[1] and c0 + width > overlay_x0)
        if not (with_light or o_hit):
            # Fast path, branch-free so that it vectorises: 0/1 factors blend exactly.
            for j in range(width):
                f = fl[j]
                is_g = np.float32(f & 1)
                is_b = np.float32((f >> 1) & 1)
                is_c = np.float32((f >> 2) & 1)
                value = np.float32(tx[j])
                w = is_c * ceiling + (one - is_c) * (wall_k * value)
                v = is_g * (mat + k_line * value + np.float32(sh[j])) + (one - is_g) * w
                v = is_b * (bonnet_dn + refl * v) + (one - is_b) * v
                v = v * ga[j] + sigma * np.float32(nz[j])
                o[j] = np.uint8(min(max(v, zero), top) + half)
            continue
        for j in range(width):
            f = fl[j]
            value = np.float32(tx[j])
            if f & 1:
                v = mat + k_line * value
                if with_light:
                    v = v * (np.float32(light[2 * (li + j)]) * inv255) + np.float32(
                        light[2 * (li + j) + 1])
                v = v + np.float32(sh[j])
            elif f & 4:
                v = ceiling
            else:
                v = wall_k * value
            if o_hit and not f & 2:
                oc = c0 + j - overlay_x0
                if 0 <= oc < overlay_mask.shape[1] and overlay_mask[o_row, oc]:
                    v = overlay[o_row, oc]
            if f & 2:
                v = bonnet_dn + refl * v
            v = v * ga[j] + sigma * np.float32(nz[j])
            o[j] = np.uint8(min(max(v, zero), top) + half)


_PACK = 1024
"""Pixels per row of the packed buffers handed to ``cv2.remap``."""


@dataclass(frozen=True)
class _Stack:
    """The requested windows' row pieces, packed back to back (no padding): piece t is
    image row ``rows[t]``, columns ``cols[t]`` … + ``widths[t]``; its output starts at
    ``out_offsets[t]``, its atlas sample at ``tex_offsets[t]``. The ``s_*`` arrays list the
    pieces that sample the atlas (rows of nothing but ceiling do not)."""

    rows: np.ndarray
    cols: np.ndarray
    widths: np.ndarray
    out_offsets: np.ndarray
    tex_offsets: np.ndarray
    s_rows: np.ndarray
    s_cols: np.ndarray
    s_widths: np.ndarray
    s_offsets: np.ndarray
    tex_rows: int
    zero_len: int
    out_len: int
    window_offsets: list[int]


@dataclass(frozen=True)
class _Layout:
    """Per-pixel constants for one atlas layout and hall (cached by the renderer)."""

    coord_a: np.ndarray  # ground: car-frame x [m]; walls: wall column at yaw 0 [texels]
    coord_b: np.ndarray  # ground: car-frame y [m]; walls: atlas row [texels]
    scale: np.ndarray  # ground: 2^-level
    bias_x: np.ndarray  # ground: level offset in the atlas; walls: the wall's atlas column
    bias_y: np.ndarray
    flags: np.ndarray  # uint8: 1 ground, 2 bonnet, 4 ceiling
    sampled_rows: np.ndarray  # bool per image row: has a pixel that reads the atlas


class Renderer:
    """Renders 752×480 grayscale frames of a ``Scene`` from a car pose.

    ``render(scene, pose)`` gives the full frame; ``render_windows(scene, pose, windows)``
    only the requested ``(x, y, width, height)`` windows [px], identical to crops of it.
    """

    def __init__(self, camera: FisheyeCamera | None = None, bonnet: Bonnet | None = None) -> None:
        self.camera = camera or FisheyeCamera.default()
        self.bonnet = bonnet or Bonnet()
        self.geometry = pixel_geometry(self.camera, self.bonnet)
        # Caches. Only the current scene is held (a new scene per episode must not pile
        # up atlases); layouts and window packings are keyed by value and bounded.
        self._current: tuple[Scene, _Layout, BoxFaces, tuple] | None = None
        self._layouts: dict[tuple, _Layout] = {}
        self._stacks: dict[tuple, _Stack] = {}
        self._effect_maps: dict[Effects, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._scratch: dict[tuple, np.ndarray] = {}
        self._windows: dict[tuple, tuple[tuple[int, int, int, int], ...]] = {}
        self._last_effect_maps: tuple[Effects, tuple] | None = None
        # A fixed table of N(0, 1) noise; each frame reads it at its own offset.
        bank = np.random.default_rng(0x7FA1DA).normal(0.0, 16.0, NOISE_BANK_SIZE)
        self._noise = np.clip(np.rint(bank), -127, 127).astype(np.int8)

    @property
    def shape(self) -> tuple[int, int]:
        return self.camera.height, self.camera.width

    # ------------------------------------------------------------------ caches
    def _scene_data(self, scene: Scene) -> tuple[_Layout, BoxFaces, tuple]:
        """Layout, obstacle faces and layout key of ``scene`` (the current scene is kept)."""
        if self._current is None or self._current[0] is not scene:
            key = (scene.resolution_m, scene.level_origin.tobytes(), scene.hall,
                   scene.wall_origin, scene.wall_size)
            layout = self._layouts.get(key)
            if layout is None:
                layout = self._build_layout(scene)
                if len(self._layouts) >= 4:
                    self._layouts.pop(next(iter(self._layouts)))
                self._layouts[key] = layout
            self._current = (scene, layout, BoxFaces.of(scene.boxes), key)
        return self._current[1], self._current[2], self._current[3]

    def _layout(self, scene: Scene) -> _Layout:
        return self._scene_data(scene)[0]

    def _build_layout(self, scene: Scene) -> _Layout:
        g = self.geometry
        hall = scene.hall
        is_ground = g.rho < hall.distance_m
        z = self.camera.mount.height_m + hall.distance_m * g.tan_el.astype(np.float64)
        ceiling = ~is_ground & (z >= hall.height_m + 0.05)
        flags = (is_ground.astype(np.uint8) | (g.bonnet << 1)
                 | (ceiling.astype(np.uint8) << 2)).astype(np.uint8)
        level = np.clip(np.rint(g.log2_fp - math.log2(scene.resolution_m)), 0,
                        scene.levels - 1).astype(np.int64)
        level_scale = 0.5 ** level
        origin = scene.level_origin
        wall_rows = scene.wall_size[1]
        wall_col = np.mod(g.azimuth.astype(np.float64), 2 * math.pi) * (
            hall.distance_m / WALL_TEXEL_M)
        wall_row = np.clip(z / WALL_TEXEL_M, 0.0, wall_rows - 1.0) + scene.wall_origin[1]
        f32 = np.float32
        return _Layout(
            coord_a=np.where(is_ground, g.gx, wall_col).astype(f32),
            coord_b=np.where(is_ground, g.gy, np.where(ceiling, _PAD, wall_row)).astype(f32),
            scale=np.where(is_ground, level_scale, 0.0).astype(f32),
            bias_x=np.where(is_ground, 0.5 * level_scale - 0.5 + origin[level, 0],
                            np.where(ceiling, _PAD, scene.wall_origin[0])).astype(f32),
            bias_y=np.where(is_ground, 0.5 * level_scale - 0.5 + origin[level, 1], 0.0
                            ).astype(f32),
            flags=flags,
            sampled_rows=~np.all(flags == 4, axis=1),
        )

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

    def render_windows(self, scene: Scene, pose: tuple[float, float, float],
                       windows: list[tuple[int, int, int, int]], *, speed_m_s: float = 0.0,
                       frame_seed: int = 0) -> list[np.ndarray]:
        """Render only the windows ``(x, y, width, height)`` [px] (inside the image).

        All windows of a call are rendered together, row by row, so four small ROIs cost
        little more than their pixels."""
        x, y, yaw = (float(v) for v in pose)
        if not all(math.isfinite(v) for v in (x, y, yaw, speed_m_s)):
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
        layout, box_faces, layout_key = self._scene_data(scene)
        gain, sheen, params = self._maps_for(fx)
        st = self._stack(boxes, layout, layout_key)
        blur_m = speed_m_s * fx.motion_blur_s
        shifts = np.linspace(0.0, blur_m, MOTION_BLUR_SAMPLES) if blur_m > 0 else np.zeros(1)
        blur = len(shifts) > 1
        with_light = scene.light is not None
        n_tex = st.tex_rows * _PACK  # sampled pixels, rounded up to whole rows of _PACK
        maps = self._buffer("maps", (2, st.tex_rows, _PACK), np.float32)  # planar x, y
        light_maps = self._buffer("light_maps", (2, st.tex_rows, _PACK) if with_light
                                  else (2, 1, 1), np.float32)
        light = self._buffer("light", (n_tex + st.zero_len, 2) if with_light else (1, 2),
                             np.uint8)
        tex = self._buffer("tex", (n_tex + st.zero_len,), np.uint8)
        tex[n_tex:] = 0  # read by the rows that show nothing but ceiling
        if blur:
            total = self._buffer("tex_sum", (n_tex + st.zero_len,), np.float32)
            total.fill(0.0)
        wall_shift = (yaw % (2 * math.pi)) * (scene.hall.distance_m / WALL_TEXEL_M)
        for k, back in enumerate(shifts):
            if not st.tex_rows:
                break
            affine = self._affine(scene, x - back * math.cos(yaw), y - back * math.sin(yaw), yaw)
            _atlas_maps(maps[0].reshape(-1), maps[1].reshape(-1), light_maps[0].reshape(-1),
                        light_maps[1].reshape(-1), st.s_rows, st.s_cols,
                        st.s_widths, st.s_offsets, layout.coord_a, layout.coord_b,
                        layout.scale, layout.bias_x, layout.bias_y, layout.flags, affine,
                        float(scene.level0_size[0]), float(scene.level0_size[1]), wall_shift,
                        float(scene.wall_size[0]), scene.resolution_m / LIGHT_RES_M,
                        with_light and k == 0)
            cv2.remap(scene.atlas, maps[0], maps[1], cv2.INTER_LINEAR,
                      dst=tex[:n_tex].reshape(st.tex_rows, _PACK),
                      borderMode=cv2.BORDER_CONSTANT, borderValue=0)
            if blur:
                total += tex
            if with_light and k == 0:
                cv2.remap(scene.light, light_maps[0], light_maps[1], cv2.INTER_LINEAR,
                          dst=light[:n_tex].reshape(st.tex_rows, _PACK, 2),
                          borderMode=cv2.BORDER_REPLICATE)
        sampled = total * np.float32(1.0 / len(shifts)) if blur else tex
        full_frame = len(boxes) == 1 and boxes[0] == (0, 0, width, height)
        faces = obstacle_faces(self.camera, box_faces, (x, y, yaw), fx.line_dn,
                               scene.hall.distance_m, None if full_frame else boxes)
        drawn = _draw_faces(faces, width, height)
        (ox0, oy0), overlay, mask = drawn if drawn is not None else (
            (0, 0), np.zeros((1, 1), np.float32), np.zeros((1, 1), np.uint8))
        out = np.empty(st.out_len, np.uint8)
        _combine(out, st.out_offsets, st.rows, st.cols, st.widths, st.tex_offsets, sampled,
                 light.reshape(-1), with_light, overlay, mask, ox0, oy0, drawn is not None,
                 layout.flags, gain, sheen, self._noise,
                 _noise_offset(frame_seed, width * height), width, params)
        return [out[o:o + ww * wh].reshape(wh, ww)
                for o, (_, _, ww, wh) in zip(st.window_offsets, boxes, strict=True)]

    def _check_windows(self, windows: list[tuple[int, int, int, int]]
                       ) -> tuple[tuple[int, int, int, int], ...]:
        """The windows as int tuples, each checked to lie inside the image."""
        width, height = self.camera.width, self.camera.height
        boxes = []
        for win in windows:
            if len(win) != 4:
                raise ValueError(f"window {win} must be (x, y, width, height) [px]")
            wx0, wy0, ww, wh = (int(v) for v in win)
            if ww <= 0 or wh <= 0 or wx0 < 0 or wy0 < 0 or wx0 + ww > width or (
                    wy0 + wh > height):
                raise ValueError(f"window {win} is not inside the {width}×{height} image")
            boxes.append((wx0, wy0, ww, wh))
        return tuple(boxes)

    def _stack(self, boxes: tuple, layout: _Layout, layout_key: tuple) -> _Stack:
        """How the windows' pixels are packed (cached per window list and layout)."""
        key = (boxes, layout_key)
        cached = self._stacks.get(key)
        if cached is not None:
            return cached
        heights = np.array([wh for _, _, _, wh in boxes])
        rows = np.concatenate([np.arange(wy0, wy0 + wh) for _, wy0, _, wh in boxes])
        cols = np.repeat(np.array([wx0 for wx0, _, _, _ in boxes]), heights)
        widths = np.repeat(np.array([ww for _, _, ww, _ in boxes]), heights)
        out_offsets = np.concatenate(([0], np.cumsum(widths)[:-1]))
        sampled = layout.sampled_rows[rows]
        s_widths = widths[sampled]
        s_offsets = np.concatenate(([0], np.cumsum(s_widths)[:-1])).astype(np.int64)
        tex_rows = -(-int(s_widths.sum()) // _PACK)
        tex_offsets = np.full(len(rows), tex_rows * _PACK, np.int64)  # the zero tail
        tex_offsets[sampled] = s_offsets
        window_offsets = np.concatenate(([0], np.cumsum(heights * np.array(
            [ww for _, _, ww, _ in boxes]))[:-1]))
        stack = _Stack(rows=rows, cols=cols, widths=widths, out_offsets=out_offsets,
                       tex_offsets=tex_offsets, s_rows=rows[sampled], s_cols=cols[sampled],
                       s_widths=s_widths, s_offsets=s_offsets, tex_rows=tex_rows,
                       zero_len=int(widths.max()), out_len=int(widths.sum()),
                       window_offsets=[int(o) for o in window_offsets])
        if len(self._stacks) >= 32:
            self._stacks.pop(next(iter(self._stacks)))
        self._stacks[key] = stack
        return stack

    def _affine(self, scene: Scene, x: float, y: float, yaw: float) -> np.ndarray:
        """Car-frame ground point → level-0 texel coordinates (centres at integers)."""
        c, s = math.cos(yaw), math.sin(yaw)
        inv = 1.0 / scene.resolution_m
        ox, oy = scene.origin
        return np.array([c * inv, -s * inv, (x - ox) * inv - 0.5,
                         -s * inv, -c * inv, (oy - y) * inv - 0.5])


def _noise_offset(frame_seed: int, pixels: int) -> int:
    """Where a frame reads the noise bank: a splitmix64 hash of its seed. The same offset
    for every window of a frame keeps the noise a function of the pixel."""
    z = (int(frame_seed) + 0x9E3779B97F4A7C15) & 0xFFFFFFFFFFFFFFFF  # int: no int64 wrap
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & 0xFFFFFFFFFFFFFFFF
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & 0xFFFFFFFFFFFFFFFF
    return (z ^ (z >> 31)) % (NOISE_BANK_SIZE - pixels)


@dataclass(frozen=True)
class BoxFaces:
    """The five visible-capable faces (no bottom) of obstacle boxes, precomputed once:
    outlines ``(n, 5, 4·OBSTACLE_EDGE_STEPS, 3)``, outward normals and face centres
    ``(n, 5, 3)`` and box centres ``(n, 3)`` [m]."""

    outlines: np.ndarray
    normals: np.ndarray
    mids: np.ndarray
    centres: np.ndarray

    @classmethod
    def of(cls, boxes: np.ndarray) -> BoxFaces:
        """Faces of boxes ``(n, 8, 3)``: corners 0–3 on the ground, 4–7 above them."""
        quads = np.array([(4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)])
        boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 8, 3)
        pts = boxes[:, quads]  # (n, 5, 4, 3)
        t = np.linspace(0.0, 1.0, OBSTACLE_EDGE_STEPS, endpoint=False)[None, None, None, :, None]
        nxt = np.roll(pts, -1, axis=2)
        outlines = (pts[:, :, :, None] + t * (nxt - pts)[:, :, :, None]).reshape(
            len(boxes), 5, 4 * OBSTACLE_EDGE_STEPS, 3)
        normals = np.cross(pts[:, :, 1] - pts[:, :, 0], pts[:, :, 3] - pts[:, :, 0])
        normals /= np.maximum(np.linalg.norm(normals, axis=-1, keepdims=True), 1e-12)
        mids = pts.mean(axis=2)
        centres = boxes.mean(axis=1)
        flip = np.einsum("nfk,nfk->nf", normals, mids - centres[:, None]) < 0
        normals[flip] *= -1.0
        return cls(outlines, normals, mids, centres)


_LIGHT_DIR = np.array([0.3, -0.5, 0.81]) / np.linalg.norm([0.3, -0.5, 0.81])


def obstacle_faces(camera: FisheyeCamera, faces: BoxFaces, pose: tuple[float, float, float],
                   white_dn: float = 255.0, max_distance_m: float = Hall().distance_m,
                   windows: list[tuple[int, int, int, int]] | None = None
                   ) -> list[tuple[np.ndarray, float]]:
    """Faces of the obstacle boxes the camera sees, as image polygons [px] with a grey
    level (white carton lit from above), farthest first (painter's order). Boxes beyond
    ``max_distance_m`` stand behind the hall's walls; faces reaching behind the lens are
    left out. With ``windows`` [(x, y, w, h) px], faces whose image bounding box touches
    none of them are left out too (they cannot change a requested pixel)."""
    if len(faces.centres) == 0:
        return []
    x, y, yaw = pose
    cam_world = np.array([x + math.cos(yaw) * camera.mount.forward_m,
                          y + math.sin(yaw) * camera.mount.forward_m, camera.mount.height_m])
    d = faces.centres - cam_world
    dist = np.sqrt(np.einsum("nk,nk->n", d, d))
    near = np.flatnonzero(dist <= max_distance_m)
    if len(near) == 0:
        return []
    facing = np.einsum("nfk,nfk->nf", faces.normals[near], cam_world - faces.mids[near]) > 0
    box_i, face_i = np.nonzero(facing)
    if len(box_i) == 0:
        return []
    outlines = faces.outlines[near[box_i], face_i]  # (m, P, 3)
    cam_pts = camera.world_to_camera(outlines.reshape(-1, 3), pose).reshape(outlines.shape)
    keep = np.all(cam_pts[:, :, 2] > 0.02, axis=1)
    uv = camera.project(cam_pts.reshape(-1, 3)).reshape(len(outlines), -1, 2)
    if windows is not None:
        # A face drawn inside its outline's bounding box (±2 px for the fill's rounding)
        # that misses every window cannot change a requested pixel.
        lo = np.nan_to_num(uv.min(axis=1), nan=-1e9) - 2.0  # (m, 2)
        hi = np.nan_to_num(uv.max(axis=1), nan=1e9) + 2.0
        win = np.asarray(windows, dtype=np.float64)  # (k, 4)
        touches = ((hi[:, None, 0] >= win[None, :, 0])
                   & (lo[:, None, 0] < win[None, :, 0] + win[None, :, 2])
                   & (hi[:, None, 1] >= win[None, :, 1])
                   & (lo[:, None, 1] < win[None, :, 1] + win[None, :, 3]))
        keep &= touches.any(axis=1)
    shade = white_dn * (0.72 + 0.28 * np.maximum(0.0, faces.normals[near[box_i], face_i]
                                                 @ _LIGHT_DIR))
    order = np.argsort(-dist[near[box_i]], kind="stable")
    return [(uv[k], float(shade[k])) for k in order if keep[k]]


def _draw_faces(faces: list[tuple[np.ndarray, float]], width: int, height: int
                ) -> tuple[tuple[int, int], np.ndarray, np.ndarray] | None:
    """Draw the obstacle faces once per frame into a buffer covering their bounding box in
    image coordinates (the same whatever window is asked for, so windows equal crops).
    Returns its top-left corner, the grey levels and the mask, or None if off-image."""
    if not faces:
        return None
    pts_all = np.concatenate([uv for uv, _ in faces])
    x0 = max(0, int(np.floor(pts_all[:, 0].min())) - 1)
    y0 = max(0, int(np.floor(pts_all[:, 1].min())) - 1)
    x1 = min(width, int(np.ceil(pts_all[:, 0].max())) + 2)
    y1 = min(height, int(np.ceil(pts_all[:, 1].max())) + 2)
    if x1 <= x0 or y1 <= y0:
        return None
    overlay = np.zeros((y1 - y0, x1 - x0), np.float32)
    mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
    shift = 4  # sub-pixel vertices: 1/16 px
    for uv, shade in faces:
        pts = np.rint((uv - np.array([x0, y0])) * (1 << shift)).astype(np.int32)
        cv2.fillPoly(overlay, [pts], float(shade), lineType=cv2.LINE_8, shift=shift)
        cv2.fillPoly(mask, [pts], 1, lineType=cv2.LINE_8, shift=shift)
    return (x0, y0), overlay, mask
