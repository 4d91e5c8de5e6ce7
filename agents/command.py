"""``tfalda-sim drive``: an agent drives laps of a track closed-loop."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from tfalda_sim.cli_common import CliError, check_outputs, positive_float_arg, positive_int_arg
from tracks import NAMED_TRACKS, generate, load_named


def add_drive_parser(sub: Any) -> None:
    dr = sub.add_parser(
        "drive", help="drive laps with the PID or a PPO policy (closed loop)",
        description="An agent steers the car from the TFALDA + LIS lanes; prints lap times, "
                    "the mean |cross-track error|, departures and LIS resets.")
    dr.add_argument("--agent", choices=["pid", "ppo"], default="pid")
    dr.add_argument("--policy", type=Path, help="PPO policy .zip (default: the committed one)")
    dr.add_argument("--track", default="7",
                    help=f"a named track ({', '.join(NAMED_TRACKS)}) or a generator seed")
    dr.add_argument("--laps", type=positive_int_arg, default=2)
    dr.add_argument("--speed", type=positive_float_arg, default=1.5, help="[m/s]")
    dr.add_argument("--no-recover", action="store_true",
                    help="end the drive at the first departure (default: put the car back)")
    dr.add_argument("--video", type=Path, help="MP4 of the drive with ROIs, lanes and a map")
    dr.add_argument("--force", action="store_true", help="overwrite an existing video")
    dr.add_argument("--json", action="store_true", help="print one JSON object")
    dr.set_defaults(func=_cmd_drive)


def _cmd_drive(args: argparse.Namespace) -> int:
    from .drive import drive, make_agent

    check_outputs({"video": args.video}, {"video": ".mp4"}, args.force)
    if args.track in NAMED_TRACKS:
        track, label = load_named(args.track), args.track
    elif args.track.isdigit():
        track, label = generate(int(args.track)), f"seed {args.track}"
    else:
        raise CliError(f"--track {args.track!r} is neither a named track "
                       f"({', '.join(NAMED_TRACKS)}) nor a seed (a non-negative integer)")
    if not track.closed:
        raise CliError(f"--track {args.track} is not a loop; laps need a closed track")
    if args.speed > 8.3:
        raise CliError(f"--speed {args.speed} m/s is above the car's top speed 8.3 m/s")
    try:
        agent = make_agent(args.agent, args.policy)
    except (ValueError, FileNotFoundError, ImportError) as exc:
        raise CliError(str(exc)) from None
    result = drive(agent, track, laps=args.laps, speed_m_s=args.speed,
                   recover=not args.no_recover, video=args.video, label=label,
                   progress=not args.json)
    summary = result.summary() | {"agent": args.agent, "speed_m_s": args.speed}
    if args.video:
        summary["video"] = str(args.video)
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"{args.agent} on {label} at {args.speed:g} m/s: {result.laps_completed}/"
              f"{args.laps} laps ({result.ended})")
        for k, t in enumerate(result.lap_times_s, start=1):
            print(f"  lap {k}: {t:.2f} s")
        print(f"  mean |cross-track error| {result.mean_abs_cross_track_m * 100:.1f} cm, "
              f"max {result.max_abs_cross_track_m * 100:.1f} cm")
        print(f"  departures {result.departures}, LIS resets {result.lis_resets}, mean hit "
              f"rate {result.mean_hit_rate:.3f}")
        if args.video:
            print(f"  wrote {args.video}")
    return 0 if result.laps_completed == args.laps else 1
