"""The camera image: per-pixel inverse mapping onto the ground, footprint-filtered.

The ground is flat and the camera is rigid on the car, so every pixel's ray, its ground
hit in the car frame and its footprint on the ground are fixed: ``PixelGeometry``
computes them once per camera. A frame then costs, per pixel, a 2-D rigid transform and
one bilinear fetch from the mip level that matches the pixel's footprint (no shimmer,
far dashes fade instead of vanishing). Rays that reach a wall first show the hall's wall
texture, with parallax.

Any set of windows can be rendered on its own (perception reads only its ROIs): every
stage, noise included, depends only on the pixel and the frame, so a window equals the
same crop of the full frame bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numba import njit

from ..camera import FisheyeCamera
from .effects import Effects
from .scene import LIGHT_RES_M, WALL_TEXEL_M, Scene

MAX_GROUND_RANGE_M: float = 40.0
"""Ground hits farther than this from the camera [m] are treated as reaching the walls."""

MOTION_BLUR_SAMPLES: int = 5
"""Sub-frame poses averaged for motion blur."""

OBSTACLE_EDGE_STEPS: int = 12
"""Points per box edge when projecting an obstacle's faces (fisheye bends straight edges)."""


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
    """Per-pixel constants of a camera on the car, all ``(height, width)`` float32."""

    gx: np.ndarray  # ground hit, car frame x [m] (NaN: the ray does not reach the ground)
    gy: np.ndarray  # ground hit, car frame y [m]
    rho: np.ndarray  # horizontal distance camera → ground hit [m] (inf: no hit)
    dx: np.ndarray  # horizontal direction of the ray, car frame (unit)
    dy: np.ndarray
    tan_el: np.ndarray  # rise of the ray per metre of horizontal travel [-]
    log2_fp: np.ndarray  # log2 of the pixel's footprint on the ground [log2 m]
    radius2: np.ndarray  # squared distance from the image centre, 1 at the corners [-]
    sheen: np.ndarray  # floor sheen weight (grazing view) [-]
    bonnet: np.ndarray  # uint8: 1 where the bonnet is (geometry there is the mirror's)


def pixel_geometry(camera: FisheyeCamera, bonnet: Bonnet | None = None) -> PixelGeometry:
    """Compute the per-pixel constants of ``camera`` (once per camera and bonnet)."""
    bonnet = bonnet or Bonnet()
    h, w = camera.height, camera.width
    pos = camera.mount.position()
    rot = camera.mount.rotation()

    def ground(u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, ...]:
        rays = camera.unproject(np.column_stack([u.ravel(), v.ravel()])) @ rot
        down = rays[:, 2] < -1e-9
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(down, -pos[2] / rays[:, 2], np.nan)
        return rays, pos[0] + t * rays[:, 0], pos[1] + t * rays[:, 1]

    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    if bonnet.enabled:
        edge = bonnet.edge(u, w)
        on_bonnet = v >= edge
        v_geo = np.where(on_bonnet, 2.0 * edge - v, v)  # mirrored about the bonnet's edge
    else:
        on_bonnet = np.zeros_like(v, dtype=bool)
        v_geo = v
    rays, gx, gy = ground(u, v_geo)
    horiz = np.hypot(rays[:, 0], rays[:, 1])
    rho = np.hypot(gx - pos[0], gy - pos[1])
    rho = np.where(np.isfinite(rho) & (rho <= MAX_GROUND_RANGE_M), rho, np.inf)
    # Footprint: geometric mean of the ground steps to the neighbouring half-pixels.
    _, ax, ay = ground(u + 0.5, v_geo)
    _, bx, by = ground(u - 0.5, v_geo)
    _, cx, cy = ground(u, v_geo + 0.5)
    _, ex, ey = ground(u, v_geo - 0.5)
    fp = np.sqrt(np.hypot(ax - bx, ay - by) * np.hypot(cx - ex, cy - ey))
    log2_fp = np.where(np.isfinite(fp) & (fp > 0), np.log2(np.where(fp > 0, fp, 1.0)), 30.0)
    cu, cv_ = (w - 1) / 2, (h - 1) / 2
    radius2 = ((u - cu) ** 2 + (v - cv_) ** 2) / (cu**2 + cv_**2)
    # Sheen: a specular floor is brightest where it is seen at grazing angles.
    with np.errstate(invalid="ignore", divide="ignore"):
        elev = np.arctan2(-rays[:, 2], horiz).reshape(h, w)
    sheen = np.where(np.isfinite(rho.reshape(h, w)), np.exp(-elev / 0.08), 0.0)
    f32 = np.float32
    return PixelGeometry(
        gx=gx.reshape(h, w).astype(f32), gy=gy.reshape(h, w).astype(f32),
        rho=rho.reshape(h, w).astype(f32),
        dx=(rays[:, 0] / np.maximum(horiz, 1e-12)).reshape(h, w).astype(f32),
        dy=(rays[:, 1] / np.maximum(horiz, 1e-12)).reshape(h, w).astype(f32),
        tan_el=(rays[:, 2] / np.maximum(horiz, 1e-12)).reshape(h, w).astype(f32),
        log2_fp=log2_fp.reshape(h, w).astype(f32), radius2=radius2.astype(f32),
        sheen=sheen.astype(f32), bonnet=on_bonnet.astype(np.uint8),
    )


@njit(cache=True, inline="always", error_model="numpy")
def _ground(wx: float, wy: float, level: int, pyramid: np.ndarray, offsets: np.ndarray,
            shapes: np.ndarray, res: np.ndarray, ox: float, oy: float, light: np.ndarray,
            mat: float, line: float, floor: float) -> float:
    inv0 = res[1]  # 1 / (level-0 texel size): see Renderer._levels
    fx = (wx - ox) * inv0
    fy = (oy - wy) * inv0
    if fx < 0.0 or fy < 0.0 or fy >= shapes[0, 0] or fx >= shapes[0, 1]:
        return floor
    scale = res[2 + level]  # 2^-level
    col = fx * scale + 0.5  # +1 texel so truncation is floor; undone below
    row = fy * scale + 0.5
    n_rows = shapes[level, 0]
    n_cols = shapes[level, 1]
    c0 = int(col)
    r0i = int(row)
    tc = col - c0
    tr = row - r0i
    c0 -= 1
    r0i -= 1
    c1 = min(c0 + 1, n_cols - 1)
    c0 = max(c0, 0)
    r1 = min(r0i + 1, n_rows - 1)
    r0i = max(r0i, 0)
    base = offsets[level]
    a = pyramid[base + r0i * n_cols + c0]
    b = pyramid[base + r0i * n_cols + c1]
    c = pyramid[base + r1 * n_cols + c0]
    d = pyramid[base + r1 * n_cols + c1]
    m = ((a * (1.0 - tc) + b * tc) * (1.0 - tr) + (c * (1.0 - tc) + d * tc) * tr) * (1.0 / 255.0)
    li = min(int(fy * res[0]), light.shape[0] - 1)  # res[0]: light texels per map texel
    lj = min(int(fx * res[0]), light.shape[1] - 1)
    paint = m * (1.0 - light[li, lj, 2])
    return (mat + (line - mat) * paint) * light[li, lj, 0] + light[li, lj, 1]


@njit(cache=True, inline="always", error_model="numpy")
def _noise(seed: np.uint64, index: int) -> float:
    """Approximately standard-normal value for (frame seed, pixel): splitmix64 hash, the
    sum of four 16-bit uniforms (Irwin–Hall), rescaled to unit variance."""
    z = seed + np.uint64(index) * np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    mask = np.uint64(0xFFFF)
    total = float(z & mask) + float((z >> np.uint64(16)) & mask) + float(
        (z >> np.uint64(32)) & mask) + float((z >> np.uint64(48)) & mask)
    return (total / 65535.0 - 2.0) * 1.7320508075688772


@njit(cache=True, error_model="numpy")
def _render_window(
    out: np.ndarray, r_start: int, c_start: int,
    gx: np.ndarray, gy: np.ndarray, rho: np.ndarray, dxa: np.ndarray, dya: np.ndarray,
    tan_el: np.ndarray, levels: np.ndarray, gain_map: np.ndarray, sheen_map: np.ndarray,
    bonnet: np.ndarray,
    pyramid: np.ndarray, offsets: np.ndarray, shapes: np.ndarray, res: np.ndarray,
    ox: float, oy: float, light: np.ndarray,
    walls: np.ndarray, wall_h: float, wall_tex: np.ndarray,
    car_x: float, car_y: float, car_yaw: float, cam_fwd: float, cam_lat: float, cam_h: float,
    blur_m: float, fx: np.ndarray, seed: np.uint64,
    overlay: np.ndarray, overlay_mask: np.ndarray, has_overlay: bool,
) -> None:
    mat, line, floor, wall_dn, noise_dn = fx[0], fx[1], fx[2], fx[3], fx[6]
    bonnet_dn, refl = fx[8], fx[9]
    c = math.cos(car_yaw)
    s = math.sin(car_yaw)
    cam_x = car_x + c * cam_fwd - s * cam_lat
    cam_y = car_y + s * cam_fwd + c * cam_lat
    xmin, ymin, xmax, ymax = walls[0], walls[1], walls[2], walls[3]
    wall_w = xmax - xmin
    wall_d = ymax - ymin
    near_wall = min(cam_x - xmin, xmax - cam_x, cam_y - ymin, ymax - cam_y)
    n_blur = 1 if blur_m <= 0.0 else 5
    width = gx.shape[1]
    wall_scale = wall_dn / 128.0
    for i in range(out.shape[0]):
        r = r_start + i
        for j in range(out.shape[1]):
            q = c_start + j
            if has_overlay and overlay_mask[i, j]:
                v = overlay[i, j]
            else:
                dist = rho[r, q]
                to_wall = math.inf
                if dist >= near_wall:
                    hx = c * dxa[r, q] - s * dya[r, q]
                    hy = s * dxa[r, q] + c * dya[r, q]
                    if hx > 1e-9:
                        to_wall = (xmax - cam_x) / hx
                    elif hx < -1e-9:
                        to_wall = (xmin - cam_x) / hx
                    if hy > 1e-9:
                        to_wall = min(to_wall, (ymax - cam_y) / hy)
                    elif hy < -1e-9:
                        to_wall = min(to_wall, (ymin - cam_y) / hy)
                if dist < to_wall:
                    level = levels[r, q]
                    px = gx[r, q]
                    py = gy[r, q]
                    wx = car_x + c * px - s * py
                    wy = car_y + s * px + c * py
                    v = 0.0
                    for k in range(n_blur):
                        back = 0.0 if n_blur == 1 else blur_m * k / (n_blur - 1)
                        v += _ground(wx - back * c, wy - back * s, level, pyramid, offsets,
                                     shapes, res, ox, oy, light, mat, line, floor)
                    v = v / n_blur + sheen_map[r, q]
                else:
                    z = cam_h + to_wall * tan_el[r, q]
                    if z >= wall_h:
                        v = 1.25 * wall_dn
                    else:
                        hx = cam_x + to_wall * (c * dxa[r, q] - s * dya[r, q])
                        hy = cam_y + to_wall * (s * dxa[r, q] + c * dya[r, q])
                        # Position along the perimeter: bottom, right, top, left wall.
                        if abs(hy - ymin) < 1e-6 * (1.0 + wall_d) or hy <= ymin:
                            p = hx - xmin
                        elif hx >= xmax - 1e-9:
                            p = wall_w + (hy - ymin)
                        elif hy >= ymax - 1e-9:
                            p = wall_w + wall_d + (xmax - hx)
                        else:
                            p = 2.0 * wall_w + wall_d + (ymax - hy)
                        tc = min(max(int(p / WALL_TEXEL_M), 0), wall_tex.shape[1] - 1)
                        tr = min(max(int(max(z, 0.0) / WALL_TEXEL_M), 0), wall_tex.shape[0] - 1)
                        v = wall_tex[tr, tc] * wall_scale
                if bonnet[r, q]:
                    v = bonnet_dn + refl * v
            v = v * gain_map[r, q]
            if noise_dn > 0.0:
                v += noise_dn * _noise(seed, r * width + q)
            if v <= 0.0:
                out[i, j] = 0
            elif v >= 255.0:
                out[i, j] = 255
            else:
                out[i, j] = int(v + 0.5)


def _effect_vector(fx: Effects) -> np.ndarray:
    return np.array([fx.mat_dn, fx.line_dn, fx.floor_dn, fx.wall_dn, fx.gain, fx.vignetting,
                     fx.noise_dn, fx.glare, fx.bonnet_dn, fx.bonnet_reflectivity])


class Renderer:
    """Renders 752×480 grayscale frames of a ``Scene`` from a car pose.

    ``render(scene, pose)`` gives the full frame; ``render_windows(scene, pose, windows)``
    only the requested ``(x, y, width, height)`` windows [px], identical to crops of it.
    """

    def __init__(self, camera: FisheyeCamera | None = None, bonnet: Bonnet | None = None) -> None:
        self.camera = camera or FisheyeCamera.default()
        self.bonnet = bonnet or Bonnet()
        self.geometry = pixel_geometry(self.camera, self.bonnet)
        self._level_cache: dict[tuple[float, int], np.ndarray] = {}
        self._effect_cache: dict[Effects, tuple[np.ndarray, np.ndarray]] = {}

    def _levels(self, scene: Scene) -> tuple[np.ndarray, np.ndarray]:
        """Per-pixel mip level (int8) for the scene's map, and the sampler's constants:
        [light texels per map texel, 1/texel, 2^-0, 2^-1, ...]."""
        res0 = float(scene.level_res[0])
        n = len(scene.level_res)
        key = (res0, n)
        if key not in self._level_cache:
            lv = np.rint(self.geometry.log2_fp - math.log2(res0))
            self._level_cache[key] = np.clip(lv, 0, n - 1).astype(np.int8)
        consts = np.concatenate(([res0 / LIGHT_RES_M, 1.0 / res0], 0.5 ** np.arange(n)))
        return self._level_cache[key], consts

    def _effect_maps(self, fx: Effects) -> tuple[np.ndarray, np.ndarray]:
        """Per-pixel gain (exposure × vignetting) and floor sheen [DN] for ``fx``."""
        if fx not in self._effect_cache:
            g = self.geometry
            gain = (fx.gain * (1.0 - fx.vignetting * g.radius2)).astype(np.float32)
            sheen = (fx.glare * g.sheen).astype(np.float32)
            if len(self._effect_cache) > 16:
                self._effect_cache.clear()
            self._effect_cache[fx] = (gain, sheen)
        return self._effect_cache[fx]

    @property
    def shape(self) -> tuple[int, int]:
        return self.camera.height, self.camera.width

    def render(self, scene: Scene, pose: tuple[float, float, float], *, speed_m_s: float = 0.0,
               frame_seed: int = 0) -> np.ndarray:
        """Full ``(480, 752)`` uint8 frame for a car at ``pose = (x [m], y [m], yaw [rad])``
        moving at ``speed_m_s`` (for motion blur); ``frame_seed`` fixes the sensor noise."""
        (frame,) = self.render_windows(scene, pose, [(0, 0, self.camera.width,
                                                      self.camera.height)],
                                       speed_m_s=speed_m_s, frame_seed=frame_seed)
        return frame

    def render_windows(self, scene: Scene, pose: tuple[float, float, float],
                       windows: list[tuple[int, int, int, int]], *, speed_m_s: float = 0.0,
                       frame_seed: int = 0) -> list[np.ndarray]:
        """Render only the windows ``(x, y, width, height)`` [px] (inside the image)."""
        x, y, yaw = (float(v) for v in pose)
        if not all(math.isfinite(v) for v in (x, y, yaw, speed_m_s)):
            raise ValueError(f"pose and speed must be finite, got {pose}, {speed_m_s}")
        g = self.geometry
        mount = self.camera.mount
        fx = scene.effects
        faces = obstacle_faces(self.camera, scene.boxes, (x, y, yaw), scene.effects.line_dn)
        levels, consts = self._levels(scene)
        gain_map, sheen_map = self._effect_maps(fx)
        out = []
        for win in windows:
            wx0, wy0, ww, wh = (int(v) for v in win)
            if ww <= 0 or wh <= 0 or wx0 < 0 or wy0 < 0 or wx0 + ww > self.camera.width or (
                    wy0 + wh > self.camera.height):
                raise ValueError(f"window {win} is not inside the {self.camera.width}×"
                                 f"{self.camera.height} image")
            buf = np.empty((wh, ww), np.uint8)
            overlay, mask = _draw_faces(faces, (wx0, wy0, ww, wh))
            _render_window(
                buf, wy0, wx0, g.gx, g.gy, g.rho, g.dx, g.dy, g.tan_el, levels, gain_map,
                sheen_map, g.bonnet, scene.pyramid, scene.level_offset, scene.level_shape,
                consts, scene.origin[0], scene.origin[1], scene.light,
                np.asarray(scene.hall, dtype=np.float64), scene.wall_height_m,
                scene.wall_texture, x, y, yaw, mount.forward_m, mount.lateral_m,
                mount.height_m, speed_m_s * fx.motion_blur_s, _effect_vector(fx),
                np.uint64(frame_seed & 0xFFFFFFFFFFFFFFFF), overlay, mask, mask.size > 1,
            )
            out.append(buf)
        return out

def obstacle_faces(camera: FisheyeCamera, boxes: np.ndarray, pose: tuple[float, float, float],
                   white_dn: float = 255.0) -> list[tuple[np.ndarray, float]]:
    """Visible faces of obstacle boxes ``(n, 8, 3)`` [m] as image polygons [px] with a
    grey level (white carton lit from above), farthest first (painter's order)."""
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
        if dist > 12.0:
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


def _draw_faces(faces: list[tuple[np.ndarray, float]], win: tuple[int, int, int, int]
                ) -> tuple[np.ndarray, np.ndarray]:
    """Obstacle overlay of one window: grey levels and a coverage mask (1×1 if empty)."""
    if not faces:
        return np.zeros((1, 1), np.float32), np.zeros((1, 1), np.uint8)
    x0, y0, w, h = win
    overlay = np.zeros((h, w), np.float32)
    mask = np.zeros((h, w), np.uint8)
    shift = 4  # sub-pixel vertices: 1/16 px
    for uv, shade in faces:
        pts = np.rint((uv - np.array([x0, y0])) * (1 << shift)).astype(np.int32)
        cv2.fillPoly(overlay, [pts], float(shade), lineType=cv2.LINE_8, shift=shift)
        cv2.fillPoly(mask, [pts], 1, lineType=cv2.LINE_8, shift=shift)
    return overlay, mask
