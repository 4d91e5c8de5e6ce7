"""The replay's command: ``replay`` (a recording in an endless loop through a detector)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from ..camera.command import add_camera_option, camera_input
from ..cli_common import (
    RECORDING_SUFFIXES,
    CliError,
    add_force_option,
    add_json_option,
    add_recording_options,
    check_outputs,
    json_text,
    positive_int_arg,
    recording_outputs,
)
from ..fileio import WriteError
from ..perception.command import check_camera_geometry
from ..sources import SourceError
from ..sources.command import add_source_options
from .loop import OUT_BYTES_PER_FRAME, Detector, HoughPreset, replay

_GROWTH = (f"≈ {OUT_BYTES_PER_FRAME[0] / 1000:g}–{OUT_BYTES_PER_FRAME[1] / 1000:g} kB a frame, "
           "about 1 GB an hour")
"""How --out grows with --forever (said in --help and when it starts)."""


def register(sub: Any) -> None:
    """Add ``replay`` to the ``tfalda-sim`` subparsers."""
    rp = sub.add_parser(
        "replay", help="replay a recording (video, images, ROS bag, MCAP) through a lane "
                       "detector",
        description="Read SOURCE in an endless loop (the second seed's set-up), run the Hough "
                    "baseline or TFALDA + LIS on every frame, report frames/s and detections. "
                    "SOURCE: a video file, an image folder or glob (natural order), a ROS 1 "
                    ".bag, a ROS 2 bag folder (sqlite3 or MCAP storage) or an MCAP file. "
                    "Colour and other frame sizes are converted to the camera's grey size. "
                    "Ctrl-C stops cleanly. See docs/recordings.md.")
    rp.add_argument("source", type=Path,
                    help="the recording (e.g. from tfalda-sim drive --camera-video or --mcap)")
    add_source_options(rp)
    rp.add_argument("--detector", choices=[d.value for d in Detector], required=True,
                    help="the lane detector")
    times = rp.add_mutually_exclusive_group()
    # default None, not 1: argparse lets an excluded option through when its value is the
    # default's very object (`--loops=1 --forever` was accepted)
    times.add_argument("--loops", type=positive_int_arg,
                       help="passes over the video (default 1)")
    times.add_argument("--forever", action="store_true",
                       help=f"loop until Ctrl-C (or --max-frames); --out grows {_GROWTH}")
    rp.add_argument("--max-frames", type=positive_int_arg, metavar="N",
                    help="stop after N frames (with --loops: whichever comes first); "
                         "bounds --out with --forever")
    rp.add_argument("--hough-preset", choices=[p.value for p in HoughPreset],
                    help="hough: the seed's numbers, the simulator preset (default; the "
                         "seed's 0.9 threshold finds no rendered marking) or real (a real "
                         "camera's frames, binarised at 0.6)")
    rp.add_argument("--out", type=Path, help="annotated MP4 (segments or ROIs and lanes)")
    rp.add_argument("--per-frame", type=Path, metavar="F.jsonl",
                    help="one JSON line a frame: frame, loop, t_s, and lanes, accepted, "
                         "fault_counter, roi_reset, state (tfalda) or segments (hough)")
    add_recording_options(rp, "the replay (frames, lanes or segments, LIS state)")
    rp.add_argument("--stages", action="store_true",
                    help="hough: write the seed's 2×2 stage view to --out instead")
    add_camera_option(rp)
    add_force_option(rp, "an existing --out")
    add_json_option(rp)
    rp.set_defaults(func=cmd_replay)


def cmd_replay(args: argparse.Namespace) -> int:
    check_outputs({"out": args.out, "per-frame": args.per_frame, **recording_outputs(args)},
                  {"out": ".mp4", "per-frame": ".jsonl", **RECORDING_SUFFIXES}, args.force,
                  inputs={"source": args.source, "camera": camera_input(args.camera)})
    camera = check_camera_geometry(args.camera)
    if args.hough_preset is not None and args.detector != Detector.HOUGH.value:
        raise CliError("--hough-preset sets the Hough baseline; it does nothing with "
                       f"--detector {args.detector}: drop it")
    args.hough_preset = args.hough_preset or HoughPreset.SIMULATOR.value
    if args.stages and (args.detector != Detector.HOUGH.value or args.out is None):
        raise CliError("--stages writes the Hough stage view: use it with --detector hough "
                       "and --out F.mp4")
    if args.forever and args.out is not None and args.max_frames is None:
        print(f"note: {args.out} grows {_GROWTH} until Ctrl-C; --max-frames N bounds it",
              file=sys.stderr)
    try:
        result = replay(args.source, Detector(args.detector),
                        loops=None if args.forever else (args.loops or 1), out=args.out,
                        hough=HoughPreset(args.hough_preset), stages=args.stages,
                        progress=sys.stderr.isatty() or not args.json, camera=camera,
                        max_frames=args.max_frames, topic=args.topic, frames=args.frames,
                        rate_hz=args.rate, per_frame=args.per_frame, mcap=args.mcap,
                        rosbag=args.rosbag)
        result["camera"] = args.camera
    except (FileNotFoundError, SourceError, WriteError) as exc:
        raise CliError(str(exc)) from None
    except OSError as exc:
        raise CliError(f"cannot write {args.out}: {exc.strerror or exc}") from None
    # An interrupted --loops N did not finish what was asked; --forever ends that way.
    code = 130 if result["stopped"] == "interrupted" and not args.forever else 0
    if args.json:
        print(json_text(result))
        return code
    topic = f" {result['topic']}" if result["topic"] else ""
    loops = result["loops_completed"]
    recorded = (f"recorded at {result['recording_rate_hz']:.3g} frames/s"
                if result["recording_rate_hz"] else "no recorded frame rate")
    print(f"{result['source']} ({result['kind']}{topic}, {recorded}): {result['frames']} "
          f"frames, {loops} loop{'' if loops == 1 else 's'} ({result['stopped']}), processed at "
          f"{result['frames_per_s'] or 0:.0f} frames/s, detector "
          f"{result['detector_ms_median'] or 0:.2f} ms/frame")
    what = "segments" if args.detector == Detector.HOUGH.value else "lanes"
    print(f"{args.detector}: {result['detections_per_frame'] or 0:.2f} {what}/frame, "
          f"{result['frames_without_detection']} frames without any"
          + (f", {result['roi_resets']} LIS resets" if result["roi_resets"] is not None
             else ""))
    if result["conversions"]:
        print("converted: " + ", ".join(result["conversions"]))
    for key in ("rate_note", "camera_info_note"):
        if result[key]:
            print(f"note: {result[key]}")
    for key in ("out", "per_frame", "recording"):
        if result[key]:
            print(f"wrote {result[key]}")
    return code
