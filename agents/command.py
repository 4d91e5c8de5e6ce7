"""``tfalda-sim drive``: an agent drives laps of a track closed-loop."""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path
from typing import Any

from tfalda_sim.cli_common import (
    CliError,
    check_outputs,
    positive_float_arg,
    positive_int_arg,
    seed_range_arg,
)
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
    dr.add_argument("--obstacles", action="store_true",
                    help="keep a generated track's cartons (the agents do not avoid them)")
    dr.add_argument("--no-recover", action="store_true",
                    help="end the drive at the first departure (default: put the car back)")
    dr.add_argument("--video", type=Path, help="MP4 of the drive with ROIs, lanes and a map")
    dr.add_argument("--camera-video", type=Path,
                    help="MP4 of the bare grey camera frames (for tfalda-sim replay)")
    dr.add_argument("--force", action="store_true", help="overwrite existing videos")
    dr.add_argument("--json", action="store_true", help="print one JSON object")
    dr.set_defaults(func=_cmd_drive)


def _cmd_drive(args: argparse.Namespace) -> int:
    from .drive import drive, make_agent

    check_outputs({"video": args.video, "camera-video": args.camera_video},
                  {"video": ".mp4", "camera-video": ".mp4"}, args.force)
    if args.track in NAMED_TRACKS:
        track, label = load_named(args.track), args.track
    elif args.track.isdigit():
        track, label = generate(int(args.track)), f"seed {args.track}"
        if not args.obstacles:
            track = replace(track, obstacles=())
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
                   recover=not args.no_recover, video=args.video,
                   camera_video=args.camera_video, label=label,
                   progress=not args.json)
    summary = result.summary() | {"agent": args.agent, "speed_m_s": args.speed}
    if args.video:
        summary["video"] = str(args.video)
    if args.camera_video:
        summary["camera_video"] = str(args.camera_video)
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
        for path in (args.video, args.camera_video):
            if path:
                print(f"  wrote {path}")
    return 0 if result.laps_completed == args.laps else 1


def add_train_parser(sub: Any) -> None:
    tr = sub.add_parser("train", help="train a PPO steering policy (needs the rl extra)",
                        description="PPO (stable-baselines3) on vectorised TfaldaTrack-v0 envs "
                                    "over the training track seeds; TensorBoard logs, "
                                    "checkpoints, the policy and train.json in --out.")
    tr.add_argument("--timesteps", type=positive_int_arg, default=1_000_000)
    tr.add_argument("--n-envs", type=positive_int_arg, default=2)
    tr.add_argument("--seed", type=int, default=0)
    tr.add_argument("--speed", type=positive_float_arg, default=1.5, help="[m/s]")
    tr.add_argument("--out", type=Path, default=Path("runs/ppo"))
    tr.add_argument("--json", action="store_true", help="print one JSON object")
    tr.set_defaults(func=_cmd_train)


def _cmd_train(args: argparse.Namespace) -> int:
    try:
        import stable_baselines3  # noqa: F401
    except ImportError:
        raise CliError("training needs the rl extra: pip install torch==2.13.0 && "
                       "pip install -e '.[rl]'") from None
    from .train import train

    if (args.out / "policy.zip").exists():
        raise CliError(f"{args.out / 'policy.zip'} exists; choose another --out")
    summary = train(args.timesteps, args.n_envs, args.seed, args.out, speed_m_s=args.speed,
                    progress=not args.json)
    print(json.dumps(summary) if args.json else
          f"trained {args.timesteps} steps in {summary['train_time_s']:.0f} s → "
          f"{args.out / 'policy.zip'}")
    return 0


def add_stress_parser(sub: Any) -> None:
    from .stress import FAULTS

    st = sub.add_parser("stress", help="stress-test the LIS reset logic with injected faults",
                        description="Closed-loop PID drives with a battery of faults, each with "
                                    "and without the LIS reset stage: resets, frames until the "
                                    "lanes are valid again, false resets, departures.")
    st.add_argument("--seeds", type=seed_range_arg, default=range(10_000, 10_010),
                    help="generated tracks A:B")
    st.add_argument("--faults", default=",".join(FAULTS),
                    help=f"comma-separated subset of: {', '.join(FAULTS)}")
    st.add_argument("--workers", type=positive_int_arg, help="processes (default: all CPUs)")
    st.add_argument("--out", type=Path, default=Path("out/stress"),
                    help="directory for stress.json, stress.md and stress.png")
    st.add_argument("--json", action="store_true", help="print the summary as JSON")
    st.set_defaults(func=_cmd_stress)


def _cmd_stress(args: argparse.Namespace) -> int:
    from .stress import FAULTS, markdown_table, report, run_battery

    faults = [f.strip() for f in args.faults.split(",") if f.strip()]
    unknown = [f for f in faults if f not in FAULTS]
    if unknown or not faults:
        raise CliError(f"unknown fault(s) {', '.join(unknown) or '(none given)'}; "
                       f"known: {', '.join(FAULTS)}")
    runs = run_battery(args.seeds, faults, workers=args.workers, progress=not args.json)
    result = report(runs, args.out)
    if args.json:
        print(json.dumps({"summary": result["summary"], "out": str(args.out)}))
    else:
        print(markdown_table(result["summary"]))
        print(f"wrote {args.out}/stress.json, stress.md, stress.png")
    return 0
