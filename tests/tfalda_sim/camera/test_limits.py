"""Every camera profile field has a plausible range (``tfalda_sim.camera.limits``): a value
at the limit loads, one just beyond is refused naming the field, the value and the
range — in a profile, through the API and through the commands."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from tests.cli_helpers import tfalda
from tfalda_sim.camera import (
    Bonnet,
    CameraFileError,
    CameraMount,
    FisheyeCamera,
    PinholeCamera,
    load_camera,
)
from tfalda_sim.camera import limits as L
from tfalda_sim.camera.profile import profile_dict

FISHEYE = FisheyeCamera.default()  # 752×480, fx = fy = 273.6, principal point (375.5, 239.5)
PINHOLE = PinholeCamera(np.array([[421.3, 0.0, 320.0], [0.0, 420.8, 200.0], [0.0, 0.0, 1.0]]),
                        np.zeros(5), width=640, height=400, bonnet=Bonnet.none())
FX = float(FISHEYE.K[0, 0])


def _set(data: dict[str, Any], key: str, value: Any) -> None:
    """``key`` as a path: ``mount.height_m``, ``camera_matrix.0.2``, ``distortion.3``."""
    *head, last = key.split(".")
    target: Any = data
    for part in head:
        target = target[int(part)] if part.isdigit() else target[part]
    if last.isdigit():
        target[int(last)] = value
    elif value is None:
        target.pop(last)
    else:
        target[last] = value


def _write(tmp_path: Path, camera: Any, changes: dict[str, Any]) -> Path:
    data = profile_dict(camera)
    for key, value in changes.items():
        _set(data, key, value)
    path = tmp_path / "cam.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


# (camera, changes, the field as the error names it, the range as it prints it)
BEYOND = {
    "frame rate low": (FISHEYE, {"frame_rate_hz": 4.9}, "frame_rate_hz", r"\[5, 1000\] Hz"),
    "frame rate 0.001": (FISHEYE, {"frame_rate_hz": 0.001}, "frame_rate_hz", r"\[5, 1000\] Hz"),
    "frame rate high": (FISHEYE, {"frame_rate_hz": 1000.5}, "frame_rate_hz", r"\[5, 1000\]"),
    "width low": (FISHEYE, {"image_width_px": 63}, "image_width_px", r"\[64, 8192\] px"),
    "width high": (FISHEYE, {"image_width_px": 8193}, "image_width_px", r"\[64, 8192\] px"),
    "height low": (FISHEYE, {"image_height_px": 63}, "image_height_px", r"\[64, 8192\] px"),
    "height high": (FISHEYE, {"image_height_px": 8193}, "image_height_px", r"\[64, 8192\]"),
    "fx low": (FISHEYE, {"camera_matrix.0.0": 75.1, "camera_matrix.1.1": 75.1},
               r"camera_matrix\[0\]\[0\] \(fx\)", r"\[75.2, 7520\] px"),
    "fx high": (FISHEYE, {"camera_matrix.0.0": 7521.0, "camera_matrix.1.1": 7521.0},
                r"camera_matrix\[0\]\[0\] \(fx\)", r"\[75.2, 7520\] px"),
    "fy low": (FISHEYE, {"camera_matrix.1.1": 0.49 * FX}, r"camera_matrix\[1\]\[1\] \(fy\)",
               rf"\[{0.5 * FX:g}, {2 * FX:g}\] px"),
    "fy high": (FISHEYE, {"camera_matrix.1.1": 2.01 * FX}, r"camera_matrix\[1\]\[1\] \(fy\)",
                rf"\[{0.5 * FX:g}, {2 * FX:g}\] px"),
    "skew": (FISHEYE, {"camera_matrix.0.1": 0.11 * FX}, r"camera_matrix\[0\]\[1\] \(skew\)",
             rf"\[{-0.1 * FX:g}, {0.1 * FX:g}\] px"),
    "cx low": (FISHEYE, {"camera_matrix.0.2": -0.6}, r"camera_matrix\[0\]\[2\] \(cx\)",
               r"\[-0.5, 751.5\] px"),
    "cx high": (FISHEYE, {"camera_matrix.0.2": 751.6}, r"camera_matrix\[0\]\[2\] \(cx\)",
                r"\[-0.5, 751.5\] px"),
    "cy low": (FISHEYE, {"camera_matrix.1.2": -0.6}, r"camera_matrix\[1\]\[2\] \(cy\)",
               r"\[-0.5, 479.5\] px"),
    "cy high": (FISHEYE, {"camera_matrix.1.2": 479.6}, r"camera_matrix\[1\]\[2\] \(cy\)",
                r"\[-0.5, 479.5\] px"),
    "fisheye k1": (FISHEYE, {"distortion.0": 10.1}, r"distortion\[0\] \(k1\)", r"\[-10, 10\]"),
    "fisheye k4": (FISHEYE, {"distortion.3": -10.1}, r"distortion\[3\] \(k4\)", r"\[-10, 10\]"),
    "pinhole k1": (PINHOLE, {"distortion.0": -10.1}, r"distortion\[0\] \(k1\)", r"\[-10, 10\]"),
    "pinhole p1": (PINHOLE, {"distortion.2": 0.11}, r"distortion\[2\] \(p1\)",
                   r"\[-0.1, 0.1\]"),
    "pinhole p2": (PINHOLE, {"distortion.3": -0.11}, r"distortion\[3\] \(p2\)",
                   r"\[-0.1, 0.1\]"),
    "pinhole k3": (PINHOLE, {"distortion.4": 10.1}, r"distortion\[4\] \(k3\)", r"\[-10, 10\]"),
    "mount height low": (FISHEYE, {"mount.height_m": 0.019}, r"mount.height_m", r"\[0.02, 2\] m"),
    "mount height high": (FISHEYE, {"mount.height_m": 2.01}, r"mount.height_m", r"\[0.02, 2\] m"),
    "forward": (FISHEYE, {"mount.forward_m": -1.01}, r"mount.forward_m", r"\[-1, 1\] m"),
    "lateral": (FISHEYE, {"mount.lateral_m": 0.51}, r"mount.lateral_m", r"\[-0.5, 0.5\] m"),
    "pitch": (FISHEYE, {"mount.pitch_rad": math.radians(80.1)}, "mount.pitch_rad", "±80°"),
    "roll": (FISHEYE, {"mount.roll_rad": -math.radians(80.1)}, "mount.roll_rad", "±80°"),
    "yaw": (FISHEYE, {"mount.yaw_rad": math.radians(80.1)}, "mount.yaw_rad", "±80°"),
    "bonnet top": (FISHEYE, {"bonnet.parabola.top_row_px": 239.9}, "bonnet parabola top_row",
                   r"\[240, 479\] px"),
    "bonnet borders": (FISHEYE, {"bonnet.parabola.top_row_px": 300.0,
                                 "bonnet.parabola.edge_drop_px": -60.1},
                       r"bonnet parabola top_row \+ edge_drop_px \(its edge at the borders\)",
                       r"\[240, 479\] px"),
    "bonnet polygon": (FISHEYE, {"bonnet": {"polygon_px": [[0, 479], [376, 239.9],
                                                           [751, 479]]}},
                       "bonnet polygon vertex 1 row v", r"\[240, 479.5\] px"),
}

AT_THE_LIMIT = {
    "frame rates": [(FISHEYE, {"frame_rate_hz": 5.0}), (FISHEYE, {"frame_rate_hz": 1000.0})],
    "focal lengths": [(FISHEYE, {"camera_matrix.0.0": 75.2, "camera_matrix.1.1": 75.2}),
                      (FISHEYE, {"camera_matrix.0.0": 7520.0, "camera_matrix.1.1": 7520.0}),
                      (FISHEYE, {"camera_matrix.1.1": 0.5 * FX}),
                      (FISHEYE, {"camera_matrix.1.1": 2.0 * FX}),
                      (FISHEYE, {"camera_matrix.0.1": -0.1 * FX})],
    "principal point": [(FISHEYE, {"camera_matrix.0.2": -0.5, "camera_matrix.1.2": 479.5}),
                        (FISHEYE, {"camera_matrix.0.2": 751.5, "camera_matrix.1.2": -0.5})],
    "distortion": [(FISHEYE, {"distortion": [10.0, -10.0, 10.0, -10.0]}),
                   (PINHOLE, {"distortion": [-10.0, 10.0, 0.1, -0.1, 10.0]})],
    "mount": [(FISHEYE, {"mount.height_m": 0.02, "mount.forward_m": 1.0,
                         "mount.lateral_m": -0.5}),
              (FISHEYE, {"mount.height_m": 2.0, "mount.forward_m": -1.0,
                         "mount.lateral_m": 0.5, "mount.pitch_rad": math.radians(79.9),
                         "mount.roll_rad": -math.radians(79.9),
                         "mount.yaw_rad": math.radians(79.9)})],
    "bonnet": [(FISHEYE, {"bonnet.parabola.top_row_px": 300.0,
                          "bonnet.parabola.edge_drop_px": -60.0}),
               (FISHEYE, {"bonnet": {"polygon_px": [[0, 479], [376, 240], [751, 479]]}})],
}


@pytest.mark.parametrize("case", list(BEYOND))
def test_a_value_beyond_its_limit_is_refused_naming_field_value_and_range(
        tmp_path: Path, case: str) -> None:
    camera, changes, field, span = BEYOND[case]
    with pytest.raises(CameraFileError, match=rf"cam.yaml: {field} must .*{span}") as err:
        load_camera(_write(tmp_path, camera, changes))
    message = str(err.value)
    assert "\n" not in message
    if "±80°" in span:  # an angle is shown in degrees
        assert message.endswith("got 80.1°") or message.endswith("got -80.1°"), message
        return
    shown = {"bonnet borders": 300.0 - 60.1, "bonnet polygon": 239.9}.get(case)
    if shown is None:
        shown = list(changes.values())[-1]
    assert message.endswith(f"got {shown:g}"), message


@pytest.mark.parametrize("case", list(AT_THE_LIMIT))
def test_values_at_their_limits_load(tmp_path: Path, case: str) -> None:
    for camera, changes in AT_THE_LIMIT[case]:
        load_camera(_write(tmp_path, camera, changes))


@pytest.mark.parametrize("build,match", [
    (lambda: FISHEYE.replace(frame_rate_hz=0.001), r"frame_rate_hz must be in \[5, 1000\]"),
    (lambda: FISHEYE.replace(K=np.diag([60.0, 60.0, 1.0]) + np.array(
        [[0, 0, 375.5], [0, 0, 239.5], [0, 0, 0]])), r"fx = K\[0, 0\] must be in \[75.2"),
    (lambda: FISHEYE.replace(D=np.array([0.0, 0.0, 0.0, 11.0])), r"D\[3\] \(k4\) must be in"),
    (lambda: FISHEYE.replace(width=32), r"image width must be in \[64, 8192\] px"),
    (lambda: CameraMount(lateral_m=0.6), r"mount.lateral_m must be in \[-0.5, 0.5\] m"),
    (lambda: CameraMount(forward_m=2.0), r"mount.forward_m must be in \[-1, 1\] m"),
    (lambda: CameraMount(height_m=0.01), r"mount.height_m must be in \[0.02, 2\] m"),
    (lambda: FISHEYE.replace(bonnet=Bonnet(top_row=100.0)), "bonnet parabola top_row must"),
])
def test_the_api_refuses_the_same_values(build: Any, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        build()


def test_the_limits_are_named_constants_with_a_reason() -> None:
    import inspect

    source = inspect.getsource(L)
    for name in ("MIN_IMAGE_SIDE_PX", "MAX_IMAGE_SIDE_PX", "MIN_FRAME_RATE_HZ",
                 "MAX_FRAME_RATE_HZ", "FOCAL_PER_WIDTH", "PIXEL_ASPECT", "MAX_SKEW",
                 "MAX_RADIAL_COEFFICIENT", "MAX_TANGENTIAL_COEFFICIENT", "MIN_MOUNT_HEIGHT_M",
                 "MAX_MOUNT_HEIGHT_M", "MAX_MOUNT_FORWARD_M", "MAX_MOUNT_LATERAL_M",
                 "MAX_MOUNT_ANGLE_RAD", "MIN_BONNET_TOP_SHARE"):
        doc = source.split(f"\n{name}:", 1)[1].split('"""')[1]
        assert "[" in doc and len(doc) > 60, name  # a unit in brackets, and why


def test_commands_refuse_a_frame_rate_of_0_001(tmp_path: Path) -> None:
    """It was accepted: a drive then made 0 steps."""
    _write(tmp_path, FISHEYE, {"frame_rate_hz": 0.001})
    for argv in (("camera", "show", "cam.yaml"), ("drive", "--camera", "cam.yaml")):
        run = tfalda(*argv, cwd=tmp_path, code=2)
        assert "cam.yaml: frame_rate_hz must be in [5, 1000] Hz" in run.err, str(run)
        assert run.err.rstrip().endswith("got 0.001"), str(run)
