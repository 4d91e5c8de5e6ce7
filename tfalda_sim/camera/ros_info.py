"""A camera's intrinsics as ROS's ``sensor_msgs/CameraInfo`` and back: recordings carry
them on a ``camera_info`` topic (``sources.CameraInfo``), which ``camera fit`` and replay
take as the lens of a team's footage."""

from __future__ import annotations

import numpy as np

from ..sources import CameraInfo
from .models import Camera, LensModel

ROS_DISTORTION_MODELS: dict[LensModel, str] = {LensModel.FISHEYE: "equidistant",
                                                LensModel.PINHOLE: "plumb_bob"}
"""ROS's ``distortion_model`` of each lens model (OpenCV's fisheye is ROS's equidistant,
its 5-coefficient pinhole ROS's plumb_bob)."""

LENS_OF_ROS_MODEL: dict[str, LensModel] = {name: lens
                                           for lens, name in ROS_DISTORTION_MODELS.items()}
"""The lens model of each ROS ``distortion_model`` read (camera_info files and topics)."""


def camera_info_of(camera: Camera) -> CameraInfo:
    """``camera``'s size, K and D as a recording's camera_info."""
    return CameraInfo(width_px=int(camera.width), height_px=int(camera.height),
                      K=np.array(camera.K, np.float64).reshape(3, 3),
                      D=np.array(camera.D, np.float64).ravel(),
                      distortion_model=ROS_DISTORTION_MODELS[camera.lens])
