"""Camera lens models: OpenCV's fisheye (Kannala–Brandt) and its standard pinhole model
with radial-tangential distortion, each with its mount on the car and the car's body in
view.

Frames:
- **camera** (OpenCV): x right, y down, z forward [m].
- **car**: x forward, y left, z up [m]; origin on the ground below the rear axle centre.
- **world**: the track's frame, x/y on the mat, z up [m].

Fisheye (identical to ``cv2.fisheye.projectPoints``): for a camera-frame point,
θ = angle from the optical axis, θ_d = θ·(1 + k1θ² + k2θ⁴ + k3θ⁶ + k4θ⁸), and the pixel is
``K · (θ_d · (x, y)/‖(x, y)‖, 1)``. With D = 0 this is the equidistant fisheye r = f·θ.
A real calibration (``K``, ``D`` from ``cv2.fisheye.calibrate``) plugs in unchanged; its
skew is ``K[0, 1] = α·fx`` (pass ``alpha=K[0, 1] / K[0, 0]`` to
``cv2.fisheye.projectPoints``, which reads only fx, fy, cx, cy from ``K``).

Pinhole (identical to ``cv2.projectPoints``, OpenCV's 5-coefficient model, ROS'
``plumb_bob``): x' = x/z, y' = y/z, r² = x'² + y'²,
x'' = x'(1 + k1r² + k2r⁴ + k3r⁶) + 2p1x'y' + p2(r² + 2x'²),
y'' = y'(1 + k1r² + k2r⁴ + k3r⁶) + p1(r² + 2y'²) + 2p2x'y', pixel ``K · (x'', y'', 1)``
(``K[0, 1]`` must be 0: OpenCV's calibration never estimates a pinhole skew).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from enum import Enum

import cv2
import numpy as np

from .bonnet import Bonnet
from .limits import MAX_FRAME_RATE_HZ, MAX_IMAGE_SIDE_PX, MIN_IMAGE_SIDE_PX, check_intrinsics
from .mount import (
    DEFAULT_HFOV_RAD,
    FRAME_RATE_HZ,
    SENSOR_HEIGHT_PX,
    SENSOR_WIDTH_PX,
    CameraMount,
)

__all__ = ["MAX_FRAME_RATE_HZ", "MAX_IMAGE_SIDE_PX", "MIN_IMAGE_SIDE_PX", "Camera",
           "FisheyeCamera", "LensModel", "PinholeCamera"]

UNPROJECT_TOLERANCE_PX: float = 1e-3
"""A pinhole pixel whose ray projects back further off than this [px] has no ray."""

PINHOLE_MIN_Z_M: float = 1e-6
"""A pinhole camera sees points at least this far in front of its centre [m]; nearer or
behind project to NaN."""


class LensModel(Enum):
    """The distortion model of a camera's intrinsics."""

    FISHEYE = "fisheye"
    """OpenCV's ``cv2.fisheye`` (Kannala–Brandt k1..k4); ROS ``equidistant``."""
    PINHOLE = "pinhole"
    """OpenCV's standard model (k1, k2, p1, p2, k3); ROS ``plumb_bob``."""


def _check_matrix(name: str, value: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.size != int(np.prod(shape)):
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    arr = arr.reshape(shape).copy()
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite")
    return arr


@dataclass(frozen=True, eq=False)  # array fields: identity equality, hashable
class Camera:
    """A calibrated camera on the car: intrinsics ``K`` (3×3) and distortion ``D``, the
    image size [px], the mount, the car's body in the image (``bonnet``) and the frame
    rate [1/s]. Use ``FisheyeCamera`` or ``PinholeCamera``; ``tfalda_sim.camera.
    load_camera`` reads either from a profile file."""

    K: np.ndarray
    D: np.ndarray
    width: int = SENSOR_WIDTH_PX
    height: int = SENSOR_HEIGHT_PX
    mount: CameraMount = field(default_factory=CameraMount)
    bonnet: Bonnet | None = None
    """The car's body in the image; ``None``: the thesis camera's parabola on a 752×480
    image (it is in pixels of that size), no body on any other."""
    frame_rate_hz: float = FRAME_RATE_HZ

    lens: LensModel = field(init=False, repr=False, default=LensModel.FISHEYE)
    n_distortion: int = field(init=False, repr=False, default=4)

    def __post_init__(self) -> None:
        object.__setattr__(self, "K", _check_matrix("K", self.K, (3, 3)))
        object.__setattr__(self, "D", _check_matrix("D", self.D, (self.n_distortion,)))
        self.K.setflags(write=False)
        self.D.setflags(write=False)
        if not (self.K[0, 0] > 0 and self.K[1, 1] > 0):
            raise ValueError("K must have positive focal lengths fx = K[0, 0] and fy = K[1, 1] "
                             f"[px], got {self.K[0, 0]:g}, {self.K[1, 1]:g}")
        if not np.array_equal(self.K[2], [0.0, 0.0, 1.0]) or self.K[1, 0] != 0:
            raise ValueError("K must be upper triangular with last row [0, 0, 1], got "
                             f"{self.K.tolist()}")
        for name in ("width", "height"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise TypeError(f"image {name} must be an integer [px], got {value!r}")
        rate = self.frame_rate_hz
        if isinstance(rate, bool) or not isinstance(rate, (int, float, np.integer, np.floating)):
            raise TypeError(f"frame_rate_hz must be a number [1/s], got {rate!r}")
        if not math.isfinite(rate):
            raise ValueError(f"frame_rate_hz must be finite, got {rate}")
        check_intrinsics(self.K, self.D, int(self.width), int(self.height), float(rate))
        if not isinstance(self.mount, CameraMount):
            raise TypeError(f"mount must be a CameraMount, got {type(self.mount).__name__}")
        if self.bonnet is None:
            thesis_size = (self.width, self.height) == (SENSOR_WIDTH_PX, SENSOR_HEIGHT_PX)
            object.__setattr__(self, "bonnet", Bonnet() if thesis_size else Bonnet.none())
        if not isinstance(self.bonnet, Bonnet):
            raise TypeError(f"bonnet must be a Bonnet, got {type(self.bonnet).__name__}")
        self.bonnet.check_inside(self.width, self.height)

    def __setstate__(self, state: dict) -> None:
        # A pickled or copied camera keeps its arrays read-only (caches key on identity).
        self.__dict__.update(state)
        self.K.setflags(write=False)
        self.D.setflags(write=False)

    def with_mount(self, **changes: float) -> Camera:
        """The same lens on a changed mount, e.g. ``cam.with_mount(height_m=0.15)``."""
        return replace(self, mount=replace(self.mount, **changes))

    def replace(self, **changes: object) -> Camera:
        """A copy with fields changed (``mount``, ``bonnet``, ``K``, …)."""
        return replace(self, **changes)

    def project(self, points: np.ndarray) -> np.ndarray:
        """``(N, 3)`` camera-frame points [m] → ``(N, 2)`` pixels (u, v); NaN where the
        lens does not see a point."""
        raise NotImplementedError

    def unproject(self, pixels: np.ndarray) -> np.ndarray:
        """``(N, 2)`` pixels → ``(N, 3)`` unit rays in the camera frame."""
        raise NotImplementedError

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


@dataclass(frozen=True, eq=False)
class FisheyeCamera(Camera):
    """A Kannala–Brandt fisheye camera (``cv2.fisheye``): ``D`` = (k1, k2, k3, k4)."""

    @classmethod
    def default(cls, mount: CameraMount | None = None) -> FisheyeCamera:
        """752×480 equidistant fisheye with a 157.5° horizontal field of view, looking
        ahead and tilted 5.5° down, mounted 0.20 m high: calibrated to the thesis."""
        f = (SENSOR_WIDTH_PX / 2) / (DEFAULT_HFOV_RAD / 2)
        K = np.array([[f, 0.0, (SENSOR_WIDTH_PX - 1) / 2],
                      [0.0, f, (SENSOR_HEIGHT_PX - 1) / 2],
                      [0.0, 0.0, 1.0]])
        return cls(K, np.zeros(4), mount=mount or CameraMount())

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
        # Newton's method, per pixel until its step is 0 (then every further step would be
        # 0 too, so leaving it out changes nothing): at once for the equidistant lens.
        act = np.arange(len(theta))
        for _ in range(20):
            th, td = theta[act], theta_d[act]
            t2 = th * th
            f = th * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))) - td
            df = 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))
            step = f / df
            theta[act] = th - step
            act = act[step != 0]
            if not len(act):
                break
        with np.errstate(invalid="ignore", divide="ignore"):
            s = np.where(theta_d > 1e-12, np.sin(theta) / np.where(theta_d > 1e-12, theta_d, 1), 1)
        return np.column_stack([xd * s, yd * s, np.cos(theta)])


@dataclass(frozen=True, eq=False)
class PinholeCamera(Camera):
    """OpenCV's standard camera model (``cv2.projectPoints``): ``D`` = (k1, k2, p1, p2,
    k3). A 4-entry ``D`` from a calibration is (k1, k2, p1, p2) with k3 = 0: pass it as
    ``np.append(D, 0)``."""

    lens: LensModel = field(init=False, repr=False, default=LensModel.PINHOLE)
    n_distortion: int = field(init=False, repr=False, default=5)

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.K[0, 1] != 0:
            raise ValueError(f"a pinhole K must have no skew (K[0, 1] = 0), got {self.K[0, 1]:g}")

    def project(self, points: np.ndarray) -> np.ndarray:
        """``(N, 3)`` camera-frame points [m] → ``(N, 2)`` pixels (u, v); NaN where a
        point is not in front of the lens (z < 1 µm)."""
        p = np.asarray(points, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != 3:
            raise ValueError(f"project expects an (N, 3) array of points, got {p.shape}")
        z = p[:, 2]
        front = z >= PINHOLE_MIN_Z_M
        zz = np.where(front, z, 1.0)
        xp, yp = p[:, 0] / zz, p[:, 1] / zz
        k1, k2, p1, p2, k3 = self.D
        r2 = xp * xp + yp * yp
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xpp = xp * radial + 2 * p1 * xp * yp + p2 * (r2 + 2 * xp * xp)
        ypp = yp * radial + p1 * (r2 + 2 * yp * yp) + 2 * p2 * xp * yp
        K = self.K
        uv = np.column_stack([K[0, 0] * xpp + K[0, 2], K[1, 1] * ypp + K[1, 2]])
        uv[~front] = np.nan
        return uv

    def unproject(self, pixels: np.ndarray) -> np.ndarray:
        """``(N, 2)`` pixels → ``(N, 3)`` unit rays in the camera frame (z > 0); the
        distortion is inverted by Newton's method from ``cv2.undistortPoints``' estimate
        (its fixed-point iteration stops at a few 1e-4 px for strong distortion). NaN for
        a pixel no ray reaches (past the distortion polynomial's turning point)."""
        uv = np.asarray(pixels, dtype=np.float64)
        if uv.ndim != 2 or uv.shape[1] != 2:
            raise ValueError(f"unproject expects an (N, 2) array of pixels, got {uv.shape}")
        if len(uv) == 0:
            return np.zeros((0, 3))
        K = self.K
        xd = (uv[:, 0] - K[0, 2]) / K[0, 0]
        yd = (uv[:, 1] - K[1, 2]) / K[1, 1]
        x, y = cv2.undistortPoints(uv.reshape(-1, 1, 2), K, self.D).reshape(-1, 2).T.copy()
        k1, k2, p1, p2, k3 = self.D
        # Newton's method, per pixel until its step is 0 (then every further step would be
        # 0 too, so leaving it out changes nothing).
        act = np.arange(len(x))
        for _ in range(8):
            xa, ya, xda, yda = x[act], y[act], xd[act], yd[act]
            r2 = xa * xa + ya * ya
            radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
            dradial = k1 + r2 * (2 * k2 + r2 * 3 * k3)  # d radial / d r2
            fx = xa * radial + 2 * p1 * xa * ya + p2 * (r2 + 2 * xa * xa) - xda
            fy = ya * radial + p1 * (r2 + 2 * ya * ya) + 2 * p2 * xa * ya - yda
            j11 = radial + 2 * xa * xa * dradial + 2 * p1 * ya + 6 * p2 * xa
            j12 = 2 * xa * ya * dradial + 2 * p1 * xa + 2 * p2 * ya
            j21 = 2 * xa * ya * dradial + 2 * p1 * xa + 2 * p2 * ya
            j22 = radial + 2 * ya * ya * dradial + 6 * p1 * ya + 2 * p2 * xa
            det = j11 * j22 - j12 * j21
            with np.errstate(divide="ignore", invalid="ignore"):
                step_x = (j22 * fx - j12 * fy) / det
                step_y = (j11 * fy - j21 * fx) / det
                x[act] = xa - step_x
                y[act] = ya - step_y
            act = act[(step_x != 0) | (step_y != 0)]
            if not len(act):
                break
        rays = np.column_stack([x, y, np.ones(len(x))])
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        # Beyond the distortion polynomial's turning point no ray maps to the pixel:
        # NaN there, not a wrong ray.
        with np.errstate(invalid="ignore"):
            back = self.project(rays)
            bad = ~(np.hypot(*(back - uv).T) <= UNPROJECT_TOLERANCE_PX)
        rays[bad] = np.nan
        return rays
