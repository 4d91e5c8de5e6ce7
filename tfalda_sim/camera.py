"""Fisheye camera (OpenCV's Kannala–Brandt model) mounted on the car.

Frames:
- **camera** (OpenCV): x right, y down, z forward [m].
- **car**: x forward, y left, z up [m]; origin on the ground below the rear axle centre.
- **world**: the track's frame, x/y on the mat, z up [m].

Projection (identical to ``cv2.fisheye.projectPoints``): for a camera-frame point,
θ = angle from the optical axis, θ_d = θ·(1 + k1θ² + k2θ⁴ + k3θ⁶ + k4θ⁸), and the pixel is
``K · (θ_d · (x, y)/‖(x, y)‖, 1)``. With D = 0 this is the equidistant fisheye r = f·θ.
A real calibration (``K``, ``D`` from ``cv2.fisheye.calibrate``) plugs in unchanged; its
skew is ``K[0, 1] = α·fx`` (pass ``alpha=K[0, 1] / K[0, 0]`` to
``cv2.fisheye.projectPoints``, which reads only fx, fy, cx, cy from ``K``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

SENSOR_WIDTH_PX: int = 752
"""Image width [px] (thesis 1.1: 752×480 grayscale)."""

SENSOR_HEIGHT_PX: int = 480
"""Image height [px] (thesis 1.1)."""

DEFAULT_HFOV_RAD: float = math.radians(157.5)
"""Default horizontal field of view [rad]: the middle of the thesis' 155–160° lens."""

DEFAULT_MOUNT_HEIGHT_M: float = 0.200
"""Default camera height above the ground [m]. Calibrated with ``DEFAULT_MOUNT_PITCH_RAD``
so that on a straight, centred in the right lane, the lane is 112 px wide at image row
270 (thesis fig. 2.2), the widths at the ROI rows lie in table 2.3's ranges and the ROIs
of table 2.4 hold the ego lane's markings; see ``docs/camera-calibration.md``."""

DEFAULT_MOUNT_PITCH_RAD: float = math.radians(5.5)
"""Default downward tilt [rad]. An untilted camera cannot meet the thesis' widths (with
any radially symmetric lens the width at row v is ∝ (v − c_y), so width(425)/width(270)
would be 6.1 where table 2.3 allows 2.9–4.6); the thesis' camera had "a defined tilt"
(2.1.1). 5.5° puts the horizon at row 213, 27 px above the image middle."""

FRAME_RATE_HZ: float = 50.0
"""Camera frame rate [1/s] (thesis 1.1; REFERENCE.md)."""

DEFAULT_MOUNT_FORWARD_M: float = 0.20
"""Default camera position ahead of the rear axle [m] (roof of a 1:10 car)."""


@dataclass(frozen=True)
class CameraMount:
    """Where the camera sits on the car and how it is turned.

    ``height_m`` above the ground, ``forward_m`` ahead of and ``lateral_m`` left of the
    rear axle centre [m]; ``pitch_rad`` > 0 tilts the view down, ``yaw_rad`` > 0 turns it
    left, ``roll_rad`` > 0 turns the image clockwise (the horizon's right end drops) [rad].
    """

    height_m: float = DEFAULT_MOUNT_HEIGHT_M
    forward_m: float = DEFAULT_MOUNT_FORWARD_M
    lateral_m: float = 0.0
    pitch_rad: float = DEFAULT_MOUNT_PITCH_RAD
    roll_rad: float = 0.0
    yaw_rad: float = 0.0

    def rotation(self) -> np.ndarray:
        """3×3 rotation taking car-frame directions to camera-frame directions."""
        return self._rotation.copy()

    @cached_property
    def _rotation(self) -> np.ndarray:
        base = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
        cp, sp = math.cos(self.pitch_rad), math.sin(self.pitch_rad)
        cy, sy = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        cr, sr = math.cos(self.roll_rad), math.sin(self.roll_rad)
        pitch = np.array([[1.0, 0.0, 0.0], [0.0, cp, -sp], [0.0, sp, cp]])
        yaw = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])
        roll = np.array([[cr, -sr, 0.0], [sr, cr, 0.0], [0.0, 0.0, 1.0]])
        return roll @ pitch @ yaw @ base

    def position(self) -> np.ndarray:
        """Camera centre in the car frame [m]."""
        return self._position.copy()

    @cached_property
    def _position(self) -> np.ndarray:
        return np.array([self.forward_m, self.lateral_m, self.height_m])


def _check_matrix(name: str, value: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.size != int(np.prod(shape)):
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    arr = arr.reshape(shape)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite")
    return arr


@dataclass(frozen=True, eq=False)  # array fields: identity equality, hashable
class FisheyeCamera:
    """A Kannala–Brandt fisheye camera: intrinsics ``K`` (3×3), distortion ``D``
    (k1..k4), image size [px] and its mount on the car."""

    K: np.ndarray
    D: np.ndarray
    width: int = SENSOR_WIDTH_PX
    height: int = SENSOR_HEIGHT_PX
    mount: CameraMount = field(default_factory=CameraMount)

    def __post_init__(self) -> None:
        object.__setattr__(self, "K", _check_matrix("K", self.K, (3, 3)))
        object.__setattr__(self, "D", _check_matrix("D", self.D, (4,)))
        if self.K[0, 0] <= 0 or self.K[1, 1] <= 0:
            raise ValueError("K must have positive focal lengths fx, fy")
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"image size must be positive, got {self.width}×{self.height}")

    @classmethod
    def default(cls, mount: CameraMount | None = None) -> FisheyeCamera:
        """752×480 equidistant fisheye with a 157.5° horizontal field of view, looking
        ahead and tilted 5.5° down, mounted 0.20 m high: calibrated to the thesis."""
        f = (SENSOR_WIDTH_PX / 2) / (DEFAULT_HFOV_RAD / 2)
        K = np.array([[f, 0.0, (SENSOR_WIDTH_PX - 1) / 2],
                      [0.0, f, (SENSOR_HEIGHT_PX - 1) / 2],
                      [0.0, 0.0, 1.0]])
        return cls(K, np.zeros(4), mount=mount or CameraMount())

    def with_mount(self, **changes: float) -> FisheyeCamera:
        """The same lens on a changed mount, e.g. ``cam.with_mount(height_m=0.15)``."""
        return replace(self, mount=replace(self.mount, **changes))

    # ---------------------------------------------------------------- projection
    def project(self, points: np.ndarray) -> np.ndarray:
        """``(N, 3)`` camera-frame points [m] → ``(N, 2)`` pixels (u, v); NaN where a
        point is behind the lens (z ≤ 0)."""
        p = np.asarray(points, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != 3:
            raise ValueError(f"project expects an (N, 3) array of points, got {p.shape}")
        x, y, z = p[:, 0], p[:, 1], p[:, 2]
        r = np.hypot(x, y)
        theta = np.arctan2(r, z)
        t2 = theta * theta
        k1, k2, k3, k4 = self.D
        theta_d = theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
        with np.errstate(invalid="ignore", divide="ignore"):
            scale = np.where(r > 1e-12, theta_d / np.where(r > 1e-12, r, 1.0), 1.0 / np.where(
                z > 0, z, 1.0))
        xd, yd = x * scale, y * scale
        K = self.K
        uv = np.column_stack([K[0, 0] * (xd + K[0, 1] / K[0, 0] * yd) + K[0, 2],
                              K[1, 1] * yd + K[1, 2]])
        uv[z <= 0] = np.nan
        return uv

    def unproject(self, pixels: np.ndarray) -> np.ndarray:
        """``(N, 2)`` pixels → ``(N, 3)`` unit rays in the camera frame (inverse of
        ``project``; θ is recovered by Newton's method)."""
        uv = np.asarray(pixels, dtype=np.float64)
        if uv.ndim != 2 or uv.shape[1] != 2:
            raise ValueError(f"unproject expects an (N, 2) array of pixels, got {uv.shape}")
        K = self.K
        yd = (uv[:, 1] - K[1, 2]) / K[1, 1]
        xd = (uv[:, 0] - K[0, 2] - K[0, 1] * yd) / K[0, 0]
        theta_d = np.hypot(xd, yd)
        k1, k2, k3, k4 = self.D
        theta = theta_d.copy()
        for _ in range(20):
            t2 = theta * theta
            f = theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))) - theta_d
            df = 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))
            theta = theta - f / df
        with np.errstate(invalid="ignore", divide="ignore"):
            s = np.where(theta_d > 1e-12, np.sin(theta) / np.where(theta_d > 1e-12, theta_d, 1), 1)
        return np.column_stack([xd * s, yd * s, np.cos(theta)])

    # ---------------------------------------------------------------- frames
    def car_to_camera(self, points_car: np.ndarray) -> np.ndarray:
        """``(N, 3)`` car-frame points [m] → camera frame [m]."""
        p = np.asarray(points_car, dtype=np.float64)
        return (p - self.mount._position) @ self.mount._rotation.T

    def world_to_camera(self, points_world: np.ndarray, car_pose: tuple[float, float, float]
                        ) -> np.ndarray:
        """``(N, 3)`` world points [m] seen from a car at ``(x [m], y [m], yaw [rad])``."""
        x, y, yaw = car_pose
        p = np.asarray(points_world, dtype=np.float64)
        c, s = math.cos(yaw), math.sin(yaw)
        # World → car (rotate by −yaw about the car) → camera, as one affine map.
        world_to_car = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
        rot = self.mount._rotation @ world_to_car
        origin = np.array([x, y, 0.0]) + world_to_car.T @ self.mount._position
        return (p - origin) @ rot.T

    def project_world(self, points_world: np.ndarray, car_pose: tuple[float, float, float]
                      ) -> np.ndarray:
        """World points [m] → pixels, for a car at ``car_pose``; NaN behind the lens."""
        return self.project(self.world_to_camera(points_world, car_pose))

    def pixels_to_ground(self, pixels: np.ndarray) -> np.ndarray:
        """``(N, 2)`` pixels → the ``(N, 2)`` points (x forward, y left) [m] of the flat
        ground they see, in the car frame; NaN where the ray does not reach the ground."""
        rays = self.unproject(pixels) @ self.mount._rotation
        pos = self.mount._position
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(rays[:, 2] < -1e-9, -pos[2] / rays[:, 2], np.nan)
        return np.column_stack([pos[0] + t * rays[:, 0], pos[1] + t * rays[:, 1]])

    def pixel_rays_car(self) -> np.ndarray:
        """Unit ray of every pixel centre in the car frame, ``(height, width, 3)``."""
        v, u = np.mgrid[0:self.height, 0:self.width].astype(np.float64)
        rays = self.unproject(np.column_stack([u.ravel(), v.ravel()]))
        return (rays @ self.mount.rotation()).reshape(self.height, self.width, 3)
