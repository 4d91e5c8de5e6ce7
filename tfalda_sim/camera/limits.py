"""Plausible ranges of a camera's numbers: what a camera on a 1:10 Carolo-Cup car can
have. A value outside is a typo, a wrong unit or a calibration of another image size, and
would make a drive, a render or a fit silently meaningless; ``Camera``, ``CameraMount``
and ``Bonnet`` refuse it when built, camera files when loaded, each error naming the
field, the value and the range (``check_intrinsics`` takes the field names the caller's
user wrote: a profile's keys or the API's arguments).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

MIN_IMAGE_SIDE_PX: int = 64
"""Smallest image width or height [px]: the detectors split the image into ROI rows tens
of pixels high (thesis table 2.4: 85 px of 480); below 64 px a 20 mm marking is not
resolved at all."""

MAX_IMAGE_SIDE_PX: int = 8192
"""Largest image width or height [px]: per-pixel tables are built per camera (8K is
beyond any camera a model car carries)."""

MIN_FRAME_RATE_HZ: float = 5.0
"""Slowest frame rate [1/s]: at 5 frames/s a car at 2 m/s moves 0.4 m — a lane's width —
between frames, the detectors' frame-to-frame tracking has nothing to follow and a drive's
step budget rounds to almost no frames (a rate of 0.001 ran 0 steps)."""

MAX_FRAME_RATE_HZ: float = 1000.0
"""Fastest frame rate [1/s]: faster than any camera on a model car; each frame is
rendered, so a second of driving would cost more than a thousand renders."""

FOCAL_PER_WIDTH: tuple[float, float] = (0.1, 10.0)
"""fx as a multiple of the image width [px/px]: at 0.1 × width an equidistant fisheye
would span 10 rad (570°) across the image, more than any lens; at 10 × width a pinhole
sees 5.7° across, too narrow to see a 0.4 m lane nearer than 4 m. Outside: a focal
length of another image size (a calibration at another resolution) or of another unit."""

PIXEL_ASPECT: tuple[float, float] = (0.5, 2.0)
"""fy / fx [1]: 1 for square pixels, a few per cent off in a calibration; beyond a factor
2 one of them belongs to a scaled image."""

MAX_SKEW: float = 0.1
"""Largest |K[0, 1] / fx| [1] (a fisheye calibration's skew α): calibrations give
|α| < 0.01; 0.1 tilts the pixel axes by 5.7°, no sensor does."""

MAX_RADIAL_COEFFICIENT: float = 10.0
"""Largest |k| of a radial distortion coefficient [1] (fisheye k1..k4, pinhole k1, k2,
k3): strong wide-angle calibrations reach a few units; ten and more is a diverged fit or
another model's coefficients (the rational model's k4..k6 read as these)."""

MAX_TANGENTIAL_COEFFICIENT: float = 0.1
"""Largest |p1|, |p2| of a pinhole calibration [1]: the lens' decentring, a few 1e-3 in
practice; 0.1 shifts an image corner by ~10 % of the focal length."""

MIN_MOUNT_HEIGHT_M: float = 0.02
"""Lowest camera above the ground [m]: a 1:10 car's ground clearance plus a lens' radius;
lower is a wrong sign or unit (mm as m)."""

MAX_MOUNT_HEIGHT_M: float = 2.0
"""Highest camera above the ground [m]: ten times a 1:10 car's roof; higher is a wrong
unit."""

MAX_MOUNT_FORWARD_M: float = 1.0
"""Largest |forward_m|, the camera ahead of (or behind) the rear axle [m]: twice a 1:10
car's length (0.45 m); farther it is not on the car."""

MAX_MOUNT_LATERAL_M: float = 0.5
"""Largest |lateral_m|, the camera left or right of the car's centre line [m]: 2.5 times
a 1:10 car's half width (0.1 m); farther it is not on the car."""

MAX_MOUNT_ANGLE_RAD: float = math.radians(80.0)
"""Largest mount pitch, roll or yaw [rad]: beyond it the camera looks at the ground under
the car or at the sky, and the mount's angle order stops meaning much."""

MIN_BONNET_TOP_SHARE: float = 0.5
"""The car's body may reach no higher than this share of the image height from the top
[1]: a body over the upper half hides the road ahead (the thesis camera's bonnet starts at
row 440 of 480, 92 %)."""

_COEFFICIENTS = {4: ("k1", "k2", "k3", "k4"), 5: ("k1", "k2", "p1", "p2", "k3")}

API_NAMES: Mapping[str, str] = {
    "width": "image width", "height": "image height", "fx": "fx = K[0, 0]",
    "fy": "fy = K[1, 1]", "skew": "skew K[0, 1]", "cx": "cx = K[0, 2]", "cy": "cy = K[1, 2]",
    "D": "D", "frame_rate_hz": "frame_rate_hz"}
"""Field names in errors of ``Camera(...)``."""

PROFILE_NAMES: Mapping[str, str] = {
    "width": "image_width_px", "height": "image_height_px",
    "fx": "camera_matrix[0][0] (fx)", "fy": "camera_matrix[1][1] (fy)",
    "skew": "camera_matrix[0][1] (skew)", "cx": "camera_matrix[0][2] (cx)",
    "cy": "camera_matrix[1][2] (cy)", "D": "distortion", "frame_rate_hz": "frame_rate_hz"}
"""Field names in errors of a profile file."""

CALIBRATION_NAMES: Mapping[str, str] = {
    **PROFILE_NAMES, "width": "image_width", "height": "image_height",
    "D": "distortion_coefficients"}
"""Field names in errors of an OpenCV or ROS calibration file."""


def check_range(name: str, value: float, low: float, high: float, unit: str, why: str) -> None:
    """Refuse (``ValueError``) ``value`` outside ``[low, high]``, naming ``name``, the
    value, the range and ``why``."""
    if not low <= value <= high:
        raise ValueError(f"{name} must be in [{low:g}, {high:g}]{' ' + unit if unit else ''} "
                         f"({why}), got {value:g}")


def check_intrinsics(K: np.ndarray, D: np.ndarray, width: int, height: int,
                     frame_rate_hz: float | None,
                     names: Mapping[str, str] = API_NAMES) -> None:
    """Refuse (``ValueError``) intrinsics no camera on a model car has; ``K`` is 3×3,
    ``D`` 4 (fisheye) or 5 (pinhole) coefficients, both finite; ``frame_rate_hz`` None: not
    checked (a calibration file has none)."""
    for key, side in (("width", width), ("height", height)):
        check_range(names[key], side, MIN_IMAGE_SIDE_PX, MAX_IMAGE_SIDE_PX, "px",
                    "a model car's camera image")
    fx, fy, skew, cx, cy = K[0, 0], K[1, 1], K[0, 1], K[0, 2], K[1, 2]
    lo, hi = FOCAL_PER_WIDTH
    check_range(names["fx"], fx, lo * width, hi * width, "px",
                f"{lo:g}–{hi:g} × the {width} px width: fields of view from 570° to 5.7°; "
                "is K for another image size?")
    lo, hi = PIXEL_ASPECT
    check_range(names["fy"], fy, lo * fx, hi * fx, "px",
                f"{lo:g}–{hi:g} × fx: pixels at most twice as tall as wide")
    check_range(names["skew"], skew, -MAX_SKEW * fx, MAX_SKEW * fx, "px",
                f"|skew| ≤ {MAX_SKEW:g} × fx")
    check_range(names["cx"], cx, -0.5, width - 0.5, "px",
                f"the principal point lies in the {width}×{height} image; is K for another "
                "image size?")
    check_range(names["cy"], cy, -0.5, height - 0.5, "px",
                f"the principal point lies in the {width}×{height} image; is K for another "
                "image size?")
    coefficients = _COEFFICIENTS[len(D)]
    for i, (label, value) in enumerate(zip(coefficients, D, strict=True)):
        limit = MAX_TANGENTIAL_COEFFICIENT if label.startswith("p") else MAX_RADIAL_COEFFICIENT
        kind = "a tangential" if label.startswith("p") else "a radial"
        check_range(f"{names['D']}[{i}] ({label})", float(value), -limit, limit, "",
                    f"{kind} distortion coefficient of a real lens; another model's or a "
                    "diverged fit's?")
    if frame_rate_hz is not None:
        check_range(names["frame_rate_hz"], frame_rate_hz, MIN_FRAME_RATE_HZ,
                    MAX_FRAME_RATE_HZ, "Hz", "a model car's camera")
