"""The tracks' commands: ``track generate``, ``track validate`` and ``track list``."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

from ..cli_common import (
    CliError,
    add_force_option,
    add_json_option,
    bounded_float_arg,
    check_outputs,
    seed_arg,
)
from ..outputs import Outputs
from .dimensions import MAT_EDGE_MARGIN_M
from .fileformat import TrackFileError, load_track, save_track
from .generator import GeneratorParams, generate
from .model import Track, printable
from .named import NAMED_TRACKS, named_path
from .preview import write_preview
from .rules import Violation, validate


def register(sub: Any) -> None:
    """Add ``track generate|validate|list`` to the ``tfalda-sim`` subparsers."""
    track = sub.add_parser("track", help="generate, validate and list tracks")
    track_sub = track.add_subparsers(dest="track_command", required=True)

    gen = track_sub.add_parser("generate", help="generate a track for a seed (scenario id)")
    gen.add_argument("--seed", type=seed_arg, required=True, help="scenario id (≥ 0)")
    gen.add_argument("--difficulty", type=bounded_float_arg(0.0, 1.0),
                     default=GeneratorParams().difficulty,
                     help="0 (wide curves, clean markings) … 1 (tight curves, gaps, obstacles)")
    gen.add_argument("--out", type=Path, help="write the track file (JSON) here")
    gen.add_argument("--png", type=Path, help="write a preview PNG here")
    add_force_option(gen)
    add_json_option(gen)
    gen.set_defaults(func=cmd_track_generate)

    val = track_sub.add_parser("validate", help="check a track file against the rules")
    val.add_argument("file", help="track file (JSON) or a named track: " + ", ".join(NAMED_TRACKS))
    add_json_option(val)
    val.set_defaults(func=cmd_track_validate)

    lst = track_sub.add_parser("list", help="list the named tracks")
    add_json_option(lst)
    lst.set_defaults(func=cmd_track_list)



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
    print(f"track        {printable(summary['name']) or '-'}"
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


def cmd_track_generate(args: argparse.Namespace) -> int:
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


def cmd_track_validate(args: argparse.Namespace) -> int:
    path = _resolve_track_file(args.file)
    try:
        track = load_track(path, check_rules=False)
    except TrackFileError as exc:
        raise CliError(str(exc)) from None
    summary = track_summary(track, validate(track))
    summary["file"] = str(path)
    _emit(summary, args.json)
    return 0 if summary["valid"] else 1


def cmd_track_list(args: argparse.Namespace) -> int:
    rows = []
    for name in NAMED_TRACKS:
        track = load_track(named_path(name))
        rows.append({"name": name, "length_m": track.length_m, "closed": track.closed,
                     "description": track.description})
    if args.json:
        print(json.dumps({"tracks": rows}))
    else:
        for row in rows:
            print(f"{printable(row['name']):14} {row['length_m']:7.2f} m  "
                  f"{'closed' if row['closed'] else 'open  '}  {printable(row['description'])}")
    return 0


def _emit(summary: dict[str, Any], as_json: bool) -> None:
    if as_json:
        print(json.dumps(summary))
    else:
        _print_summary(summary)


def _is_seed(text: str) -> bool:
    return text.isascii() and text.isdigit()  # "²".isdigit() is True, int("²") fails


def track_file_arg(text: str) -> Path | None:
    """The track file a ``--track`` names (``resolve_track_arg`` reads it), else None (a
    name, a seed or no track): an input that no output may overwrite."""
    if text in NAMED_TRACKS or _is_seed(text):
        return None
    path = Path(text)
    return path if path.suffix.lower() == ".json" else None


def track_arg_label(text: str) -> str:
    """How reports name the track of a ``--track``: its name, "seed N" or the file's name."""
    path = track_file_arg(text)
    return f"seed {text}" if _is_seed(text) else path.name if path is not None else text


def resolve_track_arg(text: str) -> Track:
    """A named track, a seed (generated track) or a track file."""
    if text in NAMED_TRACKS:
        return load_track(named_path(text))
    if _is_seed(text):
        return generate(int(text))
    path = track_file_arg(text)
    if path is not None:
        try:
            return load_track(path)
        except TrackFileError as exc:
            raise CliError(str(exc)) from None
    raise CliError(f"--track {text!r} is neither a named track ({', '.join(NAMED_TRACKS)}), "
                   "a seed (a non-negative integer) nor a .json track file")
