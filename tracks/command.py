"""The tracks' commands: ``track generate``, ``track validate`` and ``track list``."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

from ..cli_common import (
    CliError,
    add_force_option,
    add_json_option,
    bounded_float_arg,
    check_outputs,
    json_text,
    seed_arg,
)
from ..outputs import Outputs
from .dimensions import MAT_EDGE_MARGIN_M
from .fileformat import TrackFileError, load_track, save_track
from .generator import GeneratorParams, generate, seed_name
from .model import Track, printable
from .named import NAMED_TRACKS, named_path
from .preview import write_preview
from .rules import Violation, validate

TRACK_ARG_HELP = ("named track (" + ", ".join(NAMED_TRACKS) + "), seed (generated track) or "
                  "track file (.json)")
"""The help of every track argument (``--track``, ``track validate``'s): one meaning."""


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

    val = track_sub.add_parser("validate", help="check a track against the rules")
    val.add_argument("track", help=TRACK_ARG_HELP)
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


def cmd_track_validate(args: argparse.Namespace) -> int:
    track = resolve_track_arg(args.track, check_rules=False, option="track")
    summary = track_summary(track, validate(track))
    path = (named_path(args.track) if args.track in NAMED_TRACKS
            else track_file_arg(args.track))
    summary["file"] = None if path is None else str(path)
    _emit(summary, args.json)
    return 0 if summary["valid"] else 1


def cmd_track_list(args: argparse.Namespace) -> int:
    rows = []
    for name in NAMED_TRACKS:
        track = load_track(named_path(name))
        rows.append({"name": name, "length_m": track.length_m, "closed": track.closed,
                     "description": track.description})
    if args.json:
        print(json_text({"tracks": rows}))
    else:
        for row in rows:
            print(f"{printable(row['name']):14} {row['length_m']:7.2f} m  "
                  f"{'closed' if row['closed'] else 'open  '}  {printable(row['description'])}")
    return 0


def _emit(summary: dict[str, Any], as_json: bool) -> None:
    if as_json:
        print(json_text(summary))
    else:
        _print_summary(summary)


def _is_seed(text: str) -> bool:
    return text.isascii() and text.isdigit()  # "²".isdigit() is True, int("²") fails


def track_file_arg(text: str) -> Path | None:
    """The track file a track argument names (``resolve_track_arg`` reads it), else None
    (a name or a seed): an input that no output may overwrite."""
    if text in NAMED_TRACKS or _is_seed(text):
        return None
    return Path(text)


def track_arg_label(text: str) -> str:
    """How every output names the track of a track argument: a named track's name, a
    seed's ``seed-N`` (its generated track's name) or the file's name — escaped, as any
    name printed (``printable``)."""
    if text in NAMED_TRACKS:
        return text
    if _is_seed(text):
        return seed_name(int(text))
    return printable(Path(text).name)


def resolve_track_arg(text: str, *, check_rules: bool = True, option: str = "--track") -> Track:
    """The track of a track argument (``option``, for the error): a named track, a seed (its
    generated track) or a track file; a file is one if it exists or ends in ``.json``
    (a name mistyped is then not reported as a missing file). ``check_rules`` False: a
    file breaking a rule is read as it is (``track validate`` lists the violations)."""
    if text in NAMED_TRACKS:
        return load_track(named_path(text))
    if _is_seed(text):
        return generate(int(text))
    path = Path(text)
    if path.suffix.lower() == ".json" or path.exists():
        try:
            return load_track(path, check_rules=check_rules)
        except TrackFileError as exc:
            raise CliError(str(exc)) from None
    raise CliError(f"{option} {printable(text)[:80]!r} is neither a named track "
                   f"({', '.join(NAMED_TRACKS)}), a seed (a non-negative integer) nor a track "
                   "file (.json)")
