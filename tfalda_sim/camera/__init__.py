"""Cameras: lens models (fisheye, pinhole), the mount on the car, the car's body in view,
and camera profiles — files that hold all of it (``load_camera``, ``save_camera``; named
profiles ``thesis`` and ``reference-car``; readers for OpenCV and ROS calibration files).
See ``docs/cameras.md``."""

from .bonnet import Bonnet
from .models import Camera, FisheyeCamera, LensModel, PinholeCamera
from .mount import (
    DEFAULT_HFOV_RAD,
    DEFAULT_MOUNT_FORWARD_M,
    DEFAULT_MOUNT_HEIGHT_M,
    DEFAULT_MOUNT_PITCH_RAD,
    FRAME_RATE_HZ,
    SENSOR_HEIGHT_PX,
    SENSOR_WIDTH_PX,
    CameraMount,
)
from .profile import (
    NAMED_CAMERAS,
    CameraFileError,
    load_camera,
    load_intrinsics,
    save_camera,
)

__all__ = [
    "DEFAULT_HFOV_RAD", "DEFAULT_MOUNT_FORWARD_M", "DEFAULT_MOUNT_HEIGHT_M",
    "DEFAULT_MOUNT_PITCH_RAD", "FRAME_RATE_HZ", "NAMED_CAMERAS", "SENSOR_HEIGHT_PX",
    "SENSOR_WIDTH_PX", "Bonnet", "Camera", "CameraFileError", "CameraMount", "FisheyeCamera",
    "LensModel", "PinholeCamera", "load_camera", "load_intrinsics", "save_camera",
]
