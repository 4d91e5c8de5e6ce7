"""The perception domain's command-line helpers (it has no command of its own): a
``--camera`` checked against what the detectors need, before any work."""

from __future__ import annotations

from ..camera import Camera
from ..camera.command import resolve_camera_arg
from ..cli_common import CliError
from .geometry import CameraGeometryError
from .hough import HoughConfig
from .params import DetectorConfig


def check_camera_geometry(text: str) -> Camera:
    """The camera of ``--camera``, refused (``CliError``) when either detector's layout
    cannot be derived for it (it does not see the lane)."""
    camera = resolve_camera_arg(text)
    try:
        DetectorConfig.for_camera(camera)
        HoughConfig.for_camera(camera)
    except CameraGeometryError as exc:
        raise CliError(f"--camera {text}: {exc}") from None
    return camera
