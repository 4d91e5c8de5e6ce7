"""Camera profiles: one YAML file with a camera's intrinsics, mount, body mask and frame
rate, and readers for the calibration files OpenCV and ROS write.

Profile format (``format: tfalda-sim-camera/1``; every key below, no others)::

    format: tfalda-sim-camera/1
    lens: fisheye                 # fisheye (cv2.fisheye, k1..k4) | pinhole (k1 k2 p1 p2 k3)
    image_width_px: 752
    image_height_px: 480
    camera_matrix: [[fx, skew, cx], [0, fy, cy], [0, 0, 1]]     # [px]
    distortion: [k1, k2, k3, k4]  # pinhole: [k1, k2, p1, p2, k3]
    mount:                        # the camera on the car (car frame: x ahead, y left, z up)
      height_m: 0.2               # above the ground
      forward_m: 0.2              # ahead of the rear axle
      lateral_m: 0.0              # left of the car's centre line
      pitch_rad: 0.096            # down > 0; or pitch_deg (one of the two)
      roll_rad: 0.0               # image turned clockwise > 0; or roll_deg
      yaw_rad: 0.0                # turned left > 0; or yaw_deg
    bonnet:                       # the car's body in the image; one of
      polygon_px: [[u, v], ...]   #   an outline drawn on a frame [px]
      # parabola: {top_row_px: 440, edge_drop_px: 22}   (the thesis camera's)
      # none: true                                       (no body in view)
    frame_rate_hz: 50
    description: free text        # optional

``save_camera`` writes the angles in radians so that ``load_camera(save_camera(c))``
gives back exactly ``c``; hand-written files may use degrees.

Calibration files carry intrinsics only (``load_intrinsics``): OpenCV ``cv2.FileStorage``
YAML or XML with ``camera_matrix``, ``distortion_coefficients``, ``image_width``,
``image_height`` (4 coefficients: ``cv2.fisheye.calibrate``; 5: ``cv2.calibrateCamera``),
and ROS ``camera_info`` YAML (``distortion_model: equidistant`` or ``plumb_bob``). They
combine with a mount given or fitted (``tfalda-sim camera fit``).
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml

from ..fileio import atomic_write
from .bonnet import Bonnet
from .limits import CALIBRATION_NAMES, PROFILE_NAMES, check_intrinsics
from .models import (
    MAX_IMAGE_SIDE_PX,
    MIN_IMAGE_SIDE_PX,
    Camera,
    FisheyeCamera,
    LensModel,
    PinholeCamera,
)
from .mount import CameraMount
from .ros_info import LENS_OF_ROS_MODEL

PROFILE_FORMAT: str = "tfalda-sim-camera/1"
"""The ``format`` value of a camera profile file."""

PROFILES_DIR = Path(__file__).with_name("profiles")

NAMED_CAMERAS: tuple[str, ...] = ("thesis", "reference-car")
"""Profiles shipped with tfalda-sim: ``thesis`` (the simulator's camera, calibrated to the
thesis' tables) and ``reference-car`` (another team's car, fitted from
``../shared/reference/straight-road.png``; see docs/cameras.md)."""

MAX_PROFILE_BYTES: int = 1 << 20
"""Largest camera file read [bytes] (a profile is a few kB)."""

_TOP_KEYS = ("format", "lens", "image_width_px", "image_height_px", "camera_matrix",
             "distortion", "mount", "bonnet", "frame_rate_hz", "description")
_REQUIRED = ("format", "lens", "image_width_px", "image_height_px", "camera_matrix",
             "distortion", "mount", "bonnet", "frame_rate_hz")
_MOUNT_LENGTHS = ("height_m", "forward_m", "lateral_m")
_MOUNT_ANGLES = ("pitch", "roll", "yaw")
_DISTORTION_NAMES = {LensModel.FISHEYE: "k1, k2, k3, k4", LensModel.PINHOLE: "k1, k2, p1, p2, k3"}
_CLASSES: dict[LensModel, type[Camera]] = {LensModel.FISHEYE: FisheyeCamera,
                                           LensModel.PINHOLE: PinholeCamera}


class CameraFileError(ValueError):
    """A camera file that cannot be used; the message names the file, the field and the fix."""


@dataclass(frozen=True)
class Intrinsics:
    """What a calibration file holds: the lens model, ``K`` (3×3), ``D`` and the image
    size [px]."""

    lens: LensModel
    K: np.ndarray
    D: np.ndarray
    width: int
    height: int

    def camera(self, mount: CameraMount, bonnet: Bonnet | None = None,
               frame_rate_hz: float | None = None) -> Camera:
        """These intrinsics on ``mount`` (no body in view unless ``bonnet`` is given)."""
        kwargs: dict[str, Any] = {"width": self.width, "height": self.height, "mount": mount,
                                  "bonnet": bonnet or Bonnet.none()}
        if frame_rate_hz is not None:
            kwargs["frame_rate_hz"] = frame_rate_hz
        return _CLASSES[self.lens](self.K, self.D, **kwargs)


# --------------------------------------------------------------------------- helpers
class _StrictLoader(yaml.SafeLoader):
    """PyYAML's safe loader that refuses a key given twice (PyYAML keeps the last)."""


def _mapping(loader: _StrictLoader, node: yaml.MappingNode, deep: bool = False) -> dict:
    seen: set = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        if key in seen:
            raise yaml.constructor.ConstructorError(
                None, None, f"key {key!r} is given twice", key_node.start_mark)
        seen.add(key)
    return loader.construct_mapping(node, deep=deep)


_StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _mapping)


def _read_text(path: Path) -> str:
    if not path.exists():
        raise CameraFileError(f"{path}: no such file (give a profile name — "
                              f"{', '.join(NAMED_CAMERAS)} — or a camera file)")
    if path.is_dir():
        raise CameraFileError(f"{path}: is a folder, not a camera file")
    if not path.is_file():
        raise CameraFileError(f"{path}: not a regular file (a device or a pipe?)")
    try:
        with open(path, "rb") as fh:  # bounded whatever the size claims
            data = fh.read(MAX_PROFILE_BYTES + 1)
        if len(data) > MAX_PROFILE_BYTES:
            raise CameraFileError(f"{path}: larger than {MAX_PROFILE_BYTES} bytes: not a "
                                  "camera file")
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise CameraFileError(f"{path}: not a text file (byte {exc.start} is not UTF-8): "
                              "is it a camera file?") from None
    except OSError as exc:
        raise CameraFileError(f"{path}: cannot read: {exc.strerror}") from None


def _parse_yaml(path: Path, text: str) -> Any:
    try:
        return yaml.load(text, Loader=_StrictLoader)
    except TypeError:  # a complex (list or mapping) key
        raise CameraFileError(f"{path}: a key that is a list or a mapping: keys are names")\
            from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
        where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise CameraFileError(f"{path}: not valid YAML{where}: {problem}") from None


def _yaml_float(number: float) -> str:
    """``number`` spelt so that YAML 1.1 reads it as a float (a decimal point in the
    mantissa and a signed exponent)."""
    text = repr(number)
    mantissa, _, exponent = text.partition("e")
    if "." not in mantissa:
        mantissa += ".0"
    return f"{mantissa}e{exponent}" if exponent else mantissa


def _text_number_hint(value: str) -> str:
    """Why a string that reads as a number came from the YAML, and how to write it."""
    try:
        number = float(value)
    except (ValueError, OverflowError):
        return ""
    if not math.isfinite(number):
        return ""
    return (f": YAML 1.1 (PyYAML, which reads camera files) reads {value!r} as text, a float "
            f"needs a decimal point and a signed exponent: write {_yaml_float(number)}")


def _number(path: Path, field: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        hint = _text_number_hint(value) if isinstance(value, str) else ""
        raise CameraFileError(f"{path}: {field} must be a number, got {value!r}{hint}")
    try:
        number = float(value)
    except OverflowError:
        raise CameraFileError(f"{path}: {field} is too large to be a number") from None
    if not math.isfinite(number):
        raise CameraFileError(f"{path}: {field} must be finite, got {value}")
    return number


def _integer(path: Path, field: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise CameraFileError(f"{path}: {field} must be an integer, got {value!r}")
    return value


def _matrix(path: Path, field: str, value: Any, shape: tuple[int, ...]) -> np.ndarray:
    try:
        arr = np.array(value, dtype=object)
    except ValueError:
        arr = None
    if arr is None or arr.shape != shape:
        want = ("a list of 3 rows of 3 numbers" if shape == (3, 3)
                else f"a list of {shape[0]} numbers")
        raise CameraFileError(f"{path}: {field} must be {want}, got {value!r}")
    flat = [_number(path, field, v) for v in arr.ravel()]
    return np.array(flat, dtype=np.float64).reshape(shape)


def _unknown(path: Path, where: str, keys: Any, known: tuple[str, ...]) -> None:
    extra = [k for k in keys if k not in known]
    if extra:
        raise CameraFileError(f"{path}: unknown key {extra[0]!r} in {where} (known: "
                              f"{', '.join(known)})")


def _checked_camera(path: Path, build: Any) -> Camera:
    try:
        return build()
    except (ValueError, TypeError) as exc:
        raise CameraFileError(f"{path}: {exc}") from None


def _plausible(path: Path, K: np.ndarray, D: np.ndarray, width: int, height: int,
               rate: float | None, names: Any) -> None:
    """The ranges of ``limits``, the fields named as the file names them."""
    if not (K[0, 0] > 0 and K[1, 1] > 0):
        return  # the camera's own check says it in its words: positive focal lengths
    try:
        check_intrinsics(K, D, width, height, rate, names)
    except ValueError as exc:
        raise CameraFileError(f"{path}: {exc}") from None


# --------------------------------------------------------------------------- profiles
def _lens(path: Path, value: Any, field: str = "lens") -> LensModel:
    try:
        return LensModel(value)
    except (ValueError, TypeError):
        raise CameraFileError(f"{path}: {field} must be one of "
                              f"{', '.join(m.value for m in LensModel)}, got {value!r}") from None


def _mount(path: Path, data: Any) -> CameraMount:
    if not isinstance(data, dict):
        raise CameraFileError(f"{path}: mount must be a mapping of height_m, forward_m, "
                              f"lateral_m, pitch_rad|pitch_deg, roll_rad|roll_deg, "
                              f"yaw_rad|yaw_deg, got {data!r}")
    known = (*_MOUNT_LENGTHS, *(f"{a}_{u}" for a in _MOUNT_ANGLES for u in ("rad", "deg")))
    _unknown(path, "mount", data, known)
    values: dict[str, float] = {}
    for name in _MOUNT_LENGTHS:
        if name not in data:
            raise CameraFileError(f"{path}: mount.{name} is missing")
        values[name] = _number(path, f"mount.{name}", data[name])
    for angle in _MOUNT_ANGLES:
        rad, deg = f"{angle}_rad", f"{angle}_deg"
        if rad in data and deg in data:
            raise CameraFileError(f"{path}: mount gives both {rad} and {deg}: keep one")
        if rad in data:
            values[rad] = _number(path, f"mount.{rad}", data[rad])
        elif deg in data:
            values[rad] = math.radians(_number(path, f"mount.{deg}", data[deg]))
        else:
            raise CameraFileError(f"{path}: mount.{rad} (or {deg}) is missing")
    try:
        return CameraMount(**values)
    except (ValueError, TypeError) as exc:
        raise CameraFileError(f"{path}: {exc}") from None


def _bonnet(path: Path, data: Any) -> Bonnet:
    forms = ("polygon_px", "parabola", "none")
    if not isinstance(data, dict) or len(data) != 1 or next(iter(data)) not in forms:
        raise CameraFileError(f"{path}: bonnet must be one of {{polygon_px: [[u, v], ...]}}, "
                              "{parabola: {top_row_px, edge_drop_px}} or {none: true}, got "
                              f"{data!r}")
    (form, value), = data.items()
    try:
        if form == "none":
            if value is not True:
                raise CameraFileError(f"{path}: bonnet.none must be true, got {value!r}")
            return Bonnet.none()
        if form == "parabola":
            if not isinstance(value, dict):
                raise CameraFileError(f"{path}: bonnet.parabola must be a mapping of "
                                      f"top_row_px, edge_drop_px, got {value!r}")
            _unknown(path, "bonnet.parabola", value, ("top_row_px", "edge_drop_px"))
            for key in ("top_row_px", "edge_drop_px"):
                if key not in value:
                    raise CameraFileError(f"{path}: bonnet.parabola.{key} is missing")
            return Bonnet(top_row=_number(path, "bonnet.parabola.top_row_px", value["top_row_px"]),
                          edge_drop_px=_number(path, "bonnet.parabola.edge_drop_px",
                                               value["edge_drop_px"]))
        if not isinstance(value, list) or not all(
                isinstance(p, list) and len(p) == 2 for p in value):
            raise CameraFileError(f"{path}: bonnet.polygon_px must be a list of [u, v] pixel "
                                  f"pairs, got {value!r}")
        pts = [[_number(path, "bonnet.polygon_px", c) for c in p] for p in value]
        return Bonnet.polygon(pts)
    except ValueError as exc:
        if isinstance(exc, CameraFileError):
            raise
        raise CameraFileError(f"{path}: {exc}") from None


def _profile_camera(path: Path, data: dict) -> Camera:
    _unknown(path, "the profile", data, _TOP_KEYS)
    for key in _REQUIRED:
        if key not in data:
            raise CameraFileError(f"{path}: {key} is missing (a profile needs "
                                  f"{', '.join(_REQUIRED)})")
    if data["format"] != PROFILE_FORMAT:
        raise CameraFileError(f"{path}: format {data['format']!r} is not {PROFILE_FORMAT!r}")
    lens = _lens(path, data["lens"])
    width = _integer(path, "image_width_px", data["image_width_px"])
    height = _integer(path, "image_height_px", data["image_height_px"])
    K = _matrix(path, "camera_matrix", data["camera_matrix"], (3, 3))
    n = 4 if lens is LensModel.FISHEYE else 5
    if not isinstance(data["distortion"], list) or len(data["distortion"]) != n:
        raise CameraFileError(f"{path}: distortion of a {lens.value} lens must be a list of "
                              f"{n} numbers ({_DISTORTION_NAMES[lens]}), got "
                              f"{data['distortion']!r}")
    D = _matrix(path, "distortion", data["distortion"], (n,))
    mount = _mount(path, data["mount"])
    bonnet = _bonnet(path, data["bonnet"])
    rate = _number(path, "frame_rate_hz", data["frame_rate_hz"])
    if "description" in data and not isinstance(data["description"], str):
        raise CameraFileError(f"{path}: description must be text")
    _plausible(path, K, D, width, height, rate, PROFILE_NAMES)
    return _checked_camera(path, lambda: _CLASSES[lens](K, D, width=width, height=height,
                                                        mount=mount, bonnet=bonnet,
                                                        frame_rate_hz=rate))


def profile_dict(camera: Camera, description: str | None = None) -> dict[str, Any]:
    """``camera`` as the profile file's mapping (angles in radians: exact round trip)."""
    m = camera.mount
    b = camera.bonnet
    if not b.enabled:
        bonnet: dict[str, Any] = {"none": True}
    elif b.polygon_px is not None:
        bonnet = {"polygon_px": [[float(u), float(v)] for u, v in b.polygon_px]}
    else:
        bonnet = {"parabola": {"top_row_px": float(b.top_row),
                               "edge_drop_px": float(b.edge_drop_px)}}
    out: dict[str, Any] = {
        "format": PROFILE_FORMAT, "lens": camera.lens.value,
        "image_width_px": int(camera.width), "image_height_px": int(camera.height),
        "camera_matrix": [[float(x) for x in row] for row in camera.K],
        "distortion": [float(x) for x in camera.D],
        "mount": {"height_m": float(m.height_m), "forward_m": float(m.forward_m),
                  "lateral_m": float(m.lateral_m), "pitch_rad": float(m.pitch_rad),
                  "roll_rad": float(m.roll_rad), "yaw_rad": float(m.yaw_rad)},
        "bonnet": bonnet, "frame_rate_hz": float(camera.frame_rate_hz),
    }
    if description:
        out["description"] = description
    return out


def profile_text(camera: Camera, description: str | None = None) -> str:
    """The profile file's text for ``camera``."""
    head = ("# tfalda-sim camera profile (format: docs/cameras.md). Angles in radians; "
            "a hand-written file may use pitch_deg/roll_deg/yaw_deg.\n")
    return head + yaml.safe_dump(profile_dict(camera, description), sort_keys=False,
                                 default_flow_style=None, width=100)


def save_camera(camera: Camera, path: str | os.PathLike[str],
                description: str | None = None) -> Path:
    """Write ``camera`` as a profile file (``load_camera(path)`` gives it back exactly)."""
    out = Path(path)
    with atomic_write(out) as fh:
        fh.write(profile_text(camera, description))
    return out


# --------------------------------------------------------------------------- calibrations
MAX_OPENCV_MATRIX_SIDE: int = 16
"""Most rows or columns of a matrix read from an OpenCV file [1]: a camera matrix is 3×3,
distortion at most 14 coefficients (OpenCV's largest model); a larger size is a broken file
and would make OpenCV allocate it before any check."""

_OPENCV_FIX = ("a truncated or hand-edited file? Write it again with cv2.FileStorage (as "
               "OpenCV's calibration sample does) or give a tfalda-sim profile")


def _opencv_reason(exc: BaseException) -> str:
    """OpenCV's own words for a failed read, without its source path: "line N: what" for
    a parse error. OpenCV's Python binding raises a parse error in a constructor as a
    ``SystemError`` whose cause is the ``cv2.error``."""
    if isinstance(exc, SystemError) and exc.__cause__ is not None:
        exc = exc.__cause__
    text = str(exc).strip()
    parse = re.search(r"in function '[^']*\((\d+)\): ([^']*)'", text)
    if parse:
        return f"line {parse.group(1)}: {parse.group(2).strip()}"
    what = re.search(r"error: \(-?\d+:[^)]*\) (.*?) in function", text, re.S)
    if what:
        return what.group(1).strip()
    return text.splitlines()[-1] if text else "unreadable"


def _opencv_intrinsics(path: Path, lens: LensModel | None) -> Intrinsics:
    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_FORMAT_AUTO)
    except (cv2.error, SystemError) as exc:
        raise CameraFileError(f"{path}: not a valid OpenCV FileStorage file "
                              f"({_opencv_reason(exc)}): {_OPENCV_FIX}") from None
    try:
        if not fs.isOpened():
            raise CameraFileError(f"{path}: OpenCV cannot open it as a FileStorage file: "
                                  f"{_OPENCV_FIX}")
        if fs.root().empty() or (fs.root().isMap() and not fs.root().keys()):
            raise CameraFileError(f"{path}: an empty OpenCV FileStorage file, no camera_matrix "
                                  f"({_OPENCV_FIX})")
        if not fs.root().isMap():
            raise CameraFileError(f"{path}: an OpenCV FileStorage file whose top level is not "
                                  "a mapping of named nodes (camera_matrix, "
                                  "distortion_coefficients, image_width, image_height)")

        def integer(node: Any, field: str, low: int, high: int) -> int:
            value = node.real() if node.isInt() or node.isReal() else None
            if value is None or not math.isfinite(value) or value != int(value) \
                    or not low <= value <= high:
                shown = node.string() if node.isString() else (
                    "nothing" if value is None else f"{value:g}")
                raise CameraFileError(f"{path}: {field} must be an integer in [{low}, {high}], "
                                      f"got {shown}")
            return int(value)

        def mat(name: str) -> np.ndarray:
            node = fs.getNode(name)
            if node.empty():
                raise CameraFileError(f"{path}: no {name} matrix (OpenCV calibration files "
                                      "hold camera_matrix and distortion_coefficients)")
            if not node.isMap():
                raise CameraFileError(f"{path}: {name} is not an opencv-matrix (a node with "
                                      "rows, cols, dt and data)")
            for key in ("rows", "cols", "dt", "data"):
                if node.getNode(key).empty():
                    raise CameraFileError(f"{path}: {name}.{key} is missing (an opencv-matrix "
                                          "has rows, cols, dt and data)")
            rows = integer(node.getNode("rows"), f"{name}.rows", 1, MAX_OPENCV_MATRIX_SIDE)
            cols = integer(node.getNode("cols"), f"{name}.cols", 1, MAX_OPENCV_MATRIX_SIDE)
            dt = node.getNode("dt")
            if not dt.isString() or dt.string() not in ("d", "f"):
                raise CameraFileError(f"{path}: {name}.dt must be d or f (a matrix of floating-"
                                      "point numbers)")
            data = node.getNode("data")
            if not data.isSeq() or data.size() != rows * cols:
                count = data.size() if data.isSeq() else "no list of"
                raise CameraFileError(f"{path}: {name}.data must hold rows × cols = "
                                      f"{rows * cols} numbers, got {count} numbers")
            for k in range(data.size()):
                item = data.at(k)
                if not (item.isInt() or item.isReal()):
                    shown = item.string() if item.isString() else "not a number"
                    raise CameraFileError(f"{path}: {name}.data[{k}] must be a number, got "
                                          f"{shown!r}")
            return np.asarray(node.mat(), dtype=np.float64)

        def size(name: str) -> int:
            node = fs.getNode(name)
            if node.empty():
                raise CameraFileError(f"{path}: no {name}: the image size is needed (add "
                                      f"'{name}: N' — OpenCV's calibration sample writes it)")
            return integer(node, name, MIN_IMAGE_SIDE_PX, MAX_IMAGE_SIDE_PX)

        try:
            K = mat("camera_matrix")
            D = mat("distortion_coefficients").ravel()
            width, height = size("image_width"), size("image_height")
        except (cv2.error, SystemError) as exc:
            raise CameraFileError(f"{path}: a malformed OpenCV matrix or size "
                                  f"({_opencv_reason(exc)}): {_OPENCV_FIX}") from None
    finally:
        fs.release()
    if K.shape != (3, 3):
        raise CameraFileError(f"{path}: camera_matrix must be 3×3, got {K.shape}")
    if lens is None:
        if len(D) == 4:
            lens = LensModel.FISHEYE  # what cv2.fisheye.calibrate returns
        elif len(D) == 5:
            lens = LensModel.PINHOLE  # cv2.calibrateCamera's default
        else:
            raise CameraFileError(f"{path}: {len(D)} distortion coefficients: tfalda-sim "
                                  "reads 4 (cv2.fisheye) or 5 (k1 k2 p1 p2 k3); the rational "
                                  "and thin-prism models are not supported")
    return _intrinsics(path, lens, K, D, width, height)


def _intrinsics(path: Path, lens: LensModel, K: np.ndarray, D: np.ndarray, width: int,
                height: int) -> Intrinsics:
    if lens is LensModel.PINHOLE and len(D) == 4:
        D = np.append(D, 0.0)  # (k1, k2, p1, p2) with k3 = 0
    n = 4 if lens is LensModel.FISHEYE else 5
    if len(D) != n:
        raise CameraFileError(f"{path}: a {lens.value} lens needs {n} distortion "
                              f"coefficients ({_DISTORTION_NAMES[lens]}), got {len(D)}")
    _plausible(path, K, D, width, height, None, CALIBRATION_NAMES)
    # Build once to check K, D and the size with the camera's own rules.
    _checked_camera(path, lambda: _CLASSES[lens](K, D, width=width, height=height,
                                                 bonnet=Bonnet.none()))
    return Intrinsics(lens, K, D, width, height)


def _ros_intrinsics(path: Path, data: dict, lens: LensModel | None) -> Intrinsics:
    known = ("image_width", "image_height", "camera_name", "camera_matrix", "distortion_model",
             "distortion_coefficients", "rectification_matrix", "projection_matrix")
    _unknown(path, "the camera_info file", data, known)
    model = data["distortion_model"]
    ros = LENS_OF_ROS_MODEL
    if not isinstance(model, str) or model not in ros:
        raise CameraFileError(f"{path}: distortion_model {model!r} is not supported (known: "
                              f"{', '.join(ros)})")
    found = ros[model]
    if lens is not None and lens is not found:
        raise CameraFileError(f"{path}: distortion_model {model} is a {found.value} lens, "
                              f"not {lens.value}")

    def matrix(name: str, rows: int, cols: int) -> np.ndarray:
        node = data.get(name)
        if not isinstance(node, dict) or "data" not in node:
            raise CameraFileError(f"{path}: {name} must be a mapping with rows, cols, data")
        values = node["data"]
        if not isinstance(values, list) or (cols and len(values) != rows * cols):
            raise CameraFileError(f"{path}: {name}.data must hold {rows * cols} numbers")
        return np.array([_number(path, f"{name}.data", v) for v in values], dtype=np.float64)

    for key in ("image_width", "image_height"):
        if key not in data:
            raise CameraFileError(f"{path}: {key} is missing")
    K = matrix("camera_matrix", 3, 3).reshape(3, 3)
    D = matrix("distortion_coefficients", 1, 0)
    return _intrinsics(path, found, K, D, _integer(path, "image_width", data["image_width"]),
                       _integer(path, "image_height", data["image_height"]))


def intrinsics_from_camera_info(where: str, width: int, height: int, K: np.ndarray,
                                D: np.ndarray, distortion_model: str) -> Intrinsics:
    """The intrinsics of a recording's ``camera_info`` (``where`` names it in errors):
    ROS's ``equidistant`` is a fisheye, ``plumb_bob`` a pinhole; checked as a calibration
    file is (``CameraFileError``)."""
    ros = LENS_OF_ROS_MODEL
    if distortion_model not in ros:
        raise CameraFileError(f"{where}: distortion_model {distortion_model!r} is not "
                              "supported (known: equidistant, plumb_bob); give --intrinsics")
    K = np.asarray(K, dtype=np.float64).reshape(3, 3)
    D = np.asarray(D, dtype=np.float64).ravel()
    if ros[distortion_model] is LensModel.PINHOLE and len(D) < 5:
        D = np.concatenate([D, np.zeros(5 - len(D))])  # ROS may leave trailing zeros out
    return _intrinsics(Path(where), ros[distortion_model], K, D, int(width), int(height))


def _read(path: Path, lens: LensModel | None) -> tuple[str, Any]:
    """('profile', Camera) or ('intrinsics', Intrinsics)."""
    text = _read_text(path)
    head = text.lstrip()[:200]
    # OpenCV's YAML: "%YAML:1.0" (older OpenCV) or "%YAML 1.0" with !!opencv-matrix tags;
    # any other "%YAML" file is plain YAML
    opencv_yaml = head.startswith("%YAML:") or (head.startswith("%YAML") and (
        "!!opencv-" in text or head.startswith("%YAML 1.0") or head.startswith("%YAML:1.0")))
    if opencv_yaml or head.startswith("<?xml") or "<opencv_storage>" in head:
        return "intrinsics", _opencv_intrinsics(path, lens)
    data = _parse_yaml(path, text)
    if not isinstance(data, dict):
        raise CameraFileError(f"{path}: not a camera file (a tfalda-sim profile, an OpenCV "
                              "calibration or a ROS camera_info YAML)")
    if "format" in data:
        if lens is not None:
            raise CameraFileError(f"{path}: a profile names its own lens; drop the lens option")
        return "profile", _profile_camera(path, data)
    if "distortion_model" in data:
        return "intrinsics", _ros_intrinsics(path, data, lens)
    raise CameraFileError(f"{path}: not a camera file: it has neither 'format: "
                          f"{PROFILE_FORMAT}' (a profile) nor 'distortion_model' (ROS "
                          "camera_info) and is not an OpenCV FileStorage file")


def named_camera_path(name: str) -> Path:
    """The file of a named profile; a clear error lists the names for an unknown one."""
    if name not in NAMED_CAMERAS:
        raise CameraFileError(f"unknown camera {name!r}: give one of {', '.join(NAMED_CAMERAS)} "
                              "or a camera file (.yaml, .yml, .xml)")
    return PROFILES_DIR / f"{name}.yaml"


def _profile_path(text: str) -> Path:
    """The file of a profile name (``NAMED_CAMERAS``) or a camera file's path; a bare word
    that names neither is an unknown profile name (``CameraFileError``)."""
    if text in NAMED_CAMERAS:
        return named_camera_path(text)
    path = Path(text)
    if os.sep not in text and "." not in text and not path.exists():
        named_camera_path(text)  # raises: an unknown profile name
    return path


def load_intrinsics(path: str | os.PathLike[str], lens: LensModel | None = None) -> Intrinsics:
    """The intrinsics of a profile (a name of ``NAMED_CAMERAS`` or a file) or of any camera
    file: an OpenCV calibration or a ROS camera_info (``lens`` forces the model of an
    OpenCV file's coefficients)."""
    kind, value = _read(_profile_path(os.fspath(path)), lens)
    if kind == "profile":
        return Intrinsics(value.lens, value.K, value.D, value.width, value.height)
    return value


def load_camera(spec: str | os.PathLike[str] | Camera, *, mount: CameraMount | None = None,
                bonnet: Bonnet | None = None, lens: LensModel | None = None) -> Camera:
    """The camera of ``spec``: a profile name (``NAMED_CAMERAS``), a camera file, or a
    camera (returned as is). ``mount``/``bonnet`` replace the file's; a calibration file
    (OpenCV, ROS) carries no mount and needs ``mount``."""
    if isinstance(spec, Camera):
        camera = spec
    else:
        if not isinstance(spec, (str, os.PathLike)):
            raise TypeError(f"camera must be a profile name, a path or a Camera, got "
                            f"{type(spec).__name__}")
        path = _profile_path(os.fspath(spec))
        kind, value = _read(path, lens)
        if kind == "intrinsics":
            if mount is None:
                raise CameraFileError(f"{path}: a calibration file carries no mount: give one "
                                      "(mount=CameraMount(...)) or fit it from a frame with "
                                      f"'tfalda-sim camera fit FRAME --intrinsics {path} --out "
                                      "PROFILE.yaml'")
            return _checked_camera(path, lambda: value.camera(mount, bonnet))
        camera = value
    changes: dict[str, Any] = {}
    if mount is not None:
        changes["mount"] = mount
    if bonnet is not None:
        changes["bonnet"] = bonnet
    return camera.replace(**changes) if changes else camera
