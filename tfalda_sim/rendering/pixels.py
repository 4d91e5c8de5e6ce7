"""The pixel geometry of a camera on the car: the bonnet in the image and each pixel's
ray, ground hit, footprint and shading weights — constants per camera, computed once,
used by the renderer, the ground truth, the evaluation and the env."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..camera import Bonnet, Camera

__all__ = ["Bonnet", "PixelGeometry", "pixel_geometry"]


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


PIXEL_GEOMETRIES_KEPT: int = 4
"""Pixel geometries kept per process (≈ 13 MB each for 752×480): computing one takes
1–2 s (a Newton inversion of the lens for 5 × 360 k rays), and every renderer, so every
env, needs its camera's."""

_KEPT: dict[tuple, PixelGeometry] = {}


def _key(camera: Camera, bonnet: Bonnet) -> tuple:
    """What the pixel geometry depends on, by value (a camera read from its profile file
    again is a new object with the same numbers)."""
    polygon = None if bonnet.polygon_px is None else np.asarray(bonnet.polygon_px).tobytes()
    return (type(camera), camera.K.tobytes(), camera.D.tobytes(), camera.width,
            camera.height, camera.mount, bonnet.top_row, bonnet.edge_drop_px,
            bonnet.enabled, polygon)


def pixel_geometry(camera: Camera, bonnet: Bonnet | None = None) -> PixelGeometry:
    """The per-pixel constants of ``camera`` (the camera's own bonnet unless ``bonnet`` is
    given): computed once per camera and bonnet values and kept (``PIXEL_GEOMETRIES_KEPT``,
    arrays read-only)."""
    bonnet = bonnet or camera.bonnet
    key = _key(camera, bonnet)
    geometry = _KEPT.get(key)
    if geometry is None:
        geometry = _compute(camera, bonnet)
        for value in vars(geometry).values():
            value.flags.writeable = False
        if len(_KEPT) >= PIXEL_GEOMETRIES_KEPT:
            _KEPT.pop(next(iter(_KEPT)))
        _KEPT[key] = geometry
    return geometry


def _compute(camera: Camera, bonnet: Bonnet) -> PixelGeometry:
    h, w = camera.height, camera.width
    pos = camera.mount.position()
    rot = camera.mount.rotation()

    def ground(u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        rays = camera.unproject(np.column_stack([u.ravel(), v.ravel()])) @ rot
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(rays[:, 2] < -1e-9, -pos[2] / rays[:, 2], np.nan)
        return rays, pos[0] + t * rays[:, 0], pos[1] + t * rays[:, 1]

    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    edge = bonnet.edge(u, w, h)
    on_bonnet = v >= edge
    v_geo = np.where(on_bonnet, 2.0 * np.where(on_bonnet, edge, 0.0) - v, v)  # mirrored
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
