"""The ``tfalda-sim`` command line.

Every command that reports figures takes ``--json`` (one JSON object on stdout). Exit
codes: 0 success, 1 the command ran but the result is negative (an invalid track),
2 bad input (unreadable file, unknown option, refused overwrite).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from tracks.fileformat import TrackFileError, load_track, save_track
from tracks.generator import GeneratorParams, generate
from tracks.model import Track
from tracks.named import NAMED_TRACKS, named_path
from tracks.preview import write_preview
from tracks.rules import MAT_EDGE_MARGIN_M, Violation, validate


class CliError(Exception):
    """Bad input: printed as ``error: …`` with exit code 2."""


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
    outputs = [p for p in (args.out, args.png) if p is not None]
    if args.out is not None and args.out.suffix.lower() != ".json":
        raise CliError(f"--out must name a .json file, got {args.out}")
    if args.png is not None and args.png.suffix.lower() != ".png":
        raise CliError(f"--png must name a .png file, got {args.png}")
    existing = [str(p) for p in outputs if p.exists()]
    if existing and not args.force:
        raise CliError(f"{', '.join(existing)} exists; add --force to overwrite")
    track = generate(args.seed, GeneratorParams(difficulty=args.difficulty))
    summary = track_summary(track, validate(track))
    if args.out:
        summary["out"] = str(save_track(track, args.out, overwrite=True))
    if args.png:
        summary["png"] = str(write_preview(track, args.png, overwrite=True))
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


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"seed must be a non-negative integer, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"seed must be a non-negative integer, got {text!r}")
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="tfalda-sim", description="Carolo-Cup lane-keeping simulator (tfalda-sim).")
    sub = parser.add_subparsers(dest="command", required=True)

    track = sub.add_parser("track", help="generate, validate and list tracks")
    track_sub = track.add_subparsers(dest="track_command", required=True)

    gen = track_sub.add_parser("generate", help="generate a track for a seed (scenario id)")
    gen.add_argument("--seed", type=_seed, required=True, help="scenario id (≥ 0)")
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
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except CliError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
