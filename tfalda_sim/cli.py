"""The ``tfalda-sim`` command line.

Every command that reports figures takes ``--json`` (one JSON object on stdout). Exit
codes: 0 success, 1 the command ran but the result is negative (an invalid track),
2 bad input (unreadable file, unknown option, refused overwrite).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from tfalda_sim.agents.command import (
    add_drive_parser,
    add_evaluate_agent_parser,
    add_stress_parser,
    add_train_parser,
)
from tfalda_sim.cli_common import (
    EXIT_BAD_INPUT,
    EXIT_NEGATIVE,
    EXIT_OK,
    CliError,
    check_outputs,
    finite_float_arg,
    interrupted,
    seed_arg,
)
from tfalda_sim.outputs import OutputError, Outputs
from tfalda_sim.tracks.fileformat import TrackFileError, load_track, save_track
from tfalda_sim.tracks.generator import GeneratorParams, generate
from tfalda_sim.tracks.model import Track
from tfalda_sim.tracks.named import NAMED_TRACKS, named_path
from tfalda_sim.tracks.preview import write_preview
from tfalda_sim.tracks.rules import MAT_EDGE_MARGIN_M, Violation, validate

from .evaluation.command import add_compare_parser, add_evaluate_parser
from .replay import add_replay_parser


def track_summary(track: Track, violations: list[Violation]) -> dict[str, Any]:
    """The figures ``track generate`` and ``track validate`` report."""
    xmin, ymin, xmax, ymax = track.bounds(MAT_EDGE_MARGIN_M)
    r = track.min_centre_radius_m
    return {
        "name": track.name,
        "seed": track.seed,
        "valid": not violations,
        "violations": [v.to_dict() for v in violations],
        "closed": track.closed,
        "length_m": track.length_m,
        "min_centre_radius_m": r if math.isfinite(r) else None,
        "segments": len(track.segments),
        "intersections": len(track.intersections),
        "gaps": len(track.gaps),
        "obstacles": len(track.obstacles),
        "mat_size_m": [xmax - xmin, ymax - ymin],
    }


def _print_summary(summary: dict[str, Any]) -> None:
    r = summary["min_centre_radius_m"]
    print(f"track        {summary['name'] or '-'}"
          + (f" (seed {summary['seed']})" if summary["seed"] is not None else ""))
    print(f"valid        {'yes' if summary['valid'] else 'NO'}")
    print(f"length       {summary['length_m']:.2f} m, {summary['segments']} segments, "
          f"{'closed' if summary['closed'] else 'open'}")
    print(f"min radius   {'-' if r is None else f'{r:.3f} m'} (centre line)")
    print(f"elements     {summary['intersections']} intersections, {summary['gaps']} gaps, "
          f"{summary['obstacles']} obstacles")
    print(f"mat          {summary['mat_size_m'][0]:.2f} m × {summary['mat_size_m'][1]:.2f} m")
    for v in summary["violations"]:
        print(f"  ✗ {v['field']}: {v['message']} (rule {v['rule']})")
    for key in ("out", "png"):
        if key in summary:
            print(f"{'wrote':12} {summary[key]}")


def _cmd_track_generate(args: argparse.Namespace) -> int:
    check_outputs({"out": args.out, "png": args.png}, {"out": ".json", "png": ".png"},
                  args.force)
    track = generate(args.seed, GeneratorParams(difficulty=args.difficulty))
    summary = track_summary(track, validate(track))
    with Outputs() as outs:  # both files or neither
        if args.out:
            save_track(track, outs.path(args.out), overwrite=True)
            summary["out"] = str(args.out)
        if args.png:
            write_preview(track, outs.path(args.png), overwrite=True)
            summary["png"] = str(args.png)
        outs.commit()
    _emit(summary, args.json)
    return 0 if summary["valid"] else 1


def _resolve_track_file(name_or_path: str) -> Path:
    if name_or_path in NAMED_TRACKS:
        return named_path(name_or_path)
    return Path(name_or_path)


def _cmd_track_validate(args: argparse.Namespace) -> int:
    path = _resolve_track_file(args.file)
    try:
        track = load_track(path, check_rules=False)
    except TrackFileError as exc:
        raise CliError(str(exc)) from None
    summary = track_summary(track, validate(track))
    summary["file"] = str(path)
    _emit(summary, args.json)
    return 0 if summary["valid"] else 1


def _cmd_track_list(args: argparse.Namespace) -> int:
    rows = []
    for name in NAMED_TRACKS:
        track = load_track(named_path(name))
        rows.append({"name": name, "length_m": track.length_m, "closed": track.closed,
                     "description": track.description})
    if args.json:
        print(json.dumps({"tracks": rows}))
    else:
        for row in rows:
            print(f"{row['name']:14} {row['length_m']:7.2f} m  "
                  f"{'closed' if row['closed'] else 'open  '}  {row['description']}")
    return 0


def _load_track_arg(text: str) -> Track:
    """A named track, a seed (generated track) or a track file."""
    if text in NAMED_TRACKS:
        return load_track(named_path(text))
    if text.isdigit():
        return generate(int(text))
    path = Path(text)
    if path.suffix.lower() == ".json":
        try:
            return load_track(path)
        except TrackFileError as exc:
            raise CliError(str(exc)) from None
    raise CliError(f"--track {text!r} is neither a named track ({', '.join(NAMED_TRACKS)}), "
                   "a seed (a non-negative integer) nor a .json track file")


def _write_png(path: Path, image: np.ndarray) -> None:
    ok, buf = cv2.imencode(".png", image)
    if not ok:
        raise CliError(f"could not encode {path}")
    path.write_bytes(buf.tobytes())


def _cmd_render(args: argparse.Namespace) -> int:
    from tfalda_sim.rendering import (
        DomainRandomization,
        Effects,
        Renderer,
        build_scene,
        frame_truth,
    )

    track_file = Path(args.track) if args.track.lower().endswith(".json") else None
    check_outputs({"out": args.out, "truth": args.truth}, {"out": ".png", "truth": ".png"},
                  args.force, inputs={"track": track_file})
    track = _load_track_arg(args.track)
    if not track.closed and not 0.0 <= args.s <= track.length_m:
        raise CliError(f"--s {args.s} m is outside the open track [0, {track.length_m:.2f}] m")
    rng = np.random.default_rng(args.seed)
    effects = {"off": Effects.off, "default": Effects,
               "random": lambda: DomainRandomization().sample(rng)}[args.effects]()
    x, y, h = (float(v) for v in track.pose(args.s, args.lateral))
    pose = (x, y, h + args.heading)
    renderer = Renderer()
    try:
        scene = build_scene(track, effects, rng)
    except ValueError as exc:  # a legal but huge track: the marking map's pixel cap
        raise CliError(f"--track {args.track}: cannot render this track: {exc}") from None
    renderer.render(scene, pose, frame_seed=args.seed)  # warm-up (JIT, caches) for the timing
    t0 = time.perf_counter()
    frame = renderer.render(scene, pose, frame_seed=args.seed)
    render_ms = 1000.0 * (time.perf_counter() - t0)
    summary: dict[str, Any] = {
        "track": track.name, "s_m": args.s, "lateral_m": args.lateral,
        "heading_rad": args.heading, "pose": list(pose), "effects": asdict(effects),
        "render_ms": render_ms, "out": str(args.out),
    }
    with Outputs() as outs:  # the frame and the truth picture, or neither
        _write_png(outs.path(args.out), frame)
        if args.truth is not None:
            truth = frame_truth(track, renderer.camera, pose, s_hint_m=args.s)
            picture = truth.colour()
            for line in (truth.left_boundary_px, truth.right_boundary_px):
                if len(line) > 1:
                    cv2.polylines(picture, [np.rint(line).astype(np.int32)], False,
                                  (0, 255, 0), 1, cv2.LINE_AA)
            _write_png(outs.path(args.truth), picture)
            summary["truth"] = str(args.truth)
        outs.commit()
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"rendered {track.name} at s = {args.s:.2f} m, lateral {args.lateral:+.2f} m, "
              f"heading {args.heading:+.3f} rad in {render_ms:.2f} ms")
        for key in ("out", "truth"):
            if key in summary:
                print(f"wrote {summary[key]}")
    return 0


def _emit(summary: dict[str, Any], as_json: bool) -> None:
    if as_json:
        print(json.dumps(summary))
    else:
        _print_summary(summary)


def _difficulty(text: str) -> float:
    value = float(text)
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"difficulty must be in [0, 1], got {text}")
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="tfalda-sim", description="Carolo-Cup lane-keeping simulator (tfalda-sim).")
    sub = parser.add_subparsers(dest="command", required=True)

    track = sub.add_parser("track", help="generate, validate and list tracks")
    track_sub = track.add_subparsers(dest="track_command", required=True)

    gen = track_sub.add_parser("generate", help="generate a track for a seed (scenario id)")
    gen.add_argument("--seed", type=seed_arg, required=True, help="scenario id (≥ 0)")
    gen.add_argument("--difficulty", type=_difficulty, default=GeneratorParams().difficulty,
                     help="0 (wide curves, clean markings) … 1 (tight curves, gaps, obstacles)")
    gen.add_argument("--out", type=Path, help="write the track file (JSON) here")
    gen.add_argument("--png", type=Path, help="write a preview PNG here")
    gen.add_argument("--force", action="store_true", help="overwrite existing output files")
    gen.add_argument("--json", action="store_true", help="print one JSON object")
    gen.set_defaults(func=_cmd_track_generate)

    val = track_sub.add_parser("validate", help="check a track file against the rules")
    val.add_argument("file", help="track file (JSON) or a named track: " + ", ".join(NAMED_TRACKS))
    val.add_argument("--json", action="store_true", help="print one JSON object")
    val.set_defaults(func=_cmd_track_validate)

    lst = track_sub.add_parser("list", help="list the named tracks")
    lst.add_argument("--json", action="store_true", help="print one JSON object")
    lst.set_defaults(func=_cmd_track_list)

    ren = sub.add_parser("render", help="render one camera frame of a track")
    ren.add_argument("--track", required=True,
                     help="named track, seed (generated track) or track file (.json)")
    ren.add_argument("--s", type=finite_float_arg, required=True, help="arc length of the car [m]")
    ren.add_argument("--lateral", type=finite_float_arg, default=-0.2,
                     help="lateral offset from the centre line [m], left > 0 (default: the "
                          "middle of the right lane)")
    ren.add_argument("--heading", type=finite_float_arg, default=0.0,
                     help="heading relative to the road [rad], left > 0")
    ren.add_argument("--out", type=Path, required=True, help="frame PNG (752×480 grayscale)")
    ren.add_argument("--truth", type=Path, help="ground-truth PNG (labels in colour, ego lane "
                                                "boundaries in green)")
    ren.add_argument("--effects", choices=("off", "default", "random"), default="default",
                     help="photometric effects (random: drawn with --seed)")
    ren.add_argument("--seed", type=seed_arg, default=0,
                     help="seed of the random effects, the scene layout and the sensor noise")
    ren.add_argument("--force", action="store_true", help="overwrite existing output files")
    ren.add_argument("--json", action="store_true", help="print one JSON object")
    ren.set_defaults(func=_cmd_render)

    add_evaluate_parser(sub)
    add_compare_parser(sub)
    add_drive_parser(sub)
    add_train_parser(sub)
    add_stress_parser(sub)
    add_evaluate_agent_parser(sub)
    add_replay_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command and return its exit code (``tfalda_sim.cli_common``); a bad
    argument is reported with the usage and returns 2 (``--help`` returns 0)."""
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:  # argparse has printed the usage and the error
        return exc.code if isinstance(exc.code, int) else EXIT_BAD_INPUT
    try:
        return int(args.func(args))
    except (CliError, OutputError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except SystemExit as exc:  # a handler's parser.error(): usage and message printed
        return exc.code if isinstance(exc.code, int) else EXIT_BAD_INPUT
    except KeyboardInterrupt:
        # The long commands catch Ctrl-C themselves and keep what they finished; here
        # it struck before any result existed.
        return interrupted("stopped before any result was finished; nothing written")
    except BrokenPipeError:
        # stdout closed by its reader (`… | head`): the files are written, stop quietly.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_OK
    except OSError as exc:
        print(f"error: {exc.strerror or exc}"
              + (f": {exc.filename}" if exc.filename else ""), file=sys.stderr)
        return EXIT_BAD_INPUT
    except Exception as exc:  # a bug: one line, the traceback on demand
        if os.environ.get("TFALDA_SIM_DEBUG"):
            raise
        print(f"internal error: {type(exc).__name__}: {exc} (set TFALDA_SIM_DEBUG=1 for the "
              "traceback and please report it)", file=sys.stderr)
        return EXIT_NEGATIVE


if __name__ == "__main__":
    sys.exit(main())
