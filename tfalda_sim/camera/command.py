"""``tfalda-sim camera fit|show|list``: bring a real car's camera — fit its mount from a
frame or a clip, show and list profiles — and the ``--camera NAME|FILE`` option of the other
commands."""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from ..cli_common import (
    CliError,
    add_force_option,
    add_json_option,
    bounded_float_arg,
    check_outputs,
    json_text,
)
from ..outputs import Outputs
from ..sources.command import add_source_options
from ..tracks.dimensions import LANE_WIDTH_M
from ..video import ImageError, read_grey_image
from .bonnet import Bonnet
from .clip import (
    ClipFitError,
    ClipFrame,
    HeadingSample,
    Spread,
    clip_focal,
    fit_clip,
    sample_frames,
)
from .drawing import draw_fit, fit_overlay
from .fit import (
    LANE_WIDTH_FIT_RANGE_M,
    MountFit,
    MountFitError,
    SearchScale,
    body_search_mask,
    detect_bonnet,
    fit_focal,
    fit_mount,
    lines_off_body,
)
from .limits import MAX_FRAME_RATE_HZ, MAX_MOUNT_LATERAL_M, MIN_FRAME_RATE_HZ
from .models import Camera, LensModel
from .mount import DEFAULT_MOUNT_FORWARD_M, CameraMount
from .profile import (
    NAMED_CAMERAS,
    CameraFileError,
    intrinsics_from_camera_info,
    load_camera,
    load_intrinsics,
    profile_text,
)
from .static_body import STATIC_MIN_FRAMES, static_body

MAX_POINTS_FILE_BYTES: int = 1 << 20
"""Largest ``--points`` / ``--bonnet`` JSON file [bytes]."""


def register(sub: Any) -> None:
    """Add ``camera fit|show|list`` to the ``tfalda-sim`` subparsers."""
    cam = sub.add_parser("camera", help="camera profiles: fit a real car's mount, show, list")
    cam_sub = cam.add_subparsers(dest="camera_command", required=True)

    fit = cam_sub.add_parser(
        "fit", help="fit the camera's mount (and focal length) from a frame or a clip",
        description="Estimate pitch, roll, yaw and height of the camera from frames of a "
                    "straight road with the Carolo-Cup markings (lanes --lane-width apart, a "
                    "dashed centre line); write a camera profile and an overlay PNG of the "
                    "fitted model lines on a frame. SOURCE is one image — the car parked "
                    "parallel to the road and centred in the right lane (its lateral offset "
                    "is fitted) — or a clip: a video, a folder or glob of images, a ROS bag "
                    "or an MCAP file of the car driving. From a clip the frames of straight "
                    "road are found and fitted one by one; pitch, roll and height are their "
                    "medians, the yaw is their mean over time: the car's heading is assumed "
                    "to average out (a car that stays in its lane weaves about the lane's "
                    "direction). Where the car drives in the lane cannot be told from where "
                    "the camera sits on it: a clip keeps the lateral offset (--lateral-m, "
                    "default 0) and reports the car's offset. A mount no camera on a 1:10 "
                    "car has, or frames that disagree, is refused naming the parameter (the "
                    "overlay is still written). See docs/cameras.md.")
    fit.add_argument("source", metavar="SOURCE",
                     help="an image (PNG/JPEG, any bit depth, grey or colour), a video, a "
                          "folder or glob of images ('clip/*.png'), a ROS 1/2 bag or an MCAP "
                          "file")
    add_source_options(fit)
    lens = fit.add_mutually_exclusive_group()
    lens.add_argument("--intrinsics", type=Path,
                      help="the camera's calibration: a profile (a name, e.g. reference-car, "
                           "or a file), an OpenCV FileStorage YAML/XML or a ROS camera_info "
                           "YAML (default: the recording's camera_info)")
    lens.add_argument("--fit-focal", action="store_true",
                      help="no calibration: fit an equidistant fisheye's focal length too")
    fit.add_argument("--lens", choices=[m.value for m in LensModel],
                     help="the model of an OpenCV file's 4 distortion coefficients "
                          "(default: 4 → fisheye, 5 → pinhole)")
    fit.add_argument("--points", type=Path,
                     help="JSON {\"centre\": [[u, v], ...], \"left\": [...], \"right\": [...]}"
                          " of marked line pixels, instead of finding the markings (one "
                          "image; the centre line and at least one neighbour)")
    fit.add_argument("--bonnet", default="auto",
                     help="the car's body in the image, kept out of the marking search: auto "
                          "(one image: its dark bonnet's edge; a clip: what stays put while "
                          "the road moves), none, or a JSON file of the polygon [[u, v], ...] "
                          "[px] (default: auto)")
    fit.add_argument("--lane-width", type=bounded_float_arg(*LANE_WIDTH_FIT_RANGE_M, "m",
                                                            why="a model car's lanes"),
                     default=LANE_WIDTH_M, metavar="M",
                     help=f"the lines' spacing, centre to centre [m] (default: the "
                          f"Carolo-Cup's {LANE_WIDTH_M:g})")
    fit.add_argument("--forward-m", type=float, default=None,
                     help="camera ahead of the rear axle [m] (frames cannot tell; "
                          "default: an --intrinsics profile's, else 0.20)")
    fit.add_argument("--lateral-m", type=float, default=None,
                     help="camera left of the car's centre line [m] (default: one image: "
                          "fitted, the parked car centred in the lane; a clip: an "
                          "--intrinsics profile's, else 0)")
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


def _bonnet_polygon(spec: str) -> np.ndarray:
    """The polygon of a ``--bonnet FILE``."""
    return _pixel_list(_read_json(Path(spec), "--bonnet"), f"--bonnet {spec}: polygon")


def _bonnet_file(spec: str, width: int, height: int) -> Bonnet:
    """``--bonnet FILE`` for a ``width``×``height`` image."""
    poly = _bonnet_polygon(spec)
    try:
        bonnet = Bonnet.polygon(poly)
        bonnet.check_inside(width, height)
    except ValueError as exc:
        raise CliError(f"--bonnet: {exc}") from None
    return bonnet


def _single_bonnet(spec: str, frame: np.ndarray) -> Bonnet:
    """``--bonnet`` for one image: ``auto`` is its dark bonnet's edge (``detect_bonnet``)."""
    if spec == "none":
        return Bonnet.none()
    if spec == "auto":
        try:
            return Bonnet.polygon(detect_bonnet(frame))
        except ValueError as exc:
            if isinstance(exc, MountFitError):
                raise
            raise CliError(f"--bonnet auto: {exc}") from None
    return _bonnet_file(spec, frame.shape[1], frame.shape[0])


def _clip_bonnet(spec: str, frames: list[ClipFrame], marking_width_px: int
                 ) -> tuple[Bonnet, list[str]]:
    """``--bonnet`` for a clip: ``auto`` is what stays put while the road moves
    (``static_body``; with fewer frames the first one's dark bonnet edge, or none)."""
    h, w = frames[0].image.shape
    if spec == "none":
        return Bonnet.none(), []
    if spec != "auto":
        return _bonnet_file(spec, w, h), []
    if len(frames) < STATIC_MIN_FRAMES:
        try:
            return Bonnet.polygon(detect_bonnet(frames[0].image)), [
                "bonnet: the first frame's dark edge (too few frames to see what stays put)"]
        except MountFitError:
            return Bonnet.none(), ["bonnet: none found (too few frames to see what stays put)"]
    poly, notes = static_body([f.image for f in frames], marking_width_px)
    try:
        bonnet = Bonnet.none() if poly is None else Bonnet.polygon(poly)
        bonnet.check_inside(w, h)
    except ValueError:  # never above the lower half by construction; be safe
        bonnet, notes = Bonnet.none(), [*notes, "the body found reaches too high: none kept"]
    return bonnet, ["bonnet: " + "; ".join(notes)]


def _search_mask(bonnet: Bonnet, width: int, height: int) -> np.ndarray | None:
    """The marking search's mask for ``bonnet`` (None: no body in view)."""
    if not bonnet.enabled:
        return None
    return body_search_mask(bonnet.mask(width, height))


def _spread_json(spread: Spread) -> dict[str, float]:
    return {"median": spread.median, "sigma": spread.sigma, "q25": spread.q25,
            "q75": spread.q75, "frames": spread.n}


def fit_summary(fit: MountFit) -> dict[str, Any]:
    """The figures ``camera fit`` reports."""
    m = fit.camera.mount
    return {
        "residual_px": fit.residual_px, "height_m": m.height_m, "lateral_m": m.lateral_m,
        "forward_m": m.forward_m, "pitch_deg": math.degrees(m.pitch_rad),
        "roll_deg": math.degrees(m.roll_rad), "yaw_deg": math.degrees(m.yaw_rad),
        "roll_fitted": fit.roll_fitted, "focal_px": float(fit.camera.K[0, 0]),
        "lens": fit.camera.lens.value, "lane_width_m": fit.lane_width_m,
        "frame_rate_hz": fit.camera.frame_rate_hz,
        "lines": [{"role": ln.role, "pixels": len(ln.pixels), "coverage": ln.coverage}
                  for ln in fit.lines],
    }


@dataclass
class _Job:
    """What ``camera fit`` read: the frames (one for an image), where the intrinsics and
    the frame rate come from, and the notes to print."""

    frames: list[ClipFrame]
    single: bool
    base: Camera | None  # None: --fit-focal
    intrinsics_from: str
    frame_rate_hz: float | None
    frame_rate_from: str
    source_frames: int
    notes: list[str]
    heading_frames: list[ClipFrame] | None = None
    """More frames, smaller, whose road directions give the yaw (a clip's)."""


def _base_camera(args: argparse.Namespace, width: int, height: int,
                 camera_info: Any | None, where: str) -> tuple[Camera | None, str, float | None]:
    """The camera whose intrinsics are kept (None: ``--fit-focal``), where they come from,
    and an ``--intrinsics`` profile's frame rate."""
    forward = args.forward_m
    if args.fit_focal:
        return None, "--fit-focal", None
    if args.intrinsics is None:
        if camera_info is None:
            raise CliError(f"{args.source}: the recording has no camera_info; give the lens' "
                           "calibration (--intrinsics) or fit its focal length (--fit-focal)")
        try:
            intr = intrinsics_from_camera_info(
                f"{where}: camera_info", camera_info.width_px, camera_info.height_px,
                camera_info.K, camera_info.D, camera_info.distortion_model)
        except CameraFileError as exc:
            raise CliError(str(exc)) from None
        mount = CameraMount(forward_m=DEFAULT_MOUNT_FORWARD_M if forward is None else forward)
        return intr.camera(mount), "the recording's camera_info", None
    try:
        intr = load_intrinsics(args.intrinsics, LensModel(args.lens) if args.lens else None)
    except CameraFileError as exc:
        raise CliError(f"--intrinsics: {exc}") from None
    base = intr.camera(CameraMount())
    rate = None
    if args.lens is None:
        try:  # a profile as --intrinsics: keep its forward and lateral offset, frame rate
            own = load_camera(args.intrinsics)
            base = base.replace(mount=CameraMount(forward_m=own.mount.forward_m,
                                                  lateral_m=own.mount.lateral_m))
            rate = own.frame_rate_hz
        except CameraFileError:
            pass  # a calibration file: no mount, the defaults
    if forward is not None:
        base = base.with_mount(forward_m=forward)
    if (base.width, base.height) != (width, height):
        raise CliError(f"{args.source}: the frames are {width}×{height}, the --intrinsics "
                       f"are for {base.width}×{base.height}")
    return base, "--intrinsics", rate


def _read_job(args: argparse.Namespace) -> _Job:
    """The frames of SOURCE: one image (read as before), or a clip through ``open_source``
    (sampled, ``MAX_CLIP_FRAMES`` at most)."""
    path = Path(args.source)
    if path.is_file() and cv2.haveImageReader(str(path)) and args.topic is None \
            and args.frames is None:
        frame = _read_frame(path)
        h, w = frame.shape
        base, src, rate = _base_camera(args, w, h, None, str(path))
        rate, rate_from = ((args.rate, "--rate") if args.rate is not None else
                           (rate, "the --intrinsics profile") if rate is not None else
                           (None, "not in an image: the default"))
        return _Job([ClipFrame(0, 0.0, frame)], True, base, src, rate, rate_from, 1, [])
    from ..sources import SourceError, open_source
    from ..sources.base import to_grey

    try:
        source = open_source(args.source, topic=args.topic, frames=args.frames,
                             rate_hz=args.rate)
        info = source.info
        size = (info.width_px, info.height_px)
        seen = 0
        headings = HeadingSample()

        def grey() -> Iterator[ClipFrame]:
            nonlocal seen
            for f in source.frames():
                seen += 1
                frame = ClipFrame(f.index, f.t_s, to_grey(f.image, size))
                headings.add(frame)
                yield frame

        frames = sample_frames(grey())
    except SourceError as exc:
        raise CliError(str(exc)) from None
    if not frames:
        within = f" in --frames {args.frames}" if args.frames else ""
        raise CliError(f"{args.source}: no frames{within}")
    base, src, rate = _base_camera(args, size[0], size[1], info.camera_info, str(path))
    if info.rate_hz is not None:
        rate, rate_from = info.rate_hz, ("--rate" if args.rate is not None else "the recording")
        if not MIN_FRAME_RATE_HZ <= rate <= MAX_FRAME_RATE_HZ:
            raise CliError(f"{args.source}: the recording's frame rate {rate:g} Hz is outside "
                           f"{MIN_FRAME_RATE_HZ:g}–{MAX_FRAME_RATE_HZ:g} Hz (a model car's "
                           "camera); give the camera's rate with --rate")
    else:
        rate_from = "the --intrinsics profile" if rate is not None else \
            "not in the recording: the default (set it with --rate)"
    notes = list(info.notes)
    return _Job(frames, len(frames) == 1, base, src, rate, rate_from, seen, notes,
                headings.frames)


def _overlay_png(path: Path, image: np.ndarray) -> None:
    """Write the overlay (refused: a CliError)."""
    if not cv2.imwrite(str(path), image):
        raise CliError(f"--overlay {path}: OpenCV could not write the PNG")


def _refusal(args: argparse.Namespace, overlay: Path, exc: MountFitError,
             frame: np.ndarray | None, bonnet: Bonnet | None, where: str) -> CliError:
    """A refused fit: its overlay written for inspection when it found lines, and the
    one-line error naming the parameter and the overlay."""
    if frame is not None and (exc.lines or exc.camera is not None):
        camera = exc.camera.replace(bonnet=bonnet) if exc.camera is not None and bonnet \
            is not None else exc.camera
        body = bonnet.polygon_px if bonnet is not None else None
        with Outputs() as outs:
            _overlay_png(outs.path(overlay), draw_fit(
                frame, exc.lines, camera, lane_width_m=exc.lane_width_m, body=body,
                text=[f"REFUSED ({where}): {exc}"], refused=True))
            outs.commit()
        return CliError(f"{args.source}: {exc} (see {overlay})")
    return CliError(f"{args.source}: {exc}")


def cmd_camera_fit(args: argparse.Namespace) -> int:
    overlay = args.overlay or args.out.with_name(args.out.stem + "-fit.png")
    intrinsics = camera_input(str(args.intrinsics)) if args.intrinsics else None  # a file
    source = Path(args.source)
    check_outputs({"out": args.out, "overlay": overlay}, {"out": ".yaml", "overlay": ".png"},
                  args.force, inputs={"source": source if source.is_file() else None,
                                      "intrinsics": intrinsics, "points": args.points,
                                      "bonnet": None if args.bonnet in ("auto", "none")
                                      else Path(args.bonnet)})
    for name in ("forward_m", "lateral_m"):
        value = getattr(args, name)
        limit = 1.0 if name == "forward_m" else MAX_MOUNT_LATERAL_M
        if value is not None and not (math.isfinite(value) and -limit <= value <= limit):
            raise CliError(f"--{name.replace('_', '-')} must be a finite distance in "
                           f"[{-limit:g}, {limit:g}] m, got {value}")
    if args.lens and not args.intrinsics:
        raise CliError("--lens names the model of an --intrinsics file; give one, or drop it")
    if args.fit_focal and args.points:
        raise CliError("--points needs known intrinsics (--intrinsics), not --fit-focal")
    points = _points(args.points) if args.points else None
    if args.bonnet not in ("auto", "none"):
        _bonnet_polygon(args.bonnet)  # a bad file refused before the fit's work
    job = _read_job(args)
    if points is not None and not job.single:
        raise CliError("--points marks the lines of one image; SOURCE is a clip of "
                       f"{len(job.frames)} frames")
    if job.single:
        result = _fit_single(args, job, points, overlay)
    else:
        result = _fit_clip(args, job, overlay)
    camera, image, summary, lines = result
    if job.frame_rate_hz is not None:
        camera = camera.replace(frame_rate_hz=float(job.frame_rate_hz))
    summary.update(frame_rate_hz=camera.frame_rate_hz, frame_rate_from=job.frame_rate_from,
                   intrinsics_from=job.intrinsics_from, notes=job.notes)
    with Outputs() as outs:  # the profile and its overlay, or neither
        outs.path(args.out).write_text(profile_text(camera, args.description),
                                       encoding="utf-8")
        _overlay_png(outs.path(overlay), image)
        outs.commit()
    summary.update(out=str(args.out), overlay=str(overlay))
    if args.json:
        print(json_text(summary))
    else:
        _print_summary(summary, lines)
    return 0


def _fit_single(args: argparse.Namespace, job: _Job, points: list[np.ndarray | None] | None,
                overlay: Path) -> tuple[Camera, np.ndarray, dict[str, Any], list[str]]:
    """One image, as the car parked in the lane: its own fit."""
    frame = job.frames[0].image
    h, w = frame.shape
    # A polygon given (--bonnet FILE) keeps the search off the body; the edge found in
    # the image (auto, after the fit as before) is checked after: the search's own rules
    # (lines through one vanishing point, below the horizon) keep a bonnet's reflections
    # out, and a fit through the found edge's pixels would differ from the frame's own.
    bonnet = None if args.bonnet == "auto" else _single_bonnet(args.bonnet, frame)
    mask = None if bonnet is None else _search_mask(bonnet, w, h)
    try:
        if job.base is None:
            fit = fit_focal(frame, w, h, lane_width_m=args.lane_width, mask=mask,
                            lateral_m=args.lateral_m)
            if args.forward_m is not None:
                fit = _with_forward(fit, args.forward_m)
        else:
            fit = fit_mount(frame, job.base, points=points, forward_m=args.forward_m,
                            lane_width_m=args.lane_width, mask=mask, lateral_m=args.lateral_m)
        if bonnet is None:
            bonnet = _single_bonnet(args.bonnet, frame)
            body = _search_mask(bonnet, w, h)
            if body is not None:
                lines_off_body(fit.lines, body)
    except MountFitError as exc:
        raise _refusal(args, overlay, exc, frame, bonnet, "one frame") from None
    fit = MountFit(fit.camera.replace(bonnet=bonnet), fit.lines, fit.residual_px,
                   fit.roll_fitted, fit.focal_px, fit.lane_width_m)
    summary = fit_summary(fit)
    summary.update(frames={"source": 1, "tried": 1, "fitted": 1, "used": 1}, spread=None)
    text = [f"one frame: residual {fit.residual_px:.2f} px, height "
            f"{fit.camera.mount.height_m * 1000:.0f} mm"]
    return fit.camera, fit_overlay(frame, fit, text), summary, []


def _fit_clip(args: argparse.Namespace, job: _Job, overlay: Path
              ) -> tuple[Camera, np.ndarray, dict[str, Any], list[str]]:
    """A clip: the frames of straight road fitted one by one, combined."""
    h, w = job.frames[0].image.shape
    f_px = None if job.base is None else float(np.sqrt(job.base.K[0, 0] * job.base.K[1, 1]))
    width_px = SearchScale.for_image(w, h, f_px).marking_width_px
    bonnet, bonnet_notes = _clip_bonnet(args.bonnet, job.frames, width_px)
    job.notes.extend(bonnet_notes)
    mask = _search_mask(bonnet, w, h)
    focal = None
    try:
        if job.base is None:
            base, focal = clip_focal(job.frames, mask=mask, lane_width_m=args.lane_width)
            base = base.replace(mount=CameraMount(
                forward_m=DEFAULT_MOUNT_FORWARD_M if args.forward_m is None
                else args.forward_m))
        else:
            base = job.base
        base = base.replace(bonnet=bonnet)
        lateral = base.mount.lateral_m if args.lateral_m is None else args.lateral_m
        clip = fit_clip(job.frames, base, mask=mask, lane_width_m=args.lane_width,
                        lateral_m=lateral, heading_frames=job.heading_frames)
        if focal is not None:
            clip.spreads["focal_px"] = focal
    except ClipFitError as exc:
        frame = None
        if exc.frame is not None:
            frame = next(f.image for f in job.frames if f.index == exc.frame.index)
        raise _refusal(args, overlay, exc, frame, bonnet,
                       f"frame {exc.frame.index}" if exc.frame else "clip") from None
    except MountFitError as exc:
        raise CliError(f"{args.source}: {exc}") from None
    fit = clip.shown_fit
    shown = next(f.image for f in job.frames if f.index == clip.shown.index)
    m = clip.camera.mount
    summary = fit_summary(MountFit(clip.camera, fit.lines, clip.residual_px, clip.roll_fitted,
                                   fit.focal_px, clip.lane_width_m))
    summary.update(
        frames={"source": job.source_frames, "tried": len(job.frames),
                "fitted": clip.fitted, "used": clip.used, "shown": clip.shown.index},
        spread={k: _spread_json(v) for k, v in clip.spreads.items()})
    job.notes.extend(clip.notes)
    sp = clip.spreads
    text = [f"clip: {clip.used} of {len(job.frames)} frames agree (frame {clip.shown.index} "
            f"shown), residual {clip.residual_px:.2f} px",
            f"height {m.height_m * 1000:.0f} ± {sp['height_m'].sigma * 1000:.1f} mm, pitch "
            f"{math.degrees(m.pitch_rad):.2f} ± {sp['pitch_deg'].sigma:.2f}°, roll "
            f"{math.degrees(m.roll_rad):.2f} ± {sp['roll_deg'].sigma:.2f}°, yaw "
            f"{math.degrees(m.yaw_rad):.2f}° (heading ± {sp['heading_deg'].sigma:.1f}°)"]
    lines = [f"frames         {clip.used} of {len(job.frames)} agree ({clip.fitted} fitted by "
             f"themselves; {job.source_frames} in the source; the heading from "
             f"{sp['heading_deg'].n})",
             "spread (σ)     " + ", ".join(
                 f"{k} {_spread_text(k, v)}" for k, v in sp.items()),
             f"car            heading ±{sp['heading_deg'].sigma:.1f}° about the lane's "
             f"direction, {sp['car_offset_m'].median * 1000:+.0f} ± "
             f"{sp['car_offset_m'].sigma * 1000:.0f} mm left of the lane's centre (not the "
             "mount's)"]
    return clip.camera, fit_overlay(shown, fit, text), summary, lines


def _spread_text(name: str, spread: Spread) -> str:
    if name.endswith("_m"):
        return f"{spread.sigma * 1000:.1f} mm"
    if name.endswith("_deg"):
        return f"{spread.sigma:.2f}°"
    return f"{spread.sigma:.2f} px"


def _print_summary(summary: dict[str, Any], lines: list[str]) -> None:
    print(f"fitted mount   height {summary['height_m'] * 1000:.1f} mm, lateral "
          f"{summary['lateral_m'] * 1000:+.1f} mm, pitch {summary['pitch_deg']:.2f}°, roll "
          f"{summary['roll_deg']:.2f}°{'' if summary['roll_fitted'] else ' (not fitted: 2 lines)'},"
          f" yaw {summary['yaw_deg']:.2f}°")
    print(f"lens           {summary['lens']}, focal {summary['focal_px']:.1f} px "
          f"({summary['intrinsics_from']})")
    print("lines          " + ", ".join(f"{ln['role']} ({ln['pixels']} px)"
                                        for ln in summary["lines"])
          + f", {summary['lane_width_m']:g} m apart")
    for line in lines:
        print(line)
    print(f"residual       {summary['residual_px']:.2f} px")
    print(f"frame rate     {summary['frame_rate_hz']:g} Hz ({summary['frame_rate_from']})")
    for note in summary["notes"]:
        print(f"note           {note}")
    print(f"wrote          {summary['out']}, {summary['overlay']}")


def _with_forward(fit: MountFit, forward_m: float) -> MountFit:
    cam = fit.camera.with_mount(forward_m=forward_m)
    return MountFit(cam, fit.lines, fit.residual_px, fit.roll_fitted, fit.focal_px,
                    fit.lane_width_m)


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
