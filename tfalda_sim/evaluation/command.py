"""The evaluation's commands: ``evaluate`` (the thesis' test system) and ``compare``
(the Hough baseline against TFALDA with and without the LIS)."""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..camera import load_camera
from ..camera.command import add_camera_option, camera_input
from ..camera.ros_info import camera_info_of
from ..cli_common import (
    DIRECTORY,
    RECORDING_SUFFIXES,
    CliError,
    add_force_option,
    add_json_option,
    add_recording_options,
    bounded_float_arg,
    bounded_int_arg,
    check_outputs,
    json_text,
    seed_range_arg,
    speed_arg_for,
)
from ..interrupts import holding_stops
from ..perception import DetectorConfig, LaneObservation
from ..perception.command import check_camera_geometry
from ..perception.params import IMAGE_WIDTH_PX
from ..recording import Recorder, RecordingFormat
from ..rendering import FrameTruth, Renderer
from ..sweep_runner import (
    SweepEnd,
    SweepSpec,
    add_sweep_options,
    check_sweep_options,
    read_results,
    resume_hint,
    run_sweep,
    sweep_backend,
    sweep_exit,
)
from ..vehicle import MIN_CRUISE_SPEED_M_S, CarParams
from .metrics import EPSILON_PX
from .runner import WITH_LIS, WITHOUT_LIS, run_scenario
from .scenarios import (
    THESIS_SPEED_M_S,
    ScenarioKind,
    generated_scenario,
    thesis_scenario,
)
from .trajectory import FRAME_RATE_HZ

PRESETS = {"thesis": DetectorConfig.thesis, "improved": DetectorConfig.improved}
"""The "with LIS" configurations ``--preset`` selects."""

_SUFFIXES = {"plot": ".png", "xml": ".xml", "jsonl": ".jsonl", "video": ".mp4",
             "results": ".jsonl", **RECORDING_SUFFIXES}


def register(sub: Any) -> None:
    """Add the evaluation's commands to the ``tfalda-sim`` subparsers."""
    _evaluate_parser(sub)
    _compare_parser(sub)


MAX_STRIDE: int = 50
"""Largest ``--stride``: one frame per second of the drive (50 frames/s); beyond it a lap
keeps a handful of frames and the LIS's frame-to-frame filters mean nothing."""

MAX_FRAMES: int = 10**7
"""Largest ``--max-frames`` (60 hours of driving at 50 frames/s)."""


def _evaluate_parser(sub: Any) -> None:
    ev = sub.add_parser(
        "evaluate", help="run the thesis' test system: hit rate with and without the LIS",
        description="Render a scenario, run TFALDA with and without the LIS on every frame "
                    "and score the lanes against the exact ground truth (thesis ch. 4). "
                    "Generated tracks stream: --jsonl gets each track's frames as it "
                    "finishes, and Ctrl-C keeps the tracks finished so far.")
    ev.add_argument("--scenario", choices=[k.value for k in ScenarioKind],
                    help="the thesis' straight/curve/track drive, or generated tracks")
    ev.add_argument("--frames", type=Path, metavar="SOURCE",
                    help="instead of a scenario: real frames scored against --labels — a "
                         "folder of frames (a sequence, in name order), or a recording (a "
                         "video, a ROS 1/2 bag, an MCAP file); see docs/recordings.md")
    ev.add_argument("--topic",
                    help="with --frames RECORDING: its image topic (default: its only one)")
    ev.add_argument("--labels", type=Path,
                    help="with --frames: the folder of their labels, <frame>.labels.json "
                         "(a folder's frames) or frame-<i>.labels.json (a recording's frame "
                         "i, counted from 0)")
    ev.add_argument("--detector", choices=["tfalda", "hough", "both"], default=None,
                    help="with --frames: which detectors to score (default tfalda)")
    ev.add_argument("--repeat", type=bounded_int_arg(1, 1000), default=None,
                    help="with --frames: feed each frame N times before scoring it (the LIS "
                         "settles on a still image; default 1)")
    ev.add_argument("--stills", action="store_true",
                    help="with --frames: the frames are unrelated stills, the detectors start "
                         "afresh on each (default: a sequence)")
    ev.add_argument("--seeds", type=seed_range_arg,
                    help="generated tracks A:B (seeds A … B−1) for --scenario random")
    runs = ev.add_mutually_exclusive_group()
    runs.add_argument("--no-lis", action="store_true",
                      help="only the run without the LIS (default: with and without)")
    runs.add_argument("--ablation", action="store_true",
                      help="run the LIS ablation: each stage off alone and on alone")
    ev.add_argument("--preset", choices=sorted(PRESETS),
                    help="the configuration of the run with the LIS (default: thesis); not "
                         "with --no-lis, which has no such run")
    ev.add_argument("--epsilon-px", type=bounded_float_arg(0.0, IMAGE_WIDTH_PX, "px",
                                                           why="up to the image width"),
                    default=EPSILON_PX,
                    help=f"hit distance of the black-box test [px] (default {EPSILON_PX:g})")
    ev.add_argument("--speed", type=speed_arg_for(MIN_CRUISE_SPEED_M_S,
                                                  CarParams().max_speed_m_s),
                    default=THESIS_SPEED_M_S,
                    help=f"car speed [m/s] (default {THESIS_SPEED_M_S:.3f}: 15 km/h; at most "
                         "the car's top speed)")
    ev.add_argument("--stride", type=bounded_int_arg(1, MAX_STRIDE), default=1,
                    help=f"use every N-th camera frame ({FRAME_RATE_HZ:g}/s), 1–{MAX_STRIDE}")
    ev.add_argument("--max-frames", type=bounded_int_arg(1, MAX_FRAMES),
                    help="random: cut each lap after this many frames")
    add_sweep_options(ev, "tracks")
    ev.add_argument("--plot", type=Path, help="PNG chart (per frame; random: per track)")
    ev.add_argument("--xml", type=Path, help="lanes per frame, thesis listing 4.1 (one track)")
    ev.add_argument("--jsonl", type=Path, help="every frame of every run as JSON Lines")
    ev.add_argument("--video", type=Path, help="MP4 with ROIs and lanes drawn (one track)")
    add_recording_options(ev, "the drive (one track; the run with LIS)")
    add_camera_option(ev)
    add_force_option(ev)
    add_json_option(ev)
    ev.set_defaults(func=cmd_evaluate, parser=ev)


def _configs(args: argparse.Namespace) -> dict[str, DetectorConfig]:
    from .sweep import ablation_configs

    preset = PRESETS[args.preset]()
    if args.ablation:
        return ablation_configs(preset)
    if args.no_lis:
        return {WITHOUT_LIS: DetectorConfig.without_lis()}
    return {WITH_LIS: preset, WITHOUT_LIS: DetectorConfig.without_lis()}


_SCENARIO_ONLY = ("seeds", "max_frames", "workers", "plot", "xml", "jsonl", "video", "mcap",
                  "rosbag",
                  "ray_address", "results", "resume")
_FRAMES_ONLY = ("labels", "detector", "repeat", "stills", "topic")


def _check_frames(args: argparse.Namespace) -> None:
    """``--frames`` mode: contradictory options refused by name."""
    if args.scenario is not None:
        args.parser.error("--scenario renders a drive, --frames scores real frames: give one")
    if args.labels is None:
        args.parser.error("--frames needs --labels DIR (the frames' <name>.labels.json)")
    for opt in (*_SCENARIO_ONLY, "ablation"):
        if getattr(args, opt) not in (None, False):
            args.parser.error(f"--{opt.replace('_', '-')} applies to a --scenario, not to "
                              "--frames")
    if args.backend != "local":
        args.parser.error("--backend applies to --scenario random, not to --frames")
    if args.speed != THESIS_SPEED_M_S or args.stride != 1:
        args.parser.error("--speed and --stride apply to a --scenario, not to --frames")
    if args.detector == "hough" and (args.preset is not None or args.no_lis):
        args.parser.error("--preset and --no-lis configure TFALDA; --detector hough runs "
                          "none")


def _check(args: argparse.Namespace) -> None:
    check_sweep_options(args)
    if args.frames is None:
        if args.scenario is None:
            args.parser.error("give --scenario (a rendered drive) or --frames DIR --labels "
                              "DIR (real frames)")
        for opt in _FRAMES_ONLY:
            if getattr(args, opt) not in (None, False):
                args.parser.error(f"--{opt} applies to --frames, not to a --scenario")
    if args.no_lis and args.preset is not None:
        args.parser.error("--preset configures the run with the LIS; --no-lis runs only the "
                          "one without it: drop one of them")
    args.preset = args.preset or "thesis"
    random = args.scenario == ScenarioKind.RANDOM.value
    if random and args.seeds is None:
        args.parser.error("--scenario random needs --seeds A:B (e.g. --seeds 0:50)")
    if not random:
        for opt, value in (("--seeds", args.seeds), ("--max-frames", args.max_frames),
                           ("--workers", args.workers), ("--results", args.results),
                           ("--backend ray", "ray" if args.backend == "ray" else None)):
            if value is not None:
                args.parser.error(f"{opt} only applies to --scenario random")
        try:  # the thesis' strips are laid out for its speed: check the drive fits
            thesis_scenario(ScenarioKind(args.scenario), speed_m_s=args.speed,
                            stride=args.stride)
        except ValueError as exc:
            args.parser.error(f"--speed {args.speed:g} × --stride {args.stride} does not fit "
                              f"the thesis' {args.scenario} drive: {exc}")
    if random and len(args.seeds) > 1:
        for opt in ("xml", "video", "mcap", "rosbag"):
            if getattr(args, opt) is not None:
                raise CliError(f"--{opt} writes one track's run; give a single seed "
                               f"(--seeds {args.seeds.start}:{args.seeds.start + 1})")
    if random and _is_sweep(args):
        for opt in ("xml", "video", "mcap", "rosbag"):
            if getattr(args, opt) is not None:
                args.parser.error(f"--{opt} records one track's run in this process; not "
                                  "with --results or --backend ray")
    if args.resume and args.jsonl is not None:
        args.parser.error("--jsonl writes every frame of every track; a resumed sweep has "
                          "only the finished tracks' results, not their frames: drop --jsonl "
                          "or start afresh without --resume")
    # --resume replaces the report of the run it continues (and its --results file).
    check_outputs({k: getattr(args, k) for k in _SUFFIXES}, _SUFFIXES,
                  args.force or args.resume, inputs={"camera": camera_input(args.camera)})


def _is_sweep(args: argparse.Namespace) -> bool:
    """A random scenario streamed as a sweep (one seed too with --results or Ray)."""
    return (len(args.seeds) > 1 or args.results is not None or args.backend == "ray")


def cmd_evaluate(args: argparse.Namespace) -> int:
    from ..outputs import Outputs

    if args.frames is not None:
        return _evaluate_frames(args)
    _check(args)
    camera = check_camera_geometry(args.camera)
    configs = {k: c.on_camera(camera) for k, c in _configs(args).items()}
    kind = ScenarioKind(args.scenario)
    progress = sys.stderr.isatty() or not args.json
    out: dict[str, Any] = {"scenario": kind.value, "preset": args.preset, "camera": args.camera,
                           "epsilon_px": args.epsilon_px, "speed_m_s": args.speed,
                           "stride": args.stride, "runs": list(configs)}
    with Outputs() as outs:
        if kind is ScenarioKind.RANDOM and _is_sweep(args):
            end = _evaluate_seeds(args, configs, out, outs, progress)
        else:
            end = _evaluate_one(args, configs, kind, out, outs, progress)
        if end.early and "frames_done" not in out and not out.get("per_seed"):
            outs.abort()
            return sweep_exit(end, "no frame had been evaluated; nothing written")
        with holding_stops():
            outs.commit()
    if args.json:
        print(json_text(out))
    else:
        _print_table(out)
    what = (f"kept the {out['tracks_done']} of {len(args.seeds)} tracks that had finished"
            if "tracks_done" in out else f"kept the {out['frames_done']} frames evaluated so far")
    files = [out[k] for k in ("plot", "xml", "jsonl", "video", "recording", "results")
             if k in out]
    return sweep_exit(end, what + (f" ({', '.join(files)})" if files else "")
                      + resume_hint(args))


def _evaluate_frames(args: argparse.Namespace) -> int:
    """``evaluate --frames DIR --labels DIR``: the detectors on labelled real frames."""
    from ..perception.hough import REAL_FRAME_BINARISE_LEVEL, HoughConfig
    from ..sources import SourceError, open_source
    from .frames import (
        FramesError,
        folder_frames,
        frame_files,
        recording_labels,
        score_frames,
        source_frames,
    )

    _check_frames(args)
    camera = check_camera_geometry(args.camera)
    folder = args.frames.is_dir() and not (args.frames / "metadata.yaml").exists()
    if folder and args.topic is not None:
        args.parser.error("--topic picks a recording's image topic; --frames is a folder of "
                          "frames: drop --topic")
    try:
        if folder:
            pairs = frame_files(args.frames, args.labels)
            frames, count = folder_frames(pairs, camera), len(pairs)
        else:
            source = open_source(args.frames, topic=args.topic)
            labels = recording_labels(args.labels, str(args.frames))
            frames = source_frames(source, labels, camera, stills=args.stills)
            count = len(labels)
    except (FramesError, SourceError) as exc:
        raise CliError(str(exc)) from None
    which = args.detector or "tfalda"
    tfalda: dict[str, DetectorConfig] = {}
    if which in ("tfalda", "both"):
        args.preset = args.preset or "thesis"
        base = {WITHOUT_LIS: DetectorConfig.without_lis()} if args.no_lis else {
            WITH_LIS: PRESETS[args.preset](), WITHOUT_LIS: DetectorConfig.without_lis()}
        tfalda = {k: c.on_camera(camera) for k, c in base.items()}
    hough = ({"Hough (real frames)": HoughConfig.for_camera(camera, REAL_FRAME_BINARISE_LEVEL)}
             if which in ("hough", "both") else {})
    try:
        results = score_frames(frames, camera, tfalda=tfalda, hough=hough,
                               repeat=args.repeat or 1, stills=args.stills,
                               epsilon_px=args.epsilon_px)
    except (FramesError, SourceError) as exc:
        raise CliError(str(exc)) from None
    out = {"frames": str(args.frames), "labels": str(args.labels), "camera": args.camera,
           "repeat": args.repeat or 1, "stills": args.stills, "epsilon_px": args.epsilon_px,
           "detectors": {r.label: r.summary() | {"per_frame": r.per_frame} for r in results}}
    if args.json:
        print(json_text(out))
        return 0
    print(f"{count} labelled {'stills' if args.stills else 'frames'} in {args.frames}, "
          f"camera {args.camera}, each frame {args.repeat or 1}× (on a marking: ≥ 80 % of a "
          f"line's pixels within {args.epsilon_px:g} px of one)")
    for r in results:
        s = r.summary()
        extra = (f", lanes on markings {s['mean_lanes_on_markings']:.2f}/4"
                 if "mean_lanes_on_markings" in s else "")
        print(f"  {r.label:22} mean hit rate {s['mean_hit_rate']:.3f}{extra}, both ego "
              f"boundaries found on {s['ego_found_share'] * 100:.0f} % of frames")
        for rec in r.per_frame:
            rates = " ".join(f"{v:.2f}" for v in rec["hit_rates"])
            print(f"    {rec['frame']:28} {rates}")
    return 0


def _evaluate_seeds(args: argparse.Namespace, configs: Mapping[str, DetectorConfig],
                    out: dict[str, Any], outs: Any, progress: bool) -> SweepEnd:
    """A range of generated tracks, streamed: each finished track goes to --results, to
    --jsonl (its frames) and to the pooled tallies, then is dropped. Returns how the
    stream ended."""
    from .export import frame_records
    from .sweep import PooledTally, check_seed_record, seed_job, seed_record

    spec = SweepSpec(command="evaluate",
                     config={"scenario": args.scenario,
                             "seeds": f"{args.seeds.start}:{args.seeds.stop}",
                             "preset": args.preset, "no_lis": args.no_lis,
                             "ablation": args.ablation, "epsilon_px": args.epsilon_px,
                             "speed": args.speed, "stride": args.stride,
                             "max_frames": args.max_frames, "camera": args.camera},
                     jobs=(int(s) for s in args.seeds), total=len(args.seeds),
                     fn=seed_job(configs, epsilon_px=args.epsilon_px, camera=args.camera,
                                 speed_m_s=args.speed, stride=args.stride,
                                 max_frames=args.max_frames),
                     record=seed_record, check=check_seed_record)
    resume = read_results(args.results, spec) if args.resume else None
    backend = sweep_backend(args, len(args.seeds))
    tallies = {label: PooledTally() for label in configs}
    per_seed: list[dict[str, Any]] = []
    lines = 0
    with contextlib.ExitStack() as stack:
        fh = (stack.enter_context(open(outs.path(args.jsonl), "w", encoding="utf-8"))
              if args.jsonl is not None else None)

        def keep(rec: Mapping[str, Any]) -> None:
            if set(rec["runs"]) != set(tallies):
                raise ValueError(f"runs {sorted(rec['runs'])}, expected {sorted(tallies)}")
            for label, run in rec["runs"].items():
                tallies[label].add_counts(run["counts"])
                per_seed.append(run["summary"])

        def frames(seed: int, runs: Mapping[str, Any]) -> None:
            nonlocal lines
            if fh is None:
                return
            for run in runs.values():
                for r in frame_records(run):
                    fh.write(json.dumps(r, allow_nan=False) + "\n")
                    lines += 1
            fh.flush()  # a finished track is on disk at once

        end = run_sweep(spec, backend, keep, resume=resume, progress=progress,
                        results=None if args.results is None else outs.journal(
                            args.results, keep_on_abort=args.resume),
                        desc="tracks", unit="track", on_result=frames)
    out["seeds"] = [args.seeds.start, args.seeds.stop]
    out["tracks_done"] = len(per_seed) // len(configs)
    out["interrupted"] = end.early
    out["per_seed"] = per_seed
    if not per_seed:
        return end
    with holding_stops():  # a second Ctrl-C must not lose the first one's results
        out["pooled"] = {label: t.summary() for label, t in tallies.items()}
        _write_seed_outputs(args, configs, out, outs, per_seed, lines)
        if args.results is not None:
            out["results"] = str(args.results)
    return end


def _write_seed_outputs(args: argparse.Namespace, configs: Mapping[str, DetectorConfig],
                        out: dict[str, Any], outs: Any, per_seed: list[dict[str, Any]],
                        lines: int) -> None:
    from .charts import plot_ablation, plot_seeds

    if args.plot is not None:
        if args.ablation:
            rows = [{"config": label, **out["pooled"][label]} for label in configs]
            plot_ablation(rows, outs.path(args.plot), title=f"LIS ablation: {_title(args)}")
        else:
            plot_seeds(per_seed, outs.path(args.plot), title=_title(args))
        out["plot"] = str(args.plot)
    if args.jsonl is not None:
        out["jsonl_lines"] = lines
        out["jsonl"] = str(args.jsonl)


def _evaluate_one(args: argparse.Namespace, configs: Mapping[str, DetectorConfig],
                  kind: ScenarioKind, out: dict[str, Any], outs: Any, progress: bool
                  ) -> SweepEnd:
    """One track, run in this process (so a video records this very run). Returns how it
    ended (after a Ctrl-C the frames so far are reported and written)."""
    from ..video import VideoWriter
    from .runner import ScenarioInterrupted

    scenario = (generated_scenario(args.seeds.start, speed_m_s=args.speed,
                                   stride=args.stride, max_frames=args.max_frames)
                if kind is ScenarioKind.RANDOM
                else thesis_scenario(kind, speed_m_s=args.speed, stride=args.stride))
    end = SweepEnd()
    with contextlib.ExitStack() as stack:
        hook = None
        if args.video is not None:
            writer = stack.enter_context(VideoWriter(outs.path(args.video),
                                                     FRAME_RATE_HZ / args.stride))
            hook = _video_hook(writer, _primary_label(configs))
        if args.mcap is not None or args.rosbag is not None:
            recorder = stack.enter_context(Recorder(
                args.mcap or args.rosbag,
                RecordingFormat.MCAP if args.mcap is not None else RecordingFormat.ROSBAG,
                camera_info=camera_info_of(load_camera(args.camera)),
                source=f"evaluate {scenario.name}"))
            hook = _both(hook, _recording_hook(recorder, _primary_label(configs), scenario))
        try:
            single = run_scenario(scenario, configs, epsilon_px=args.epsilon_px,
                                  progress=progress, on_frame=hook,
                                  renderer=Renderer(load_camera(args.camera)))
        except ScenarioInterrupted as exc:
            end.interrupted = True
            if exc.results is None:
                return end
            single = exc.results
        stack.enter_context(holding_stops())  # closing the video, writing the rest
        _write_one_outputs(args, configs, kind, out, outs, single, end)
    return end


def _write_one_outputs(args: argparse.Namespace, configs: Mapping[str, DetectorConfig],
                       kind: ScenarioKind, out: dict[str, Any], outs: Any,
                       single: Mapping[str, Any], end: SweepEnd) -> None:
    from .charts import plot_ablation, plot_confidence
    from .export import write_jsonl, write_lanes_xml
    from .sweep import pooled_summary

    out["interrupted"] = end.early
    out["frames_done"] = len(next(iter(single.values())).seq)
    if args.video is not None:
        out["video"] = str(args.video)
    if args.mcap is not None or args.rosbag is not None:
        out["recording"] = str(args.mcap or args.rosbag)
    if kind is ScenarioKind.RANDOM:
        out["seeds"] = [args.seeds.start, args.seeds.stop]
        out["per_seed"] = [run.summary() for run in single.values()]
        out["pooled"] = {label: pooled_summary([run]) for label, run in single.items()}
    else:
        out["summary"] = {label: run.summary() for label, run in single.items()}
    if args.plot is not None:
        if args.ablation:
            rows = [{"config": label, **(out["pooled"][label] if "pooled" in out
                                         else out["summary"][label])} for label in configs]
            plot_ablation(rows, outs.path(args.plot), title=f"LIS ablation: {_title(args)}")
        else:
            plot_confidence(single, outs.path(args.plot), title=_title(args))
        out["plot"] = str(args.plot)
    if args.xml is not None:
        write_lanes_xml(single[_primary_label(single)], outs.path(args.xml))
        out["xml"] = str(args.xml)
    if args.jsonl is not None:
        out["jsonl_lines"] = write_jsonl(single.values(), outs.path(args.jsonl))
        out["jsonl"] = str(args.jsonl)


def _primary_label(configs: Mapping[str, Any]) -> str:
    """The run whose lanes go to the XML and the video: with LIS, else the first."""
    for label in (WITH_LIS, "all stages"):
        if label in configs:
            return label
    return next(iter(configs))


def _title(args: argparse.Namespace) -> str:
    what = (f"generated tracks {args.seeds.start}–{args.seeds.stop - 1}"
            if args.seeds is not None else f"thesis {args.scenario} drive")
    frames = "every frame" if args.stride == 1 else f"every {args.stride}. frame"
    return f"{what}, {args.speed * 3.6:.0f} km/h (scaled), {frames}"


def _video_hook(writer: Any, label: str) -> Any:
    from ..rendering.overlay import draw_observation

    def hook(seq: int, frame: np.ndarray, truth: FrameTruth,
             observations: Mapping[str, LaneObservation]) -> None:
        writer.write(draw_observation(frame, observations[label], truth=truth,
                                      text=f"seq {seq} {label}"))

    return hook


def _both(first: Any, second: Any) -> Any:
    """One frame hook calling ``first`` (if any) and ``second``."""
    if first is None:
        return second

    def hook(*args: Any) -> None:
        first(*args)
        second(*args)

    return hook


def _recording_hook(recorder: Any, label: str, scenario: Any) -> Any:
    """Each frame of ``label``'s run into ``recorder``: the frame, lanes, LIS state, the
    ground truth (the ego lane's boundaries, the cross-track error from the right lane's
    centre, left > 0) and the scripted car's pose and speed."""
    from ..recording import RecordedStep, polyline_segments

    traj, track = scenario.trajectory, scenario.track

    def hook(seq: int, frame: np.ndarray, truth: FrameTruth,
             observations: Mapping[str, LaneObservation]) -> None:
        k = seq - scenario.first_seq
        obs = observations[label]
        x, y, yaw = (float(v) for v in traj.pose(k))
        s_hint = float(traj.s_m[k]) if np.isfinite(traj.s_m[k]) else None
        lateral = track.locate(x, y, s_hint_m=s_hint).lateral_m
        recorder.write(RecordedStep(
            t_s=float(traj.times_s[k] - traj.times_s[0]), frame=frame, lanes=obs.lanes,
            accepted=obs.accepted, rois=obs.rois,
            fault_counter=int(obs.fault_count), roi_reset=bool(obs.roi_reset),
            state=obs.state.value, pose=(x, y, yaw), speed_m_s=float(traj.speeds_m_s[k]),
            truth_lanes=np.vstack([polyline_segments(truth.left_boundary_px),
                                   polyline_segments(truth.right_boundary_px)]),
            cross_track_m=lateral + 0.5 * track.lane_width_m))

    return hook


def _print_table(out: dict[str, Any]) -> None:
    rows = (out["pooled"] if "pooled" in out else out["summary"])
    head = f"{'run':34} {'frames':>7} {'mean':>6} {'min':>6} {'<0.75':>6} {'resets':>6} " \
           f"{'acc':>6} {'FP':>6} {'FN':>6}"
    print(f"scenario {out['scenario']}" + (f", seeds {out['seeds'][0]}:{out['seeds'][1]}"
                                          if "seeds" in out else ""))
    print(head)
    for label, s in rows.items():
        acc = s["tusimple_accuracy"]
        print(f"{label:34} {s['frames']:7d} {s['mean_confidence']:6.3f} "
              f"{s['min_confidence']:6.3f} {s['frames_below_0_75']:6d} {s['roi_resets']:6d} "
              f"{acc if acc is not None else float('nan'):6.3f} "
              f"{s['false_positive_rate']:6.3f} {s['false_negative_rate']:6.3f}")
    for key in ("plot", "xml", "jsonl", "video", "recording", "results"):
        if key in out:
            print(f"wrote {out[key]}")


COMPARE_FILES = {"jsonl": "compare.jsonl", "json": "compare.json", "md": "compare.md",
                 "png": "compare.png"}
"""What ``tfalda-sim compare --out DIR`` writes into DIR: each scenario's figures as it
finishes (JSON Lines), the pooled result (JSON, Markdown) and its chart."""


def _thesis_list(text: str) -> tuple[str, ...]:
    kinds = tuple(k.strip() for k in text.split(",") if k.strip())
    bad = [k for k in kinds if k not in ("straight", "curve", "track")]
    if bad or not kinds:
        raise argparse.ArgumentTypeError(
            f"--thesis takes straight, curve and/or track, comma-separated; got {text[:60]!r}")
    if len(set(kinds)) != len(kinds):  # it would run twice and be pooled with itself
        raise argparse.ArgumentTypeError(f"--thesis names a scenario twice: {text[:60]!r}")
    return kinds


def _compare_parser(sub: Any) -> None:
    cp = sub.add_parser(
        "compare", help="score the Hough baseline against TFALDA with and without the LIS",
        description="Render the thesis' scenarios and generated tracks once, run the Hough "
                    "baseline (seed values and simulator preset) and TFALDA with and "
                    "without the LIS on every frame, and score all of them against the "
                    "same ground truth: hit rate, false positives, ego lines found, ms "
                    "per frame (tfalda_sim/evaluation/baseline.py). Scenarios stream to "
                    "OUT/compare.jsonl as they finish; Ctrl-C keeps the finished ones.")
    thesis = cp.add_mutually_exclusive_group()
    thesis.add_argument("--thesis", type=_thesis_list, default=("straight", "curve", "track"),
                        help="thesis scenarios, comma-separated (default: straight,curve,track)")
    thesis.add_argument("--no-thesis", action="store_true", help="generated tracks only")
    generated = cp.add_mutually_exclusive_group()
    generated.add_argument("--seeds", type=seed_range_arg, default=range(10000, 10010),
                           help="generated tracks A:B, one lap each (default 10000:10010, "
                                "held out)")
    generated.add_argument("--no-generated", action="store_true",
                           help="thesis scenarios only")
    cp.add_argument("--max-frames", type=bounded_int_arg(1, MAX_FRAMES),
                    help="cut each generated lap after this many frames")
    add_sweep_options(cp, "scenarios")
    cp.add_argument("--out", type=Path,
                    help="write compare.jsonl, compare.json, compare.md and compare.png into "
                         "this folder")
    add_camera_option(cp)
    add_force_option(cp)
    add_json_option(cp)
    cp.set_defaults(func=cmd_compare, parser=cp)


def cmd_compare(args: argparse.Namespace) -> int:
    from ..outputs import Outputs
    from .baseline import (
        CompareTally,
        Tally,
        check_run_record,
        compare_jobs,
        markdown_table,
        plot,
        run_job,
        run_record,
    )

    check_sweep_options(args)
    thesis = () if args.no_thesis else args.thesis
    seeds = range(0) if args.no_generated else args.seeds
    if not thesis and not len(seeds):
        args.parser.error("--no-thesis and --no-generated leave nothing to compare")
    if args.max_frames is not None and args.no_generated:
        args.parser.error("--max-frames cuts generated laps; --no-generated runs none")
    # Checked before minutes of work, not after; --resume replaces the report of the run
    # it continues (and its --results file).
    check_outputs({"out": args.out, "results": args.results},
                  {"out": DIRECTORY, "results": ".jsonl"}, args.force or args.resume,
                  files_in={"out": COMPARE_FILES.values()},
                  inputs={"camera": camera_input(args.camera)})
    check_camera_geometry(args.camera)
    jobs = len(thesis) + len(seeds)
    spec = SweepSpec(command="compare",
                     config={"thesis": list(thesis),
                             "seeds": f"{seeds.start}:{seeds.stop}" if len(seeds) else None,
                             "max_frames": args.max_frames, "camera": args.camera},
                     jobs=compare_jobs(thesis, seeds, args.max_frames, args.camera),
                     total=jobs, fn=run_job, record=run_record, check=check_run_record)
    resume = read_results(args.results, spec) if args.resume else None
    backend = sweep_backend(args, jobs)
    progress = sys.stderr.isatty() or not args.json
    tally = CompareTally()
    with Outputs() as outs, contextlib.ExitStack() as stack:
        files = ({k: outs.path(args.out / f) for k, f in COMPARE_FILES.items()}
                 if args.out is not None else None)
        fh = (stack.enter_context(open(files["jsonl"], "w", encoding="utf-8"))
              if files is not None else None)

        def keep(rec: dict[str, Any]) -> None:
            tally.add(rec["group"], {k: Tally.from_json(t) for k, t in rec["tallies"].items()})
            if fh is not None:
                fh.write(json.dumps({k: rec[k] for k in ("scenario", "group", "detectors")})
                         + "\n")
                fh.flush()  # a finished scenario is on disk at once

        end = run_sweep(spec, backend, keep, resume=resume, progress=progress,
                        results=None if args.results is None else outs.journal(
                            args.results, keep_on_abort=args.resume),
                        desc="scenarios", unit="scenario")
        stack.close()
        if not tally.jobs:
            outs.abort()
            return sweep_exit(end, "no scenario had finished; nothing written")
        with holding_stops():  # a second Ctrl-C must not lose the first one's results
            result = tally.result(thesis, seeds, args.max_frames)
            result.update(scenarios_done=tally.jobs, scenarios=jobs, interrupted=end.early)
            table = markdown_table(result)
            if files is not None:
                files["json"].write_text(json.dumps(result, indent=1), encoding="utf-8")
                files["md"].write_text(table, encoding="utf-8")
                plot(result, files["png"])
                result["out"] = {k: str(args.out / f) for k, f in COMPARE_FILES.items()}
            if args.results is not None:
                result["results"] = str(args.results)
            outs.commit()
    if args.json:
        print(json_text(result))
    else:
        print(table, end="")
        written = [*(result["out"].values() if args.out is not None else ()),
                   *([str(args.results)] if args.results is not None else ())]
        if written:
            print(f"wrote {', '.join(written)}")
    where = f" in {args.out}/ ({', '.join(COMPARE_FILES.values())})" if args.out else ""
    return sweep_exit(end, f"kept the {tally.jobs} of {jobs} scenarios that had finished"
                           + where + resume_hint(args))
