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


@njit(cache=True, error_model="numpy")
def _ground_maps(maps: np.ndarray, light_maps: np.ndarray, r0: int, c0: int, gx: np.ndarray,
                 gy: np.ndarray, scale: np.ndarray, bias_x: np.ndarray, bias_y: np.ndarray,
                 affine: np.ndarray, size_x: float, size_y: float, light_scale: float,
                 with_light: bool) -> None:
    """Atlas coordinates of each pixel's ground hit (pixel centres at integers)."""
    a00, a01, a02, a10, a11, a12 = (np.float32(affine[0]), np.float32(affine[1]),
                                    np.float32(affine[2]), np.float32(affine[3]),
                                    np.float32(affine[4]), np.float32(affine[5]))
    lo = np.float32(-2.0)
    hx = np.float32(size_x + 1.0)
    hy = np.float32(size_y + 1.0)
    ls = np.float32(light_scale)
    width = maps.shape[1]
    half = np.float32(0.5)
    for i in range(maps.shape[0]):
        gxr = gx[r0 + i, c0:c0 + width]
        gyr = gy[r0 + i, c0:c0 + width]
        sr = scale[r0 + i, c0:c0 + width]
        bxr = bias_x[r0 + i, c0:c0 + width]
        byr = bias_y[r0 + i, c0:c0 + width]
        m = maps[i].reshape(2 * width)  # interleaved (x, y): contiguous stores
        for j in range(width):
            # Level-0 texel coordinates, clamped into the level's zero guard band.
            x = min(max(a00 * gxr[j] + a01 * gyr[j] + a02, lo), hx)
            y = min(max(a10 * gxr[j] + a11 * gyr[j] + a12, lo), hy)
            m[2 * j] = x * sr[j] + bxr[j]
            m[2 * j + 1] = y * sr[j] + byr[j]
        if with_light:
            lm = light_maps[i].reshape(2 * width)
            for j in range(width):
                lm[2 * j] = min(max(a00 * gxr[j] + a01 * gyr[j] + a02, lo), hx) * ls - half
                lm[2 * j + 1] = min(max(a10 * gxr[j] + a11 * gyr[j] + a12, lo), hy) * ls - half


@njit(cache=True, error_model="numpy")
def _shift_maps(out: np.ndarray, static: np.ndarray, r0: int, c0: int, shift: float) -> None:
    """``out = static[r0:, c0:] + (shift, 0)`` for interleaved (x, y) maps."""
    s = np.float32(shift)
    width = out.shape[1]
    for i in range(out.shape[0]):
        o = out[i].reshape(2 * width)
        st = static[r0 + i].reshape(2 * static.shape[1])
        for j in range(width):
            o[2 * j] = st[2 * (c0 + j)] + s
            o[2 * j + 1] = st[2 * (c0 + j) + 1]


@njit(cache=True, error_model="numpy")
def _combine(out: np.ndarray, r0: int, c0: int, cov: np.ndarray, wall: np.ndarray,
             light: np.ndarray, with_light: bool, overlay: np.ndarray, overlay_mask: np.ndarray,
             with_overlay: bool, flags: np.ndarray, gain: np.ndarray, sheen: np.ndarray,
             noise: np.ndarray, noise_offset: int, image_width: int, params: np.ndarray) -> None:
    """Final grey levels. ``flags``: 1 ground, 2 bonnet, 4 ceiling (wall texture skipped)."""
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
    width = out.shape[1]
    for i in range(out.shape[0]):
        r = r0 + i
        fl = flags[r, c0:c0 + width]
        ga = gain[r, c0:c0 + width]
        sh = sheen[r, c0:c0 + width]
        start = noise_offset + r * image_width + c0
        nz = noise[start:start + width]
        cv = cov[i]
        wl = wall[i]
        o = out[i]
        if with_overlay and not with_light:
            om = overlay_mask[i]
            ov = overlay[i]
            for j in range(width):  # as the fast path below, plus obstacles
                f = fl[j]
                is_g = np.float32(f & 1)
                is_b = np.float32((f >> 1) & 1)
                is_c = np.float32((f >> 2) & 1)
                is_o = np.float32(om[j]) * (one - is_b)
                w = is_c * ceiling + (one - is_c) * (wall_k * np.float32(wl[j]))
                v = is_g * (mat + k_line * np.float32(cv[j]) + np.float32(sh[j])) + (
                    one - is_g) * w
                v = is_o * ov[j] + (one - is_o) * v
                v = is_b * (bonnet_dn + refl * v) + (one - is_b) * v
                v = v * ga[j] + sigma * np.float32(nz[j])
                o[j] = np.uint8(min(max(v, zero), top) + half)
            continue
        if not with_light:
            # Fast path, branch-free so that it vectorises: 0/1 factors blend exactly.
            for j in range(width):
                f = fl[j]
                is_g = np.float32(f & 1)
                is_b = np.float32((f >> 1) & 1)
                is_c = np.float32((f >> 2) & 1)
                w = is_c * ceiling + (one - is_c) * (wall_k * np.float32(wl[j]))
                v = is_g * (mat + k_line * np.float32(cv[j]) + np.float32(sh[j])) + (
                    one - is_g) * w
                v = is_b * (bonnet_dn + refl * v) + (one - is_b) * v
                v = v * ga[j] + sigma * np.float32(nz[j])
                o[j] = np.uint8(min(max(v, zero), top) + half)
            continue
        for j in range(width):
            v = mat + k_line * np.float32(cv[j])
            if with_light:
                v = v * (np.float32(light[i, j, 0]) * np.float32(1.0 / 255.0)) + np.float32(
                    light[i, j, 1])
            f = fl[j]
            w = ceiling if f & 4 else wall_k * np.float32(wl[j])
            v = v + np.float32(sh[j]) if f & 1 else w
            if with_overlay and overlay_mask[i, j] and not f & 2:
                v = overlay[i, j]
            v = bonnet_dn + refl * v if f & 2 else v
            v = v * ga[j] + sigma * np.float32(nz[j])
            o[j] = np.uint8(min(max(v, zero), top) + half)


@dataclass(frozen=True)
class _Layout:
    """Per-pixel constants for one atlas layout and hall (cached by the renderer)."""

    scale: np.ndarray
    bias_x: np.ndarray
    bias_y: np.ndarray
    flags: np.ndarray  # uint8: 1 ground, 2 bonnet, 4 ceiling
    wall_maps: np.ndarray  # (H, W, 2) wall-texture coordinates at yaw 0
    ground_rows: tuple[int, int]
    wall_rows: tuple[int, int]


class Renderer:
    """Renders 752×480 grayscale frames of a ``Scene`` from a car pose.

    ``render(scene, pose)`` gives the full frame; ``render_windows(scene, pose, windows)``
    only the requested ``(x, y, width, height)`` windows [px], identical to crops of it.
    """

    def __init__(self, camera: FisheyeCamera | None = None, bonnet: Bonnet | None = None) -> None:
        self.camera = camera or FisheyeCamera.default()
        self.bonnet = bonnet or Bonnet()
        self.geometry = pixel_geometry(self.camera, self.bonnet)
        self._layouts: dict[tuple, _Layout] = {}
        self._effect_maps: dict[Effects, tuple[np.ndarray, np.ndarray]] = {}
        self._scratch: dict[tuple, np.ndarray] = {}
        # A fixed table of N(0, 1) noise; each frame reads it at its own offset.
        bank = np.random.default_rng(0x7FA1DA).normal(0.0, 16.0, NOISE_BANK_SIZE)
        self._noise = np.clip(np.rint(bank), -127, 127).astype(np.int8)

    @property
    def shape(self) -> tuple[int, int]:
        return self.camera.height, self.camera.width

    # ------------------------------------------------------------------ caches
    def _layout(self, scene: Scene) -> _Layout:
        key = (scene.resolution_m, scene.level_origin.tobytes(), scene.hall,
               scene.wall_texture.shape)
        if key in self._layouts:
            return self._layouts[key]
        g = self.geometry
        level = np.clip(np.rint(g.log2_fp - math.log2(scene.resolution_m)), 0,
                        scene.levels - 1).astype(np.int64)
        scale = (0.5 ** level).astype(np.float32)
        origin = scene.level_origin
        bias_x = (0.5 * scale - 0.5 + origin[level, 0]).astype(np.float32)
        bias_y = (0.5 * scale - 0.5 + origin[level, 1]).astype(np.float32)
        hall = scene.hall
        is_ground = (g.rho < hall.distance_m).astype(np.uint8)
        z = self.camera.mount.height_m + hall.distance_m * g.tan_el.astype(np.float64)
        tex_rows = scene.wall_texture.shape[0]
        wall_x = np.mod(g.azimuth.astype(np.float64), 2 * math.pi) * (
            hall.distance_m / WALL_TEXEL_M)
        wall_y = np.clip(z / WALL_TEXEL_M, 0.0, tex_rows - 1.0)
        wall_maps = np.dstack([wall_x, wall_y]).astype(np.float32)
        ceiling = (is_ground == 0) & (z >= hall.height_m + 0.05)
        flags = (is_ground | (g.bonnet << 1) | (ceiling.astype(np.uint8) << 2)).astype(np.uint8)
        rows_ground = np.flatnonzero(is_ground.any(axis=1))
        rows_wall = np.flatnonzero(((is_ground == 0) & ~ceiling).any(axis=1))
        layout = _Layout(
            scale=scale, bias_x=bias_x, bias_y=bias_y, flags=flags, wall_maps=wall_maps,
            ground_rows=(int(rows_ground[0]), int(rows_ground[-1]) + 1) if len(rows_ground)
            else (0, 0),
            wall_rows=(int(rows_wall[0]), int(rows_wall[-1]) + 1) if len(rows_wall) else (0, 0),
        )
        if len(self._layouts) > 8:
            self._layouts.clear()
        self._layouts[key] = layout
        return layout

    def _buffer(self, name: str, shape: tuple[int, ...], dtype: type) -> np.ndarray:
        """A reusable scratch array (fresh large arrays cost page faults every frame)."""
        key = (name, shape, dtype)
        buf = self._scratch.get(key)
        if buf is None:
            if len(self._scratch) > 64:
                self._scratch.clear()
            buf = self._scratch[key] = np.empty(shape, dtype)
        return buf

    def _maps_for(self, fx: Effects) -> tuple[np.ndarray, np.ndarray]:
        """Per-pixel gain (exposure × vignetting) and floor sheen [DN] for ``fx``."""
        if fx not in self._effect_maps:
            g = self.geometry
            gain = (fx.gain * (1.0 - fx.vignetting * g.radius2)).astype(np.float32)
            sheen = np.clip(np.rint(fx.glare * g.sheen), 0, 255).astype(np.uint8)
            if len(self._effect_maps) > 16:
                self._effect_maps.clear()
            self._effect_maps[fx] = (gain, sheen)
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
        """Render only the windows ``(x, y, width, height)`` [px] (inside the image)."""
        x, y, yaw = (float(v) for v in pose)
        if not all(math.isfinite(v) for v in (x, y, yaw, speed_m_s)):
            raise ValueError(f"pose and speed must be finite, got {pose}, {speed_m_s}")
        fx = scene.effects
        layout = self._layout(scene)
        gain, sheen = self._maps_for(fx)
        faces = obstacle_faces(self.camera, scene.boxes, (x, y, yaw), fx.line_dn,
                               scene.hall.distance_m)
        drawn = _draw_faces(faces, self.camera.width, self.camera.height)
        width, height = self.camera.width, self.camera.height
        # Same offset for every window of a frame: noise is a function of the pixel.
        span = NOISE_BANK_SIZE - width * height
        noise_offset = int(np.random.default_rng(frame_seed & 0xFFFFFFFF).integers(span))
        blur_m = speed_m_s * fx.motion_blur_s
        shifts = (np.linspace(0.0, blur_m, MOTION_BLUR_SAMPLES) if blur_m > 0
                  else np.zeros(1))
        params = np.array([fx.mat_dn, fx.line_dn, fx.wall_dn, fx.bonnet_dn,
                           fx.bonnet_reflectivity, fx.noise_dn, CEILING_FACTOR * fx.wall_dn])
        wall_shift = (yaw % (2 * math.pi)) * (scene.hall.distance_m / WALL_TEXEL_M)
        out = []
        for win in windows:
            wx0, wy0, ww, wh = (int(v) for v in win)
            if ww <= 0 or wh <= 0 or wx0 < 0 or wy0 < 0 or wx0 + ww > width or (
                    wy0 + wh > height):
                raise ValueError(f"window {win} is not inside the {width}×{height} image")
            blur = len(shifts) > 1
            cov = self._buffer("cov", (wh, ww), np.float32 if blur else np.uint8)
            if blur:
                cov.fill(0.0)  # stale float bytes may be NaN, and 0 × NaN is no 0
            wall = self._buffer("wall", (wh, ww), np.uint8)
            light = self._buffer("light", (1, 1, 2), np.uint8)
            g0, g1 = max(wy0, layout.ground_rows[0]), min(wy0 + wh, layout.ground_rows[1])
            if g1 > g0:
                band = slice(g0 - wy0, g1 - wy0)
                maps = self._buffer("maps", (g1 - g0, ww, 2), np.float32)
                light_maps = self._buffer(
                    "light_maps", (g1 - g0, ww, 2) if scene.light is not None else (1, 1, 2),
                    np.float32)
                sample = self._buffer("sample", (g1 - g0, ww), np.uint8)
                for k, back in enumerate(shifts):
                    affine = self._affine(scene, x - back * math.cos(yaw),
                                          y - back * math.sin(yaw), yaw)
                    _ground_maps(maps, light_maps, g0, wx0, self.geometry.gx, self.geometry.gy,
                                 layout.scale, layout.bias_x, layout.bias_y, affine,
                                 float(scene.level0_size[0]), float(scene.level0_size[1]),
                                 scene.resolution_m / LIGHT_RES_M,
                                 scene.light is not None and k == 0)
                    if blur:
                        cv2.remap(scene.atlas, maps, None, cv2.INTER_LINEAR, dst=sample,
                                  borderMode=cv2.BORDER_CONSTANT, borderValue=0)
                        cov[band] += sample.astype(np.float32) / len(shifts)
                    else:
                        cv2.remap(scene.atlas, maps, None, cv2.INTER_LINEAR, dst=cov[band],
                                  borderMode=cv2.BORDER_CONSTANT, borderValue=0)
                    if scene.light is not None and k == 0:
                        light = self._buffer("light", (wh, ww, 2), np.uint8)
                        cv2.remap(scene.light, light_maps, None, cv2.INTER_LINEAR,
                                  dst=light[band], borderMode=cv2.BORDER_REPLICATE)
            s0, s1 = max(wy0, layout.wall_rows[0]), min(wy0 + wh, layout.wall_rows[1])
            if s1 > s0:
                wmaps = self._buffer("wall_maps", (s1 - s0, ww, 2), np.float32)
                _shift_maps(wmaps, layout.wall_maps, s0, wx0, wall_shift)
                # Nearest texel: at the walls' distance a pixel spans about one texel.
                cv2.remap(scene.wall_texture, wmaps, None, cv2.INTER_NEAREST,
                          dst=wall[s0 - wy0:s1 - wy0], borderMode=cv2.BORDER_WRAP)
            overlay = self._buffer("overlay", (wh, ww), np.float32)
            mask = self._buffer("overlay_mask", (wh, ww), np.uint8)
            with_overlay = False
            if drawn is not None:
                (ox0, oy0), ov_all, mask_all = drawn
                ix0, iy0 = max(wx0, ox0), max(wy0, oy0)
                ix1 = min(wx0 + ww, ox0 + ov_all.shape[1])
                iy1 = min(wy0 + wh, oy0 + ov_all.shape[0])
                if ix1 > ix0 and iy1 > iy0:
                    with_overlay = True
                    overlay.fill(0.0)
                    mask.fill(0)
                    overlay[iy0 - wy0:iy1 - wy0, ix0 - wx0:ix1 - wx0] = ov_all[
                        iy0 - oy0:iy1 - oy0, ix0 - ox0:ix1 - ox0]
                    mask[iy0 - wy0:iy1 - wy0, ix0 - wx0:ix1 - wx0] = mask_all[
                        iy0 - oy0:iy1 - oy0, ix0 - ox0:ix1 - ox0]
            frame = np.empty((wh, ww), np.uint8)
            _combine(frame, wy0, wx0, cov, wall, light, scene.light is not None, overlay, mask,
                     with_overlay, layout.flags, gain, sheen, self._noise, noise_offset, width,
                     params)
            out.append(frame)
        return out

    def _affine(self, scene: Scene, x: float, y: float, yaw: float) -> np.ndarray:
        """Car-frame ground point → level-0 texel coordinates (centres at integers)."""
        c, s = math.cos(yaw), math.sin(yaw)
        inv = 1.0 / scene.resolution_m
        ox, oy = scene.origin
        return np.array([c * inv, -s * inv, (x - ox) * inv - 0.5,
                         -s * inv, -c * inv, (oy - y) * inv - 0.5])


def obstacle_faces(camera: FisheyeCamera, boxes: np.ndarray, pose: tuple[float, float, float],
                   white_dn: float = 255.0, max_distance_m: float = Hall().distance_m
                   ) -> list[tuple[np.ndarray, float]]:
    """Visible faces of obstacle boxes ``(n, 8, 3)`` [m] as image polygons [px] with a
    grey level (white carton lit from above), farthest first (painter's order). Boxes
    beyond ``max_distance_m`` stand behind the hall's walls."""
    if len(boxes) == 0:
        return []
    x, y, yaw = pose
    cam_world = np.array([x + math.cos(yaw) * camera.mount.forward_m,
                          y + math.sin(yaw) * camera.mount.forward_m, camera.mount.height_m])
    quads = ((4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7))  # no bottom
    light = np.array([0.3, -0.5, 0.81])
    t = np.linspace(0.0, 1.0, OBSTACLE_EDGE_STEPS, endpoint=False)[:, None]
    faces = []
    for box in boxes:
        centre = box.mean(axis=0)
        dist = float(np.linalg.norm(centre - cam_world))
        if dist > max_distance_m:
            continue
        for quad in quads:
            pts = box[list(quad)]
            mid = pts.mean(axis=0)
            normal = np.cross(pts[1] - pts[0], pts[3] - pts[0])
            normal /= np.linalg.norm(normal)
            if np.dot(normal, mid - centre) < 0:
                normal = -normal
            if np.dot(normal, cam_world - mid) <= 0:
                continue  # facing away
            outline = np.concatenate([pts[k] + t * (pts[(k + 1) % 4] - pts[k]) for k in range(4)])
            cam_pts = camera.world_to_camera(outline, pose)
            if np.any(cam_pts[:, 2] <= 0.02):
                continue  # a face reaching behind the lens is not drawn
            shade = white_dn * (0.72 + 0.28 * max(0.0, float(normal @ light)))
            faces.append((dist, camera.project(cam_pts), shade))
    faces.sort(key=lambda f: -f[0])
    return [(uv, shade) for _, uv, shade in faces]


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
