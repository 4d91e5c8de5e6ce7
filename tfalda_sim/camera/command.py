"""``tfalda-sim camera fit|show|list``: bring a real car's camera — fit its mount from one
frame, show and list profiles — and the ``--camera NAME|FILE`` option of the other
commands."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from ..cli_common import CliError, add_force_option, add_json_option, check_outputs
from ..outputs import Outputs
from ..video import ImageError, read_grey_image
from .bonnet import Bonnet
from .drawing import fit_overlay
from .fit import MountFit, MountFitError, detect_bonnet, fit_focal, fit_mount
from .models import Camera, LensModel
from .mount import CameraMount
from .profile import (
    NAMED_CAMERAS,
    CameraFileError,
    load_camera,
    load_intrinsics,
    profile_text,
)

MAX_POINTS_FILE_BYTES: int = 1 << 20
"""Largest ``--points`` / ``--bonnet`` JSON file [bytes]."""


def register(sub: Any) -> None:
    """Add ``camera fit|show|list`` to the ``tfalda-sim`` subparsers."""
    cam = sub.add_parser("camera", help="camera profiles: fit a real car's mount, show, list")
    cam_sub = cam.add_subparsers(dest="camera_command", required=True)

    fit = cam_sub.add_parser(
        "fit", help="fit the camera's mount (and focal length) from one frame",
        description="Estimate pitch, roll, yaw, height and lateral offset of the camera from "
                    "one frame of a straight road with the Carolo-Cup markings (0.4 m lanes, "
                    "dashed centre line), the car parallel to the road and centred in the "
                    "right lane; write a camera profile and an overlay PNG of the fitted "
                    "model lines on the frame. See docs/cameras.md.")
    fit.add_argument("frame", type=Path, help="the frame (PNG/JPEG, any bit depth, grey or colour)")
    lens = fit.add_mutually_exclusive_group(required=True)
    lens.add_argument("--intrinsics", type=Path,
                      help="the camera's calibration: a profile (a name, e.g. reference-car, "
                           "or a file), an OpenCV FileStorage YAML/XML or a ROS camera_info "
                           "YAML")
    lens.add_argument("--fit-focal", action="store_true",
                      help="no calibration: fit an equidistant fisheye's focal length too")
    fit.add_argument("--lens", choices=[m.value for m in LensModel],
                     help="the model of an OpenCV file's 4 distortion coefficients "
                          "(default: 4 → fisheye, 5 → pinhole)")
    fit.add_argument("--points", type=Path,
                     help="JSON {\"centre\": [[u, v], ...], \"left\": [...], \"right\": [...]}"
                          " of marked line pixels, instead of finding the markings")
    fit.add_argument("--bonnet", default="auto",
                     help="the car's body in the image: auto (found in the frame), none, or "
                          "a JSON file of the polygon [[u, v], ...] [px] (default: auto)")
    fit.add_argument("--forward-m", type=float, default=None,
                     help="camera ahead of the rear axle [m] (one frame cannot tell; "
                          "default: an --intrinsics profile's, else 0.20)")
    fit.add_argument("--out", type=Path, required=True, help="the profile to write (.yaml)")
    fit.add_argument("--overlay", type=Path,
                     help="the overlay PNG (default: the profile's name with -fit.png)")
    fit.add_argument("--description", default=None, help="text stored in the profile")
    add_force_option(fit)
    add_json_option(fit)
    fit.set_defaults(func=cmd_camera_fit)

    show = cam_sub.add_parser("show", help="print a camera profile's numbers")
    show.add_argument("camera", help="a profile name (" + ", ".join(NAMED_CAMERAS) + ") or file")
    add_json_option(show)
    show.set_defaults(func=cmd_camera_show)

    lst = cam_sub.add_parser("list", help="list the named camera profiles")
    add_json_option(lst)
    lst.set_defaults(func=cmd_camera_list)


# --------------------------------------------------------------------------- --camera
def add_camera_option(parser: argparse.ArgumentParser) -> None:
    """``--camera NAME|FILE``: the camera profile a command simulates or reads through."""
    parser.add_argument("--camera", default="thesis",
                        help="camera profile: " + ", ".join(NAMED_CAMERAS)
                             + " or a profile file (default: thesis)")


def camera_input(text: str) -> Path | None:
    """The file ``--camera`` reads (for the output check: never overwritten), or None
    for a named profile."""
    return None if text in NAMED_CAMERAS else Path(text)


def resolve_camera_arg(text: str, argument: str = "--camera") -> Camera:
    """The camera of ``--camera`` (or of the argument named ``argument``, as the command's
    usage line names it); a clear ``CliError`` for a bad name or file."""
    try:
        return load_camera(text)
    except CameraFileError as exc:
        raise CliError(f"{argument}: {exc}") from None


# --------------------------------------------------------------------------- fit
def _read_frame(path: Path) -> np.ndarray:
    try:
        return read_grey_image(path)
    except ImageError as exc:
        raise CliError(str(exc)) from None


def _read_json(path: Path, option: str) -> Any:
    if not path.is_file():
        raise CliError(f"{option} {path}: no such file")
    if path.stat().st_size > MAX_POINTS_FILE_BYTES:
        raise CliError(f"{option} {path}: larger than {MAX_POINTS_FILE_BYTES} bytes")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CliError(f"{option} {path}: not valid JSON ({exc})") from None


MAX_PIXEL_COORDINATE: float = 1e9
"""Largest |u| or |v| read from a points file [px]: far beyond any image; larger is not a
pixel (and would overflow the fit's arithmetic)."""


def _short_json(value: Any) -> str:
    text = json.dumps(value, allow_nan=True)
    return text if len(text) <= 40 else text[:37] + "..."


def _pixel_list(value: Any, what: str) -> np.ndarray:
    """``value`` as an ``(n, 2)`` array; a clear ``CliError`` names the first bad entry by
    its position (``what[k]``, its ``u`` or ``v``) and its value."""
    if not isinstance(value, list):
        raise CliError(f"{what} must be a list of [u, v] pixel pairs, got {_short_json(value)}")
    for k, pair in enumerate(value):
        if not isinstance(pair, list) or len(pair) != 2:
            raise CliError(f"{what}[{k}] must be a [u, v] pixel pair, got {_short_json(pair)}")
        for name, c in zip("uv", pair, strict=True):
            where = f"{what}[{k}] {name}"
            if isinstance(c, bool) or not isinstance(c, (int, float)):
                raise CliError(f"{where} must be a number of pixels, got {_short_json(c)}")
            try:
                finite = math.isfinite(c) and abs(c) <= MAX_PIXEL_COORDINATE
            except OverflowError:  # an integer too large for a float
                finite = False
            if not finite:
                # JSON has no NaN or Infinity; Python's json module accepts them
                raise CliError(f"{where} is {_short_json(c)}: a pixel coordinate must be a "
                               f"finite number within ±{MAX_PIXEL_COORDINATE:g} px (remove the "
                               "pair or mark the pixel)")
    return np.array(value, dtype=np.float64)


def _points(path: Path) -> list[np.ndarray | None]:
    data = _read_json(path, "--points")
    if not isinstance(data, dict):
        raise CliError('--points: expected {"centre": [[u, v], ...], "left": ..., '
                       '"right": ...}')
    unknown = [k for k in data if k not in ("centre", "left", "right")]
    if unknown:
        raise CliError(f"--points: unknown key {unknown[0]!r} (known: centre, left, right)")
    return [None if data.get(k) is None else _pixel_list(data[k], f"--points {path}: {k}")
            for k in ("centre", "left", "right")]


def _bonnet(spec: str, frame: np.ndarray) -> Bonnet:
    if spec == "none":
        return Bonnet.none()
    if spec == "auto":
        try:
            return Bonnet.polygon(detect_bonnet(frame))
        except ValueError as exc:
            if isinstance(exc, MountFitError):
                raise
            raise CliError(f"--bonnet auto: {exc}") from None
    poly = _bonnet_polygon(spec)
    try:
        bonnet = Bonnet.polygon(poly)
        bonnet.check_inside(frame.shape[1], frame.shape[0])
    except ValueError as exc:
        raise CliError(f"--bonnet: {exc}") from None
    return bonnet


def _bonnet_polygon(spec: str) -> np.ndarray:
    """The polygon of a ``--bonnet FILE``."""
    return _pixel_list(_read_json(Path(spec), "--bonnet"), f"--bonnet {spec}: polygon")


def fit_summary(fit: MountFit) -> dict[str, Any]:
    """The figures ``camera fit`` reports."""
    m = fit.camera.mount
    return {
        "residual_px": fit.residual_px, "height_m": m.height_m, "lateral_m": m.lateral_m,
        "forward_m": m.forward_m, "pitch_deg": math.degrees(m.pitch_rad),
        "roll_deg": math.degrees(m.roll_rad), "yaw_deg": math.degrees(m.yaw_rad),
        "roll_fitted": fit.roll_fitted, "focal_px": float(fit.camera.K[0, 0]),
        "lens": fit.camera.lens.value,
        "lines": [{"role": ln.role, "pixels": len(ln.pixels), "coverage": ln.coverage}
                  for ln in fit.lines],
    }


def cmd_camera_fit(args: argparse.Namespace) -> int:
    overlay = args.overlay or args.out.with_name(args.out.stem + "-fit.png")
    intrinsics = camera_input(str(args.intrinsics)) if args.intrinsics else None  # a file
    check_outputs({"out": args.out, "overlay": overlay}, {"out": ".yaml", "overlay": ".png"},
                  args.force, inputs={"frame": args.frame, "intrinsics": intrinsics,
                                      "points": args.points})
    if args.forward_m is not None and not (math.isfinite(args.forward_m)
                                           and -1.0 <= args.forward_m <= 1.0):
        raise CliError(f"--forward-m must be a finite distance in [-1, 1] m, got {args.forward_m}")
    if args.lens and not args.intrinsics:
        raise CliError("--lens names the model of an --intrinsics file; give one, or drop it")
    if args.fit_focal and args.points:
        raise CliError("--points needs known intrinsics (--intrinsics), not --fit-focal")
    frame = _read_frame(args.frame)
    points = _points(args.points) if args.points else None
    if args.bonnet not in ("auto", "none"):
        _bonnet_polygon(args.bonnet)  # a bad file refused before the fit's work
    try:
        if args.fit_focal:
            fit = fit_focal(frame, frame.shape[1], frame.shape[0])
            if args.forward_m is not None:
                fit = _with_forward(fit, args.forward_m)
        else:
            intr = load_intrinsics(args.intrinsics, LensModel(args.lens) if args.lens else None)
            base = intr.camera(CameraMount())
            if args.lens is None:
                try:  # a profile as --intrinsics: keep its forward offset and frame rate
                    own = load_camera(args.intrinsics)
                    base = base.replace(mount=CameraMount(forward_m=own.mount.forward_m),
                                        frame_rate_hz=own.frame_rate_hz)
                except CameraFileError:
                    pass  # a calibration file: no mount, the defaults
            fit = fit_mount(frame, base, points=points, forward_m=args.forward_m)
        bonnet = _bonnet(args.bonnet, frame)
    except CameraFileError as exc:
        raise CliError(f"--intrinsics: {exc}") from None
    except MountFitError as exc:
        raise CliError(f"{args.frame}: {exc}") from None
    fit = MountFit(fit.camera.replace(bonnet=bonnet), fit.lines, fit.residual_px,
                   fit.roll_fitted, fit.focal_px)
    summary = fit_summary(fit)
    with Outputs() as outs:  # the profile and its overlay, or neither
        outs.path(args.out).write_text(profile_text(fit.camera, args.description),
                                       encoding="utf-8")
        if not cv2.imwrite(str(outs.path(overlay)), fit_overlay(frame, fit)):
            raise CliError(f"--overlay {overlay}: OpenCV could not write the PNG")
        outs.commit()
    summary.update(out=str(args.out), overlay=str(overlay))
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"fitted mount   height {summary['height_m'] * 1000:.1f} mm, lateral "
              f"{summary['lateral_m'] * 1000:+.1f} mm, pitch {summary['pitch_deg']:.2f}°, roll "
              f"{summary['roll_deg']:.2f}°{'' if fit.roll_fitted else ' (not fitted: 2 lines)'},"
              f" yaw {summary['yaw_deg']:.2f}°")
        print(f"lens           {summary['lens']}, focal {summary['focal_px']:.1f} px")
        print("lines          " + ", ".join(f"{ln['role']} ({ln['pixels']} px)"
                                            for ln in summary["lines"]))
        print(f"residual       {summary['residual_px']:.2f} px")
        print(f"wrote          {args.out}, {overlay}")
    return 0


def _with_forward(fit: MountFit, forward_m: float) -> MountFit:
    cam = fit.camera.with_mount(forward_m=forward_m)
    return MountFit(cam, fit.lines, fit.residual_px, fit.roll_fitted, fit.focal_px)


# --------------------------------------------------------------------------- show / list
def camera_summary(camera: Camera) -> dict[str, Any]:
    """The figures ``camera show`` reports (the profile's own mapping)."""
    from .profile import profile_dict

    return profile_dict(camera)


def cmd_camera_show(args: argparse.Namespace) -> int:
    # a positional: named as argparse names it in its own errors, not as an option
    camera = resolve_camera_arg(args.camera, "argument camera")
    summary = camera_summary(camera)
    if args.json:
        print(json.dumps(summary))
    else:
        print(profile_text(camera), end="")
    return 0


def cmd_camera_list(args: argparse.Namespace) -> int:
    if args.json:
        print(json.dumps({"cameras": list(NAMED_CAMERAS)}))
    else:
        for name in NAMED_CAMERAS:
            print(name)
    return 0
