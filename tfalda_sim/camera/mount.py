"""Where the camera sits on the car and how it is turned, and the thesis camera's numbers.

Frames:
- **camera** (OpenCV): x right, y down, z forward [m].
- **car**: x forward, y left, z up [m]; origin on the ground below the rear axle centre.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .limits import (
    MAX_MOUNT_ANGLE_RAD,
    MAX_MOUNT_FORWARD_M,
    MAX_MOUNT_HEIGHT_M,
    MAX_MOUNT_LATERAL_M,
    MIN_MOUNT_HEIGHT_M,
    check_range,
)

__all__ = ["DEFAULT_HFOV_RAD", "DEFAULT_MOUNT_FORWARD_M", "DEFAULT_MOUNT_HEIGHT_M",
           "DEFAULT_MOUNT_PITCH_RAD", "FRAME_RATE_HZ", "MAX_MOUNT_ANGLE_RAD",
           "MAX_MOUNT_HEIGHT_M", "SENSOR_HEIGHT_PX", "SENSOR_WIDTH_PX", "CameraMount"]

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

    def __post_init__(self) -> None:
        for name in ("height_m", "forward_m", "lateral_m", "pitch_rad", "roll_rad", "yaw_rad"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.floating,
                                                                 np.integer)):
                raise TypeError(f"mount.{name} must be a number, got {value!r}")
            if not math.isfinite(value):
                raise ValueError(f"mount.{name} must be finite, got {value}")
        check_range("mount.height_m", self.height_m, MIN_MOUNT_HEIGHT_M, MAX_MOUNT_HEIGHT_M,
                    "m", "above the ground, on a 1:10 car")
        check_range("mount.forward_m", self.forward_m, -MAX_MOUNT_FORWARD_M,
                    MAX_MOUNT_FORWARD_M, "m", "ahead of the rear axle, on a 1:10 car")
        check_range("mount.lateral_m", self.lateral_m, -MAX_MOUNT_LATERAL_M,
                    MAX_MOUNT_LATERAL_M, "m", "left of the centre line, on a 1:10 car")
        for name in ("pitch_rad", "roll_rad", "yaw_rad"):
            if abs(getattr(self, name)) >= MAX_MOUNT_ANGLE_RAD:
                limit = math.degrees(MAX_MOUNT_ANGLE_RAD)
                value = math.degrees(getattr(self, name))
                raise ValueError(f"mount.{name} must lie within ±{limit:.0f}° (a camera looking "
                                 f"ahead at the road), got {value:.1f}°")
