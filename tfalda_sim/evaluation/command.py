"""``tfalda-sim evaluate``: the thesis' test system from the command line."""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from tracks.fileformat import atomic_write

from ..cli_common import (
    CliError,
    check_outputs,
    finite_float_arg,
    positive_float_arg,
    positive_int_arg,
    seed_range_arg,
)
from ..perception import DetectorConfig, LaneObservation
from ..rendering import FrameTruth
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

_SUFFIXES = {"plot": ".png", "xml": ".xml", "jsonl": ".jsonl", "video": ".mp4"}


def add_evaluate_parser(sub: Any) -> None:
    ev = sub.add_parser(
        "evaluate", help="run the thesis' test system: hit rate with and without the LIS",
        description="Render a scenario, run TFALDA with and without the LIS on every frame "
                    "and score the lanes against the exact ground truth (thesis ch. 4).")
    ev.add_argument("--scenario", required=True, choices=[k.value for k in ScenarioKind],
                    help="the thesis' straight/curve/track drive, or generated tracks")
    ev.add_argument("--seeds", type=seed_range_arg,
                    help="generated tracks A:B (seeds A … B−1) for --scenario random")
    ev.add_argument("--no-lis", action="store_true",
                    help="only the run without the LIS (default: with and without)")
    ev.add_argument("--ablation", action="store_true",
                    help="run the LIS ablation: each stage off alone and on alone")
    ev.add_argument("--preset", choices=sorted(PRESETS), default="thesis",
                    help="the configuration of the run with the LIS (default: thesis)")
    ev.add_argument("--epsilon-px", type=finite_float_arg, default=EPSILON_PX,
                    help=f"hit distance of the black-box test [px] (default {EPSILON_PX:g})")
    ev.add_argument("--speed", type=positive_float_arg, default=THESIS_SPEED_M_S,
                    help=f"car speed [m/s] (default {THESIS_SPEED_M_S:.3f}: 15 km/h)")
    ev.add_argument("--stride", type=positive_int_arg, default=1,
                    help=f"use every N-th camera frame ({FRAME_RATE_HZ:g}/s); 2 for the "
                         "thesis' 30 km/h case")
    ev.add_argument("--max-frames", type=positive_int_arg,
                    help="random: cut each lap after this many frames")
    ev.add_argument("--workers", type=positive_int_arg,
                    help="random: processes (default: the CPUs available)")
    ev.add_argument("--plot", type=Path, help="PNG chart (per frame; random: per track)")
    ev.add_argument("--xml", type=Path, help="lanes per frame, thesis listing 4.1 (one track)")
    ev.add_argument("--jsonl", type=Path, help="every frame of every run as JSON Lines")
    ev.add_argument("--video", type=Path, help="MP4 with ROIs and lanes drawn (one track)")
    ev.add_argument("--force", action="store_true", help="overwrite existing output files")
    ev.add_argument("--json", action="store_true", help="print one JSON object")
    ev.set_defaults(func=cmd_evaluate)


def _configs(args: argparse.Namespace) -> dict[str, DetectorConfig]:
    from .sweep import ablation_configs

    preset = PRESETS[args.preset]()
    if args.ablation:
        return ablation_configs(preset)
    if args.no_lis:
        return {WITHOUT_LIS: DetectorConfig.without_lis()}
    return {WITH_LIS: preset, WITHOUT_LIS: DetectorConfig.without_lis()}


def _check(args: argparse.Namespace) -> None:
    random = args.scenario == ScenarioKind.RANDOM.value
    if random and args.seeds is None:
        raise CliError("--scenario random needs --seeds A:B (e.g. --seeds 0:50)")
    if not random:
        for opt, value in (("--seeds", args.seeds), ("--max-frames", args.max_frames),
                           ("--workers", args.workers)):
            if value is not None:
                raise CliError(f"{opt} only applies to --scenario random")
    if args.ablation and args.no_lis:
        raise CliError("--ablation already includes the run without the LIS; drop --no-lis")
    if not (np.isfinite(args.epsilon_px) and args.epsilon_px >= 0):
        raise CliError(f"--epsilon-px must be a finite number ≥ 0, got {args.epsilon_px}")
    if random and len(args.seeds) > 1:
        for opt in ("xml", "video"):
            if getattr(args, opt) is not None:
                raise CliError(f"--{opt} writes one track's run; give a single seed "
                               f"(--seeds {args.seeds.start}:{args.seeds.start + 1})")
    check_outputs({k: getattr(args, k) for k in _SUFFIXES}, _SUFFIXES, args.force)


def cmd_evaluate(args: argparse.Namespace) -> int:
    from .charts import plot_ablation, plot_confidence, plot_seeds
    from .export import write_jsonl, write_lanes_xml
    from .sweep import pooled_summary, run_seeds

    _check(args)
    configs = _configs(args)
    kind = ScenarioKind(args.scenario)
    progress = sys.stderr.isatty() or not args.json
    out: dict[str, Any] = {"scenario": kind.value, "preset": args.preset,
                           "epsilon_px": args.epsilon_px, "speed_m_s": args.speed,
                           "stride": args.stride, "runs": list(configs)}
    if kind is ScenarioKind.RANDOM and len(args.seeds) > 1:
        per_seed = run_seeds(args.seeds, configs, workers=args.workers,
                             epsilon_px=args.epsilon_px, progress=progress,
                             speed_m_s=args.speed, stride=args.stride,
                             max_frames=args.max_frames)
        single = None
    else:
        # one track: run it here, so a video records this very run
        scenario = (generated_scenario(args.seeds.start, speed_m_s=args.speed,
                                       stride=args.stride, max_frames=args.max_frames)
                    if kind is ScenarioKind.RANDOM
                    else thesis_scenario(kind, speed_m_s=args.speed, stride=args.stride))
        hook, writer = (_video_hook(args.video, _primary_label(configs), args.stride)
                        if args.video is not None else (None, contextlib.nullcontext()))
        with writer:  # a failed run discards its video and keeps an existing file
            single = run_scenario(scenario, configs, epsilon_px=args.epsilon_px,
                                  progress=progress, on_frame=hook)
        if args.video is not None:
            out["video"] = str(args.video)
        per_seed = [single]
    if kind is ScenarioKind.RANDOM:
        out["seeds"] = [args.seeds.start, args.seeds.stop]
        out["per_seed"] = [run.summary() for runs in per_seed for run in runs.values()]
        out["pooled"] = {label: pooled_summary([runs[label] for runs in per_seed])
                         for label in configs}
    else:
        out["summary"] = {label: run.summary() for label, run in single.items()}
    all_runs = [run for runs in per_seed for run in runs.values()]
    if args.plot is not None:
        if args.ablation:
            rows = [{"config": label, **(out["pooled"][label] if "pooled" in out
                                         else out["summary"][label])} for label in configs]
            plot_ablation(rows, args.plot, title=f"LIS ablation: {_title(args)}")
        elif single is not None:
            plot_confidence(single, args.plot, title=_title(args))
        else:
            plot_seeds(out["per_seed"], args.plot, title=_title(args))
        out["plot"] = str(args.plot)
    if args.xml is not None and single is not None:
        write_lanes_xml(single[_primary_label(single)], args.xml)
        out["xml"] = str(args.xml)
    if args.jsonl is not None:
        out["jsonl_lines"] = write_jsonl(all_runs, args.jsonl)
        out["jsonl"] = str(args.jsonl)
    if args.json:
        print(json.dumps(out))
    else:
        _print_table(out)
    return 0


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


def _video_hook(path: Path, label: str, stride: int) -> tuple[Any, Any]:
    from ..rendering.overlay import draw_observation
    from ..video import VideoWriter

    writer = VideoWriter(path, FRAME_RATE_HZ / stride)

    def hook(seq: int, frame: np.ndarray, truth: FrameTruth,
             observations: Mapping[str, LaneObservation]) -> None:
        writer.write(draw_observation(frame, observations[label], truth=truth,
                                      text=f"seq {seq} {label}"))

    return hook, writer


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
              f"{s['min_confidence']:6.3f} {s['frames_below_0_75']:6d} {s['resets']:6d} "
              f"{acc if acc is not None else float('nan'):6.3f} "
              f"{s['false_positive_rate']:6.3f} {s['false_negative_rate']:6.3f}")
    for key in ("plot", "xml", "jsonl", "video"):
        if key in out:
            print(f"wrote {out[key]}")


COMPARE_FILES = {"json": "compare.json", "md": "compare.md", "png": "compare.png"}
"""What ``tfalda-sim compare --out DIR`` writes into DIR."""


def _thesis_list(text: str) -> tuple[str, ...]:
    kinds = tuple(k.strip() for k in text.split(",") if k.strip())
    bad = [k for k in kinds if k not in ("straight", "curve", "track")]
    if bad or not kinds:
        raise argparse.ArgumentTypeError(
            f"--thesis takes straight, curve and/or track, comma-separated; got {text!r}")
    return kinds


def add_compare_parser(sub: Any) -> None:
    cp = sub.add_parser(
        "compare", help="score the Hough baseline against TFALDA with and without the LIS",
        description="Render the thesis' scenarios and generated tracks once, run the Hough "
                    "baseline (seed values and simulator preset) and TFALDA with and "
                    "without the LIS on every frame, and score all of them against the "
                    "same ground truth: hit rate, false positives, ego lines found, ms "
                    "per frame (tfalda_sim/evaluation/baseline.py).")
    cp.add_argument("--thesis", type=_thesis_list, default=("straight", "curve", "track"),
                    help="thesis scenarios, comma-separated (default: straight,curve,track)")
    cp.add_argument("--no-thesis", action="store_true", help="generated tracks only")
    cp.add_argument("--seeds", type=seed_range_arg, default=range(10000, 10010),
                    help="generated tracks A:B, one lap each (default 10000:10010, held out)")
    cp.add_argument("--no-generated", action="store_true", help="thesis scenarios only")
    cp.add_argument("--max-frames", type=positive_int_arg,
                    help="cut each generated lap after this many frames")
    cp.add_argument("--workers", type=positive_int_arg,
                    help="processes (default: the CPUs available)")
    cp.add_argument("--out", type=Path,
                    help="write compare.json, compare.md and compare.png into this directory")
    cp.add_argument("--force", action="store_true", help="overwrite existing output files")
    cp.add_argument("--json", action="store_true", help="print one JSON object")
    cp.set_defaults(func=cmd_compare)


def cmd_compare(args: argparse.Namespace) -> int:
    from .baseline import compare, markdown_table, plot

    thesis = () if args.no_thesis else args.thesis
    seeds = range(0) if args.no_generated else args.seeds
    if not thesis and not len(seeds):
        raise CliError("--no-thesis and --no-generated leave nothing to compare")
    if args.out is not None:  # checked before minutes of work, not after
        if args.out.exists() and not args.out.is_dir():
            raise CliError(f"--out {args.out} is a file; give a directory")
        existing = [str(args.out / f) for f in COMPARE_FILES.values()
                    if (args.out / f).exists()]
        if existing and not args.force:
            raise CliError(f"{', '.join(existing)} exists; add --force to overwrite")
        try:
            args.out.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise CliError(f"cannot create --out {args.out}: {exc.strerror}") from None
        if not os.access(args.out, os.W_OK):
            raise CliError(f"--out {args.out} is not writable; choose another directory")
    result = compare(thesis, seeds, max_frames=args.max_frames, workers=args.workers,
                     progress=sys.stderr.isatty() or not args.json)
    table = markdown_table(result)
    if args.out is not None:
        # Each file is written to a temporary name and moved into place: an interrupted
        # or failed write leaves the previous report as it was.
        with atomic_write(args.out / COMPARE_FILES["json"]) as fh:
            fh.write(json.dumps(result, indent=1))
        with atomic_write(args.out / COMPARE_FILES["md"]) as fh:
            fh.write(table)
        plot(result, args.out / COMPARE_FILES["png"])
        result["out"] = {k: str(args.out / f) for k, f in COMPARE_FILES.items()}
    if args.json:
        print(json.dumps(result))
    else:
        print(table, end="")
        if args.out is not None:
            print(f"wrote {', '.join(result['out'].values())}")
    return 0
