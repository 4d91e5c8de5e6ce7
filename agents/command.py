"""The agents' commands: ``drive`` (laps closed-loop), ``train`` (PPO), ``stress`` (the
ROI reset logic under faults), ``evaluate-agent`` (held-out tracks, speed sweep) and
``limits`` (per track the highest speed the agent keeps its lane at)."""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import replace
from pathlib import Path
from typing import Any

from tfalda_sim.camera.command import add_camera_option, camera_input
from tfalda_sim.cli_common import (
    DIRECTORY,
    RECORDING_SUFFIXES,
    CliError,
    add_force_option,
    add_json_option,
    add_recording_options,
    bounded_float_arg,
    bounded_int_arg,
    check_outputs,
    interrupted,
    json_text,
    positive_int_arg,
    recording_outputs,
    seed_arg,
    seed_range_arg,
    speed_arg_for,
)
from tfalda_sim.interrupts import holding_stops
from tfalda_sim.perception.command import check_camera_geometry
from tfalda_sim.perception.geometry import CameraGeometryError
from tfalda_sim.sweep_runner import (
    add_sweep_options,
    check_sweep_options,
    sweep_backend,
    sweep_exit,
)
from tfalda_sim.timing import TIMINGS, Timing, load_timing, resolve_timing
from tfalda_sim.tracks import NAMED_TRACKS
from tfalda_sim.tracks.command import resolve_track_arg, track_arg_label, track_file_arg
from tfalda_sim.vehicle import MIN_CRUISE_SPEED_M_S, CarParams

TOP_SPEED_M_S: float = CarParams().max_speed_m_s
"""The car's top speed: every ``--speed`` of these commands lies below it [m/s]."""

speed_arg = speed_arg_for(MIN_CRUISE_SPEED_M_S, TOP_SPEED_M_S)
SPEED_HELP = (f"cruise speed [m/s], in [{MIN_CRUISE_SPEED_M_S:g}, {TOP_SPEED_M_S:g}] "
              "(default: %(default)s)")
AGENT_HELP = "the PID lane keeper or a PPO policy (--policy) (default: %(default)s)"


def add_trust_policy_option(parser: argparse.ArgumentParser) -> None:
    """``--trust-policy``: load a --policy file that holds pickled objects."""
    parser.add_argument("--trust-policy", action="store_true",
                        help="load a --policy file that holds pickled Python objects (a "
                             "stable-baselines3 save): unpickling runs code the file's author "
                             "chose, so only for a file from a source you trust (default: "
                             "refused; files `tfalda-sim train` writes need no trust)")


VEHICLE_CHOICES: tuple[str, ...] = ("kinematic", "dynamic")
"""``--vehicle``: the env's ``VEHICLES`` (spelt here: importing the env would load the
renderer and numba for every command's parser, ``--help`` included)."""


def timing_arg(text: str) -> str:
    """argparse type of ``--timing``: a name of ``TIMINGS`` or a .json timing file, read
    and checked now (``load_timing``), so a bad file is refused before any work."""
    if text in TIMINGS:
        return text
    if not text.endswith(".json"):
        shown = repr(text if len(text) <= 40 else text[:37] + "...")
        raise argparse.ArgumentTypeError(f"unknown timing {shown}; use {', '.join(TIMINGS)} "
                                         "or a .json timing file")
    try:
        load_timing(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def add_vehicle_options(parser: argparse.ArgumentParser) -> None:
    """``--vehicle kinematic|dynamic`` and ``--timing NAME|FILE``: the car model and the
    pipeline's timing of every env the command makes (docs/dynamics.md)."""
    parser.add_argument("--vehicle", choices=VEHICLE_CHOICES, default="kinematic",
                        help="car model: the kinematic bicycle or the dynamic single-track "
                             "car that slides beyond its tyres' grip (default: %(default)s)")
    parser.add_argument("--timing", type=timing_arg, default="ideal", metavar="NAME|FILE",
                        help=f"the pipeline's timing: {', '.join(TIMINGS)} (the thesis' "
                             "car: frames two periods old, a hobby servo) or a .json timing "
                             "file (docs/dynamics.md) (default: %(default)s)")


def timing_input(text: str) -> Path | None:
    """The file ``--timing`` reads (for the output check: never overwritten), or None for
    a named timing."""
    return None if text in TIMINGS else Path(text)


def vehicle_config(args: argparse.Namespace) -> dict[str, str]:
    """``--vehicle`` and ``--timing`` in a sweep's configuration (its results file's header,
    which ``--resume`` compares): only when not the defaults, so a results file written
    before these options existed still resumes."""
    return ({} if args.vehicle == "kinematic" else {"vehicle": args.vehicle}) | (
        {} if args.timing == "ideal" else {"timing": args.timing})


def resolve_timing_arg(text: str) -> Timing:
    """The timing of ``--timing`` (checked at the parser; read again here, so a file
    changed since is still refused in one line)."""
    try:
        return resolve_timing(text)
    except ValueError as exc:
        raise CliError(f"--timing: {exc}") from None


def register(sub: Any) -> None:
    """Add the agents' commands to the ``tfalda-sim`` subparsers."""
    _drive_parser(sub)
    _train_parser(sub)
    _stress_parser(sub)
    _evaluate_agent_parser(sub)
    _limits_parser(sub)


def _drive_parser(sub: Any) -> None:
    dr = sub.add_parser(
        "drive", help="drive laps with the PID or a PPO policy (closed loop)",
        description="An agent steers the car from the TFALDA + LIS lanes; prints lap times, "
                    "the mean |cross-track error|, departures and LIS resets.")
    dr.add_argument("--agent", choices=["pid", "ppo"], default="pid", help=AGENT_HELP)
    dr.add_argument("--policy", type=Path, help="PPO policy .zip (default: the committed one)")
    add_trust_policy_option(dr)
    dr.add_argument("--track", default="7",
                    help=f"a named track ({', '.join(NAMED_TRACKS)}), a generator seed or a "
                         "track file (.json, as `tfalda-sim track generate --out` writes) "
                         "(default: %(default)s, a generated track)")
    dr.add_argument("--laps", type=positive_int_arg, default=2,
                    help="laps to drive from the start line (default: %(default)s)")
    dr.add_argument("--speed", type=speed_arg, default=1.5, help=SPEED_HELP)
    dr.add_argument("--obstacles", action="store_true",
                    help="keep the track's cartons, a generated track's or a track file's "
                         "(the agents do not avoid them)")
    dr.add_argument("--no-recover", action="store_true",
                    help="end the drive at the first departure (default: put the car back)")
    dr.add_argument("--video", type=Path,
                    help="MP4 of the drive with ROIs, lanes and a map (default: none)")
    dr.add_argument("--camera-video", type=Path,
                    help="MP4 of the bare grey camera frames, for tfalda-sim replay "
                         "(default: none)")
    add_recording_options(dr, "the drive")
    add_camera_option(dr)
    add_vehicle_options(dr)
    add_force_option(dr, "existing videos")
    add_json_option(dr)
    dr.set_defaults(func=cmd_drive)


def _figure(value: float, spec: str, unit: str = "") -> str:
    """A figure of the table, or "n/a" where there is none (NaN: no step was driven)."""
    return f"{value:{spec}}{unit}" if math.isfinite(value) else "n/a"


def cmd_drive(args: argparse.Namespace) -> int:
    from tfalda_sim.envs import StartInCarton

    from .drive import PolicyFileError, drive, make_agent

    check_outputs({"video": args.video, "camera-video": args.camera_video,
                   **recording_outputs(args)},
                  {"video": ".mp4", "camera-video": ".mp4", **RECORDING_SUFFIXES}, args.force,
                  inputs={"policy": args.policy, "camera": camera_input(args.camera),
                          "track": track_file_arg(args.track),
                          "timing": timing_input(args.timing)})
    camera = check_camera_geometry(args.camera)
    timing = resolve_timing_arg(args.timing)
    track, label = resolve_track_arg(args.track), track_arg_label(args.track)
    if track.obstacles and not args.obstacles:
        track = replace(track, obstacles=())
    if not track.closed:
        raise CliError(f"--track {args.track} is not a loop; laps need a closed track")
    try:
        agent = make_agent(args.agent, args.policy, camera, trust_policy=args.trust_policy)
    except (ValueError, FileNotFoundError, ImportError) as exc:
        raise CliError(str(exc)) from None
    try:
        result = drive(agent, track, laps=args.laps, speed_m_s=args.speed,
                       recover=not args.no_recover, video=args.video,
                       camera_video=args.camera_video, label=label,
                       progress=not args.json, camera=camera, vehicle=args.vehicle,
                       timing=timing, mcap=args.mcap, rosbag=args.rosbag)
    except CameraGeometryError as exc:
        raise CliError(f"--camera {args.camera}: {exc}") from None
    except PolicyFileError as exc:
        raise CliError(str(exc)) from None
    except StartInCarton as exc:  # a track file may put one on the start line
        raise CliError(f"--track {args.track}: {exc}; leave out --obstacles or move the "
                       "carton") from None
    summary = result.summary() | {"agent": args.agent, "speed_m_s": args.speed,
                                  "camera": args.camera, "vehicle": args.vehicle,
                                  "timing": args.timing}
    if args.video:
        summary["video"] = str(args.video)
    if args.camera_video:
        summary["camera_video"] = str(args.camera_video)
    recording = args.mcap or args.rosbag
    if recording and result.steps:
        summary["recording"] = str(recording)
    if args.json:
        print(json_text(summary))
    else:
        print(f"{args.agent} on {label} at {args.speed:g} m/s: {result.laps_completed}/"
              f"{args.laps} laps ({result.ended})")
        print(f"  {args.vehicle} car, {args.timing} timing")
        for k, t in enumerate(result.lap_times_s, start=1):
            print(f"  lap {k}: {t:.2f} s")
        mean_cm = _figure(result.mean_abs_cross_track_m * 100, ".1f", " cm")
        max_cm = _figure(result.max_abs_cross_track_m * 100, ".1f", " cm")
        print(f"  mean |cross-track error| {mean_cm}, max {max_cm}")
        print(f"  departures {result.departures}, LIS resets {result.roi_resets}, mean hit "
              f"rate {_figure(result.mean_hit_rate, '.3f')}")
        for path in (args.video, args.camera_video, recording):
            if path:
                print(f"  wrote {path}")
    if result.ended == "interrupted":
        kept = " and ".join(str(p) for p in (args.video, args.camera_video, recording) if p)
        return interrupted(f"drove {result.laps_completed} of {args.laps} laps "
                           f"({result.steps} frames)"
                           + (f"; kept {kept} up to that frame" if kept else ""))
    return 0 if result.laps_completed == args.laps else 1


MAX_N_ENVS: int = 64
"""Most training envs: each env holds a renderer and a scene (hundreds of MB); more than
this is a typo, not a training set-up."""

MAX_ENV_RUNNERS: int = 4096
"""Most RLlib env runners (a cluster's CPUs): more is a typo."""

MAX_TRAIN_BATCH: int = 1_000_000
"""Largest ``--train-batch`` [env steps]: one iteration's batch lives in the driver's memory
(observations, actions, values, advantages: ≈ 0.3 kB a step, ≈ 0.3 GB at this bound), far
beyond any useful PPO batch."""

TRAIN_BACKENDS: tuple[str, ...] = ("sb3", "rllib")
"""What ``train`` trains with: stable-baselines3 (local) or RLlib (Ray, local or cluster)."""

BACKEND_OPTIONS: dict[str, tuple[str, ...]] = {"sb3": ("n_envs",),
                                               "rllib": ("env_runners", "train_batch",
                                                         "ray_address")}
"""The ``train`` options only one backend understands (refused with the other)."""


def _train_parser(sub: Any) -> None:
    tr = sub.add_parser("train", help="train a PPO steering policy (stable-baselines3 or RLlib)",
                        description="PPO on TfaldaTrack-v0's lane observations over the training "
                                    "track seeds. --backend sb3 (default, the rl extra): "
                                    "stable-baselines3 on --n-envs local processes; TensorBoard "
                                    "logs, checkpoints, policy.zip and train.json in --out. "
                                    "--backend rllib (the rllib extra): RLlib on a local Ray or "
                                    "the Ray cluster at --ray-address, --env-runners sampling "
                                    "actors; the RLlib checkpoint/ and train.json (every "
                                    "iteration's steps/s and mean return) in --out. Ctrl-C "
                                    "stops the training and keeps the policy so far.")
    tr.add_argument("--backend", choices=TRAIN_BACKENDS, default="sb3",
                    help="stable-baselines3 on this machine (default) or RLlib on Ray")
    tr.add_argument("--timesteps", type=bounded_int_arg(1, 10**12), default=1_000_000,
                    help="env steps to train for (rllib: whole iterations of --train-batch) "
                         "(default: %(default)s)")
    tr.add_argument("--n-envs", type=bounded_int_arg(1, MAX_N_ENVS),
                    help=f"sb3: envs stepped in parallel, one process each (1–{MAX_N_ENVS}) "
                         "(default: 2)")
    tr.add_argument("--env-runners", type=bounded_int_arg(0, MAX_ENV_RUNNERS),
                    help=f"rllib: Ray actors sampling the env, one CPU each (0–"
                         f"{MAX_ENV_RUNNERS}; 0: sample in this process) (default: 2)")
    tr.add_argument("--train-batch", type=bounded_int_arg(1, MAX_TRAIN_BATCH),
                    help=f"rllib: env steps collected per training iteration (1–"
                         f"{MAX_TRAIN_BATCH}) (default: 2048)")
    tr.add_argument("--ray-address", metavar="ADDR",
                    help="rllib: a running Ray cluster, 'auto' or HOST:PORT (default: start a "
                         "local Ray with --env-runners CPUs for this run)")
    tr.add_argument("--seed", type=seed_arg, default=0,
                    help="seed of the network's initialisation, the exploration and the "
                         "training tracks' order (default: %(default)s)")
    tr.add_argument("--speed", type=speed_arg, default=1.5, help=SPEED_HELP)
    tr.add_argument("--out", type=Path, metavar="DIR",
                    help="folder for the run (default: runs/ppo with sb3, runs/rllib with "
                         "rllib)")
    tr.add_argument("--force", action="store_true",
                    help="write into a folder that holds an earlier run: its policy.zip or "
                         "checkpoint/, train.json and same-named checkpoints are replaced, its "
                         "TensorBoard runs kept beside the new one")
    add_camera_option(tr)
    add_vehicle_options(tr)
    add_json_option(tr)
    tr.set_defaults(func=cmd_train, train_parser=tr)


def _check_backend_options(args: argparse.Namespace) -> None:
    """An option of the other backend is refused (usage and exit 2), never ignored."""
    for backend, dests in BACKEND_OPTIONS.items():
        given = [f"--{d.replace('_', '-')}" for d in dests if getattr(args, d) is not None]
        if backend != args.backend and given:
            args.train_parser.error(f"{' and '.join(given)} {'is' if len(given) == 1 else 'are'}"
                                    f" for --backend {backend}, not {args.backend}")


def cmd_train(args: argparse.Namespace) -> int:
    _check_backend_options(args)
    if args.backend == "rllib":
        return _cmd_train_rllib(args)
    try:
        import stable_baselines3  # noqa: F401
    except ImportError:
        raise CliError("training needs the rl extra: pip install torch==2.13.0 && "
                       "pip install -e '.[rl]'") from None
    from tfalda_sim.parallel import WORKER_MEMORY_BYTES, available_memory_bytes

    from .train import OUT_FILES, train

    args.out = Path("runs/ppo") if args.out is None else args.out
    args.n_envs = 2 if args.n_envs is None else args.n_envs
    check_outputs({"out": args.out}, {"out": DIRECTORY}, args.force,
                  files_in={"out": OUT_FILES}, inputs={"camera": camera_input(args.camera),
                                                       "timing": timing_input(args.timing)})
    check_camera_geometry(args.camera)
    resolve_timing_arg(args.timing)
    mem = available_memory_bytes()
    if args.n_envs > 1 and mem is not None and args.n_envs * WORKER_MEMORY_BYTES > mem:
        raise CliError(f"--n-envs {args.n_envs} needs about "
                       f"{args.n_envs * WORKER_MEMORY_BYTES / 2**30:.1f} GiB, "
                       f"{mem / 2**30:.1f} GiB is available; use at most "
                       f"{max(1, mem // WORKER_MEMORY_BYTES)}")
    summary = train(args.timesteps, args.n_envs, args.seed, args.out, speed_m_s=args.speed,
                    progress=not args.json, camera=args.camera, vehicle=args.vehicle,
                    timing=args.timing)
    print(json_text(summary) if args.json else
          f"trained {summary['timesteps_done']} steps in {summary['train_time_s']:.0f} s "
          f"({summary['steps_per_s'] or 0:.0f} steps/s) → {args.out / 'policy.zip'}")
    if summary["interrupted"]:
        return interrupted(f"stopped after {summary['timesteps_done']} of {args.timesteps} "
                           f"steps; kept the policy so far ({args.out / 'policy.zip'}), "
                           f"train.json, the checkpoints and the TensorBoard logs")
    return 0


def _cmd_train_rllib(args: argparse.Namespace) -> int:
    import sys

    from tfalda_sim.parallel import WORKER_MEMORY_BYTES, available_memory_bytes

    from . import rllib
    from . import train as sb3

    try:
        rllib.import_rllib()
    except rllib.RllibUnavailable as exc:
        raise CliError(str(exc)) from None
    out = Path("runs/rllib") if args.out is None else args.out
    runners = 2 if args.env_runners is None else args.env_runners
    # Both backends' files: an earlier run of either is not mixed into without --force.
    check_outputs({"out": out}, {"out": DIRECTORY}, args.force,
                  files_in={"out": tuple(dict.fromkeys((*rllib.OUT_FILES, *sb3.OUT_FILES)))},
                  inputs={"camera": camera_input(args.camera),
                          "timing": timing_input(args.timing)})
    check_camera_geometry(args.camera)
    resolve_timing_arg(args.timing)
    mem = available_memory_bytes()
    if args.ray_address is None and mem is not None and runners * WORKER_MEMORY_BYTES > mem:
        raise CliError(f"--env-runners {runners} needs about "
                       f"{runners * WORKER_MEMORY_BYTES / 2**30:.1f} GiB, "
                       f"{mem / 2**30:.1f} GiB is available; use at most "
                       f"{max(1, mem // WORKER_MEMORY_BYTES)}")
    config = rllib.RllibConfig(env_runners=runners, **(
        {} if args.train_batch is None else {"train_batch": args.train_batch}))
    try:
        summary = rllib.train_rllib(args.timesteps, args.seed, out, config=config,
                                    speed_m_s=args.speed, camera=args.camera,
                                    address=args.ray_address, progress=not args.json,
                                    vehicle=args.vehicle, timing=args.timing)
    except rllib.RllibUnavailable as exc:
        raise CliError(str(exc)) from None
    checkpoint = out / "checkpoint"
    print(json_text(summary) if args.json else
          f"trained {summary['timesteps_done']} steps in {summary['iterations_done']} "
          f"iterations, {summary['train_time_s']:.0f} s → {checkpoint}")
    kept = (f"kept the checkpoint of iteration {summary['iterations_done']} of "
            f"{summary['iterations']} ({checkpoint}) and train.json")
    if summary["failed"]:
        print(f"error: the training failed: {summary['failed']}; {kept}", file=sys.stderr)
        return 1
    if summary["interrupted"]:
        return interrupted(f"stopped after {summary['timesteps_done']} of {args.timesteps} "
                           f"steps; {kept}")
    return 0


def _faults_arg(text: str) -> list[str]:
    from .stress import check_fault_names

    names = [f.strip() for f in text.split(",") if f.strip()]
    repeated = [f for k, f in enumerate(names) if f in names[:k]]
    if repeated:  # its runs would be made twice and pooled with themselves
        raise argparse.ArgumentTypeError(f"{repeated[0]} is named twice: {text[:60]!r}")
    try:
        return check_fault_names(names)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _stress_parser(sub: Any) -> None:
    from .stress import FAULTS

    st = sub.add_parser("stress", help="stress-test the LIS reset logic with injected faults",
                        description="Closed-loop PID drives with a battery of faults, each with "
                                    "and without the LIS reset stage: resets, frames until the "
                                    "lanes are valid again, false resets, departures. Runs "
                                    "stream to OUT/stress.jsonl as they finish; Ctrl-C keeps "
                                    "the finished runs and their summary.")
    st.add_argument("--seeds", type=seed_range_arg, default=range(10_000, 10_010),
                    help="generated tracks A:B (default: 10000:10010)")
    st.add_argument("--faults", type=_faults_arg, default=",".join(FAULTS),
                    help=f"comma-separated subset of: {', '.join(FAULTS)} (default: all)")
    add_sweep_options(st, "runs")
    st.add_argument("--out", type=Path, default=Path("out/stress"), metavar="DIR",
                    help="folder for stress.jsonl, stress.json, stress.md and stress.png "
                         "(default: %(default)s)")
    add_recording_options(st, "the drive with the LIS reset stage (one seed, one fault)")
    add_camera_option(st)
    add_vehicle_options(st)
    add_force_option(st, "an earlier report in --out")
    add_json_option(st)
    st.set_defaults(func=cmd_stress)


def cmd_stress(args: argparse.Namespace) -> int:
    from tfalda_sim.outputs import Outputs
    from tfalda_sim.sweep_runner import SweepSpec, read_results, resume_hint, run_sweep

    from .stress import (
        REPORT_FILES,
        StressRun,
        StressTally,
        battery_jobs,
        check_run_record,
        markdown_table,
        plot,
        report_document,
        run_job,
        run_record,
    )

    check_sweep_options(args)
    faults = args.faults
    recording = args.mcap or args.rosbag
    if recording is not None and (len(args.seeds) != 1 or len(faults) != 1):
        raise CliError(f"--{'mcap' if args.mcap else 'rosbag'} records one drive: give one "
                       f"seed (--seeds N:N+1) and one fault (--faults NAME); asked for "
                       f"{len(args.seeds)} seeds and {len(faults)} faults")
    # --resume replaces the report of the run it continues (and its --results file).
    check_outputs({"out": args.out, "results": args.results, **recording_outputs(args)},
                  {"out": DIRECTORY, "results": ".jsonl", **RECORDING_SUFFIXES},
                  args.force or args.resume,
                  files_in={"out": REPORT_FILES.values()},
                  inputs={"camera": camera_input(args.camera),
                          "timing": timing_input(args.timing)})
    check_camera_geometry(args.camera)
    timing = resolve_timing_arg(args.timing)
    jobs = len(args.seeds) * len(faults) * 2
    spec = SweepSpec(command="stress",
                     config={"seeds": f"{args.seeds.start}:{args.seeds.stop}",
                             "faults": faults, "camera": args.camera,
                             **vehicle_config(args)},
                     jobs=battery_jobs(args.seeds, faults, args.camera, args.vehicle, timing),
                     total=jobs,
                     fn=run_job, record=run_record, check=check_run_record)
    resume = read_results(args.results, spec) if args.resume else None
    backend = sweep_backend(args, jobs)
    tally = StressTally()
    with Outputs() as outs:
        files = {k: outs.path(args.out / name) for k, name in REPORT_FILES.items()}
        with open(files["jsonl"], "w", encoding="utf-8") as fh:

            def keep(rec: dict[str, Any]) -> None:
                run = StressRun(**rec)
                fh.write(json.dumps(rec) + "\n")
                fh.flush()  # a finished run is on disk at once
                tally.add(run)

            end = run_sweep(spec, backend, keep, resume=resume, progress=not args.json,
                            results=None if args.results is None else outs.journal(
                                args.results, keep_on_abort=args.resume),
                            desc="stress", unit="run")
        rows = tally.rows()
        if not rows:
            outs.abort()
            return sweep_exit(end, "no run had finished; nothing written")
        if recording is not None and not end.early:
            _record_stress_run(args, timing)
        with holding_stops():  # a second Ctrl-C must not lose the first one's results
            with open(files["json"], "w", encoding="utf-8") as fh:
                json.dump(report_document(rows, tally.runs) | {
                    "interrupted": end.early, "vehicle": args.vehicle,
                    "timing": args.timing}, fh, indent=1)
            files["md"].write_text(markdown_table(rows) + "\n", encoding="utf-8")
            plot(rows, files["png"])
            outs.commit()
    written = ", ".join(REPORT_FILES.values())
    if args.json:
        print(json_text({"summary": rows, "runs": tally.runs, "jobs": jobs,
                          "interrupted": end.early, "out": str(args.out),
                          "vehicle": args.vehicle, "timing": args.timing,
                          "recording": str(recording) if recording is not None
                          and not end.early else None}))
    else:
        print(markdown_table(rows))
        print(f"wrote {args.out}/: {written}")
        if recording is not None and not end.early:
            print(f"wrote {recording}")
    return sweep_exit(end, f"kept the {tally.runs} of {jobs} runs that had finished and "
                           f"their summary in {args.out}/ ({written})" + resume_hint(args))


def _record_stress_run(args: argparse.Namespace, timing: Timing) -> None:
    """The battery's drive with the LIS reset stage, run again in this process into the
    recording (the sweep may have run it in a worker; the drive is deterministic, so it
    is the same drive)."""
    from .record import run_recorder
    from .stress import run_one

    seed, fault = args.seeds[0], args.faults[0]
    rec = run_recorder(args.mcap, args.rosbag, f"stress seed-{seed} {fault}")
    assert rec is not None
    with rec:
        run_one(seed, fault, True, args.camera, args.vehicle, timing, on_step=rec.step)


def _speeds_arg(text: str) -> tuple[float, ...]:
    # speed_arg's error is argparse's: it reads "argument --speeds: expected …".
    speeds = tuple(speed_arg(v.strip()) for v in text.split(","))
    repeated = [v for k, v in enumerate(speeds) if v in speeds[:k]]
    if repeated:  # its runs would be made twice and pooled with themselves
        raise argparse.ArgumentTypeError(f"{repeated[0]:g} m/s is named twice: {text[:60]!r}")
    return speeds


def _evaluate_agent_parser(sub: Any) -> None:
    from .train import TEST_SEEDS

    ev = sub.add_parser(
        "evaluate-agent", help="laps of an agent on held-out generated tracks (speed sweep)",
        description="The PID or a PPO policy drives each held-out generated track (cartons "
                    "removed) from its start line; a run succeeds when the laps are done "
                    "without a departure. Ctrl-C keeps the runs finished so far.")
    ev.add_argument("--agent", choices=["pid", "ppo"], default="pid", help=AGENT_HELP)
    ev.add_argument("--policy", type=Path, help="PPO policy .zip (default: the committed one)")
    add_trust_policy_option(ev)
    ev.add_argument("--seeds", type=seed_range_arg, default=range(*TEST_SEEDS),
                    help=f"held-out seeds A:B (default: {TEST_SEEDS[0]}:{TEST_SEEDS[1]})")
    ev.add_argument("--laps", type=bounded_int_arg(1, 1000), default=3,
                    help="laps each run drives, 1–1000; a run succeeds when it drives them "
                         "without leaving the road (default: %(default)s)")
    ev.add_argument("--speeds", type=_speeds_arg, default=(1.5,),
                    help=f"comma-separated cruise speeds [m/s], each in "
                         f"[{MIN_CRUISE_SPEED_M_S:g}, {TOP_SPEED_M_S:g}] (default: 1.5)")
    add_sweep_options(ev, "runs")
    add_camera_option(ev)
    add_vehicle_options(ev)
    ev.add_argument("--out", type=Path, metavar="F.json",
                    help="also write the JSON to this file (default: none)")
    add_force_option(ev, "an existing --out")
    add_json_option(ev)
    ev.set_defaults(func=cmd_evaluate_agent)


def _check_agent_sweep(args: argparse.Namespace, suffixes: dict[str, str]
                       ) -> tuple[Any, str | None]:
    """What an agent sweep (evaluate-agent, limits) checks before any work: its sweep
    options, its outputs (``suffixes`` by option name), the camera, the timing and the
    agent; returns the timing read and the policy's path (None: the committed one)."""
    from .drive import check_agent

    check_sweep_options(args)
    # --resume replaces the report of the run it continues (and its --results file).
    check_outputs({name: getattr(args, name) for name in suffixes}, suffixes,
                  args.force or args.resume,
                  inputs={"policy": args.policy, "camera": camera_input(args.camera),
                          "timing": timing_input(args.timing)})
    camera = check_camera_geometry(args.camera)
    timing = resolve_timing_arg(args.timing)
    try:
        check_agent(args.agent, args.policy, camera, trust_policy=args.trust_policy)
    except (ValueError, FileNotFoundError, ImportError) as exc:
        raise CliError(str(exc)) from None
    return timing, None if args.policy is None else str(args.policy)


def cmd_evaluate_agent(args: argparse.Namespace) -> int:
    from tfalda_sim.outputs import Outputs
    from tfalda_sim.sweep_runner import SweepSpec, read_results, resume_hint, run_sweep

    from .evaluate import (
        check_run_record,
        evaluation_jobs,
        result_document,
        run_job,
        run_record,
    )

    timing, policy = _check_agent_sweep(args, {"out": ".json", "results": ".jsonl"})
    jobs = len(args.seeds) * len(args.speeds)
    spec = SweepSpec(command="evaluate-agent",
                     config={"agent": args.agent, "policy": policy,
                             "seeds": f"{args.seeds.start}:{args.seeds.stop}",
                             "laps": args.laps, "speeds": list(args.speeds),
                             "camera": args.camera, **vehicle_config(args)},
                     jobs=evaluation_jobs(args.agent, policy, args.seeds, args.laps,
                                          args.speeds, args.camera, args.trust_policy,
                                          args.vehicle, timing),
                     total=jobs, fn=run_job, record=run_record, check=check_run_record)
    resume = read_results(args.results, spec) if args.resume else None
    backend = sweep_backend(args, jobs)
    runs: list[dict[str, Any]] = []
    with Outputs() as outs:
        end = run_sweep(spec, backend, runs.append, resume=resume, progress=not args.json,
                        results=None if args.results is None else outs.journal(
                            args.results, keep_on_abort=args.resume),
                        desc=args.agent, unit="run")
        if not runs:
            outs.abort()
            return sweep_exit(end, "no run had finished; nothing written")
        with holding_stops():  # a second Ctrl-C must not lose the first one's results
            result = result_document(args.agent, policy, args.camera, args.laps, args.seeds,
                                     args.speeds, runs, end.interrupted, end.worker_died,
                                     vehicle=args.vehicle, timing=args.timing)
            if args.out:
                outs.path(args.out).write_text(json_text(result, indent=1), encoding="utf-8")
            outs.commit()
    if args.json:
        print(json_text(result))
    else:
        print(f"{args.agent}: {args.laps} laps on seeds {args.seeds.start}:{args.seeds.stop}"
              f" ({args.vehicle} car, {args.timing} timing)")
        print(f"{'speed':>8}{'success':>10}{'mean |e|':>10}{'resets/track':>14}")
        for r in result["speeds"]:
            print(f"{r['speed_m_s']:>6.2f} m/s{r['successes']:>5}/{r['tracks']:<4}"
                  f"{r['mean_abs_cross_track_m'] * 100:>8.1f}cm"
                  f"{r['roi_resets_per_track']:>12.2f}")
        for path in (args.out, args.results):
            if path:
                print(f"wrote {path}")
    files = [str(p) for p in (args.out, args.results) if p]
    return sweep_exit(end, f"kept the {len(runs)} of {jobs} runs that had finished"
                           + (f" ({', '.join(files)})" if files else "") + resume_hint(args))


def _limits_parser(sub: Any) -> None:
    from .limits import LOWEST_SPEED_M_S, STEP_M_S
    from .limits import TOP_SPEED_M_S as TOP
    from .train import TEST_SEEDS

    li = sub.add_parser(
        "limits", help="per track, the highest constant speed an agent keeps its lane at",
        description=f"Per held-out generated track (cartons removed), the highest constant "
                    f"cruise speed at which the agent drives the laps without a departure, "
                    f"found by bisection to {STEP_M_S:g} m/s between --lowest-speed "
                    f"(default {LOWEST_SPEED_M_S:g} m/s) and the car's top speed ({TOP:g} "
                    f"m/s); reported as a distribution. A track failed at the lowest speed "
                    f"has no limit (null, below_min_speed). Ctrl-C keeps the tracks "
                    f"finished so far.")
    li.add_argument("--agent", choices=["pid", "ppo"], default="pid", help=AGENT_HELP)
    li.add_argument("--policy", type=Path, help="PPO policy .zip (default: the committed one)")
    add_trust_policy_option(li)
    li.add_argument("--seeds", type=seed_range_arg, default=range(*TEST_SEEDS),
                    help=f"held-out seeds A:B (default: {TEST_SEEDS[0]}:{TEST_SEEDS[1]})")
    li.add_argument("--laps", type=bounded_int_arg(1, 1000), default=2,
                    help="laps each drive must complete without leaving the road, 1–1000 "
                         "(default: %(default)s)")
    li.add_argument("--lowest-speed", type=bounded_float_arg(MIN_CRUISE_SPEED_M_S, TOP - 0.1,
                                                             "m/s"),
                    default=LOWEST_SPEED_M_S, metavar="V",
                    help=f"the lowest speed tried, in [{MIN_CRUISE_SPEED_M_S:g}, "
                         f"{TOP - 0.1:g}] m/s: a track failed there has no limit; raise it "
                         "for an agent that fails slow drives it passes faster "
                         "(default: %(default)s)")
    add_sweep_options(li, "tracks")
    add_camera_option(li)
    add_vehicle_options(li)
    li.add_argument("--out", type=Path, metavar="F.json",
                    help="also write the JSON to this file (default: none)")
    li.add_argument("--plot", type=Path, metavar="F.png",
                    help="histogram of the limits (default: none)")
    add_force_option(li, "an existing --out or --plot")
    add_json_option(li)
    li.set_defaults(func=cmd_limits)


def cmd_limits(args: argparse.Namespace) -> int:
    from tfalda_sim.outputs import Outputs
    from tfalda_sim.sweep_runner import SweepSpec, read_results, resume_hint, run_sweep

    from .limits import (
        check_run_record,
        limit_jobs,
        plot,
        result_document,
        run_job,
        run_record,
        table,
    )

    timing, policy = _check_agent_sweep(
        args, {"out": ".json", "plot": ".png", "results": ".jsonl"})
    jobs = len(args.seeds)
    spec = SweepSpec(command="limits",
                     config={"agent": args.agent, "policy": policy,
                             "seeds": f"{args.seeds.start}:{args.seeds.stop}",
                             "laps": args.laps, "lowest_speed": args.lowest_speed,
                             "camera": args.camera, "vehicle": args.vehicle,
                             "timing": args.timing},
                     jobs=limit_jobs(args.agent, policy, args.seeds, args.laps, args.camera,
                                     args.trust_policy, args.vehicle, timing,
                                     args.lowest_speed),
                     total=jobs, fn=run_job, record=run_record, check=check_run_record)
    resume = read_results(args.results, spec) if args.resume else None
    backend = sweep_backend(args, jobs)
    per_seed: list[dict[str, Any]] = []
    with Outputs() as outs:
        end = run_sweep(spec, backend, per_seed.append, resume=resume, progress=not args.json,
                        results=None if args.results is None else outs.journal(
                            args.results, keep_on_abort=args.resume),
                        desc=f"{args.agent} limits", unit="track")
        if not per_seed:
            outs.abort()
            return sweep_exit(end, "no track had finished; nothing written")
        with holding_stops():  # a second Ctrl-C must not lose the first one's results
            result = result_document(args.agent, policy, args.camera, args.vehicle,
                                     args.timing, args.laps, args.seeds, per_seed,
                                     end.interrupted, end.worker_died, args.lowest_speed)
            if args.out:
                outs.path(args.out).write_text(json_text(result, indent=1), encoding="utf-8")
            if args.plot:
                plot(result, outs.path(args.plot))
            outs.commit()
    files = [str(p) for p in (args.out, args.plot, args.results) if p]
    if args.json:
        print(json_text(result))
    else:
        print(table(result))
        for path in files:
            print(f"wrote {path}")
    return sweep_exit(end, f"kept the {len(per_seed)} of {jobs} tracks that had finished"
                           + (f" ({', '.join(files)})" if files else "") + resume_hint(args))
