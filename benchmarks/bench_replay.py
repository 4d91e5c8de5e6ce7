"""Benchmark of replaying recordings: frames/s of ``replay`` (TFALDA + LIS and the Hough
baseline) and of reading alone, per source kind, against an MP4 of the same frames; and
what recording a drive as MCAP costs a step.

    python benchmarks/bench_replay.py [--frames 300] [--rounds 5] [--drive-steps 300] [--json]

The simulator's camera frames of a PID drive on the oval (``env.camera_frame()``, grey
752×480, noise included) are rendered once and written, untimed, to a temporary folder as
each kind of recording ``tfalda_sim.sources.open_source`` reads (``KINDS``): an MP4 video
(H.264, as ``drive --camera-video`` writes it: the only input of the previous replay, the
same-run reference every rate is divided by), a folder of PNGs, a ROS 1 bag and a ROS 2
bag (sqlite3) of ``sensor_msgs/Image`` mono8, a ROS 2 bag in MCAP storage of
``CompressedImage`` PNG, and a plain MCAP file of Image mono8 (zstd chunks). Each round
then gives every kind three turns: a read-only pass (``frames()`` + ``to_grey``, the
opening clocked apart), and ``replay(path, Detector.TFALDA)`` and ``replay(path,
Detector.HOUGH)`` over all its frames, clocked as the command reports them
(``frames_per_s``: from the first frame to the last, opening not included); then two
drives of the oval with the PID, ``drive(..., max_steps=…)`` without and with ``mcap=``
(the recorder's file finished and in place inside the drive's clock). A figure is the
median over the rounds, a ratio the median of its rounds' ratios (the two turns of a
round are seconds apart: a busy host's bursts stay out of most). One core, OpenCV on
one thread (the MP4's decoder threads share the core). Prints a table, or one JSON object
with ``--json``.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import statistics
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
from _machine import REPO, machine, pin_to_one_core
from tqdm import tqdm

from tfalda_sim.agents.drive import drive, make_agent
from tfalda_sim.agents.pid import LanePid
from tfalda_sim.envs import TfaldaTrackEnv
from tfalda_sim.perception.params import IMAGE_HEIGHT_PX, IMAGE_WIDTH_PX
from tfalda_sim.replay import Detector, replay
from tfalda_sim.sources import FrameRange, open_source, to_grey
from tfalda_sim.tracks import load_named
from tfalda_sim.video import VideoWriter

TRACK = "oval"
"""The track the frames are rendered on and the recording drives go round."""

MP4 = "MP4 video (reference)"
KIND_NAMES: tuple[str, ...] = (
    MP4,
    "image folder, PNG",
    "ROS 1 bag, Image mono8",
    "ROS 2 bag (sqlite3), Image mono8",
    "ROS 2 bag (MCAP storage), CompressedImage PNG",
    "MCAP file, Image mono8",
)
"""The source kinds, in the table's order; the first is the reference."""

MODES: tuple[str, ...] = ("read", "tfalda", "hough")
"""A kind's turns in a round: the read-only pass, then a replay through each detector."""

SIZE = (IMAGE_WIDTH_PX, IMAGE_HEIGHT_PX)
"""The camera's frame size [px] (what ``to_grey`` converts to)."""

FIRST_STAMP_NS = 1_000_000_000
"""The recordings' first ``header.stamp`` [ns] (0 reads as no stamp)."""

MAX_FRAMES = 3000
"""``--frames`` at most: the recordings take ≈ 1.3 MB a frame on disk (the raw ones
0.36 MB each, PNGs of the camera's noisy frames ≈ 0.17 MB)."""

MAX_DRIVE_STEPS = 20_000
"""``--drive-steps`` at most: an MCAP of a drive grows ≈ 0.18 MB a step."""

WARMUP_FRAMES = 20
"""Frames each detector replays, and each kind reads, before anything is timed (numba
compiles, caches fill); steps of each warm-up drive."""


def _recordings() -> ModuleType:
    """The tests' recording writers (``tests/tfalda_sim/sources/recordings.py``), imported
    from their file: every kind of recording from frames, as teams' cameras write them."""
    path = REPO / "tests" / "tfalda_sim" / "sources" / "recordings.py"
    spec = importlib.util.spec_from_file_location("bench_replay_recordings", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def camera_frames(count: int) -> tuple[list[np.ndarray], float]:
    """``count`` camera frames of a PID drive on ``TRACK`` from its start (grey, noise
    included; a departure starts a new episode), and the camera's frame rate [Hz]."""
    env = TfaldaTrackEnv(track=TRACK)
    try:
        agent = LanePid(camera=env.camera)
        obs, _ = env.reset(seed=0)
        agent.reset()
        frames = []
        while len(frames) < count:
            obs, _, terminated, _, _ = env.step(agent.act(obs))
            frames.append(env.camera_frame())
            if terminated:
                obs, _ = env.reset()
                agent.reset()
        return frames, env.camera.frame_rate_hz
    finally:
        env.close()


def write_kinds(folder: Path, frames: Sequence[np.ndarray], rate_hz: float
                ) -> dict[str, Path]:
    """``frames`` written as every kind of ``KIND_NAMES`` in ``folder``: name → path."""
    rec = _recordings()
    stamps = [FIRST_STAMP_NS + round(k * 1e9 / rate_hz) for k in range(len(frames))]
    paths = {name: folder / file for name, file in zip(KIND_NAMES, (
        "run.mp4", "png", "run.bag", "ros2-sqlite3", "ros2-mcap", "run.mcap"), strict=True)}
    with VideoWriter(paths[MP4], rate_hz) as video:
        for frame in frames:
            video.write(frame)
    names = iter(KIND_NAMES[1:])
    rec.write_image_folder(paths[next(names)], frames)
    rec.write_ros1_bag(paths[next(names)], frames, stamps)
    rec.write_ros2_bag(paths[next(names)], frames, stamps, storage="sqlite3")
    rec.write_ros2_bag(paths[next(names)], frames, stamps, storage="mcap", compressed="png")
    rec.write_mcap(paths[next(names)], frames, stamps)
    return paths


def size_bytes(path: Path) -> int:
    """A file's size, or a folder's files' (a bag, an image folder)."""
    if path.is_dir():
        return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())
    return path.stat().st_size


def read_pass(path: Path) -> tuple[float, int, float]:
    """Open ``path`` and read every frame to the camera's grey size, no detector: (the
    opening [s], frames, the pass [s])."""
    t0 = time.perf_counter()
    source = open_source(path)
    t1 = time.perf_counter()
    n = 0
    for item in source.frames():
        to_grey(item.image, SIZE)
        n += 1
    return t1 - t0, n, time.perf_counter() - t1


def replay_pass(path: Path, detector: Detector) -> dict[str, Any]:
    """One ``replay`` of every frame of ``path`` through ``detector``: its summary."""
    return replay(path, detector, loops=1)


def drive_pass(steps: int, mcap: Path | None) -> tuple[float, int]:
    """A PID drive of ``steps`` steps on ``TRACK`` (recorded to ``mcap`` if given): its
    wall time [s] as ``drive`` clocks it, the recorder's closing included, and its steps."""
    result = drive(make_agent("pid"), load_named(TRACK), laps=1_000_000, max_steps=steps,
                   mcap=mcap)
    return result.wall_time_s, result.steps


def per_round(counts: list[int], seconds: list[float]) -> list[float]:
    """A turn's rate in each round: its frames (or steps) over its time."""
    return [n / s for n, s in zip(counts, seconds, strict=True)]


def median_ratio(these: list[float], references: list[float]) -> float:
    """The median over the rounds of a rate over the reference's rate in the same round
    (turns seconds apart: each ratio compares neighbours in time, which a busy host's
    bursts mostly slow alike)."""
    return statistics.median(a / b for a, b in zip(these, references, strict=True))


def run(frames: int, rounds: int, drive_steps: int, quiet: bool) -> dict[str, Any]:
    pin_to_one_core()
    with tempfile.TemporaryDirectory(prefix="bench_replay-") as tmp:
        folder = Path(tmp)
        images, rate_hz = camera_frames(frames)
        paths = write_kinds(folder, images, rate_hz)
        del images
        mcap = folder / "drive.mcap"
        # Warm-up, untimed: the detectors' kernels, each reader, both drives.
        for path in paths.values():
            source = open_source(path, frames=FrameRange(0, min(WARMUP_FRAMES, frames)))
            for item in source.frames():
                to_grey(item.image, SIZE)
        for detector in Detector:
            replay(paths[MP4], detector, max_frames=min(WARMUP_FRAMES, frames))
        for recording in (None, mcap):
            drive_pass(min(WARMUP_FRAMES, drive_steps), recording)

        opening: dict[str, list[float]] = {name: [] for name in paths}
        counts: dict[tuple[str, str], list[int]] = {(name, mode): [] for name in paths
                                                    for mode in MODES}
        clocks: dict[tuple[str, str], list[float]] = {key: [] for key in counts}
        detector_ms: dict[tuple[str, str], list[float]] = {}
        detections: dict[tuple[str, str], float] = {}
        drives: dict[str, list[float]] = {"without": [], "with_mcap": []}
        drive_counts: dict[str, list[int]] = {"without": [], "with_mcap": []}
        turns: list[tuple[str, Callable[[], None]]] = []

        def read_turn(name: str) -> None:
            open_s, n, s = read_pass(paths[name])
            _every_frame(name, "read", n)
            opening[name].append(open_s)
            counts[name, "read"].append(n)
            clocks[name, "read"].append(s)

        def replay_turn(name: str, detector: Detector) -> None:
            summary = replay_pass(paths[name], detector)
            key = (name, detector.value)
            n = summary["frames"]
            _every_frame(*key, n)
            counts[key].append(n)
            clocks[key].append(n / summary["frames_per_s"])
            detector_ms.setdefault(key, []).append(summary["detector_ms_median"])
            detections[key] = summary["detections_per_frame"]  # the same every round

        def _every_frame(name: str, mode: str, n: int) -> None:
            if n != frames:
                raise RuntimeError(f"{name}, {mode}: {n} frames of the {frames} written")

        def drive_turn(key: str, recording: Path | None) -> None:
            wall, steps = drive_pass(drive_steps, recording)
            drives[key].append(wall)
            drive_counts[key].append(steps)

        for name in paths:
            turns.append((f"{name}: read", lambda name=name: read_turn(name)))
            for detector in Detector:
                turns.append((f"{name}: {detector.value}",
                              lambda name=name, detector=detector: replay_turn(name, detector)))
        turns.append(("drive", lambda: drive_turn("without", None)))
        turns.append(("drive --mcap", lambda: drive_turn("with_mcap", mcap)))
        with tqdm(total=rounds * len(turns), desc="replay turns", disable=quiet,
                  file=sys.stderr) as bar:
            for _ in range(rounds):
                for label, turn in turns:
                    bar.set_postfix_str(label, refresh=False)
                    turn()
                    bar.update()
        recorded = open_source(mcap).info.frame_count or 0
        mcap_bytes = mcap.stat().st_size
        kinds_info = {name: open_source(path).info for name, path in paths.items()}
        sizes = {name: size_bytes(path) for name, path in paths.items()}

    rates = {key: per_round(counts[key], clocks[key]) for key in counts}
    kinds: dict[str, Any] = {}
    for name in paths:
        info = kinds_info[name]
        entry: dict[str, Any] = {
            "source_kind": info.kind, "encoding": info.encoding,
            "mb_per_frame": sizes[name] / 1e6 / frames,
            "open_ms": 1000 * statistics.median(opening[name])}
        for mode in MODES:
            figures: dict[str, Any] = {
                "frames_per_s": statistics.median(rates[name, mode]),
                "ratio_to_mp4": median_ratio(rates[name, mode], rates[MP4, mode])}
            if mode != "read":
                figures["detector_ms_median"] = statistics.median(detector_ms[name, mode])
                figures["detections_per_frame"] = detections[name, mode]
            entry[mode] = figures
        kinds[name] = entry
    steps_per_s = {key: per_round(drive_counts[key], drives[key]) for key in drives}
    recording: dict[str, Any] = {"track": TRACK, "drive_steps": drive_steps}
    for key, rate in steps_per_s.items():
        median = statistics.median(rate)
        recording[key] = {"ms_per_step": 1000 / median, "steps_per_s": median}
    recording |= {
        # a step's cost: the rate without over the rate with, round by round
        "cost_ratio": median_ratio(steps_per_s["without"], steps_per_s["with_mcap"]),
        "frames_recorded": recorded,
        "mb_per_frame": mcap_bytes / 1e6 / recorded if recorded else None}
    return {"machine": machine(), "frames": frames, "rounds": rounds,
            "frame_size_px": list(SIZE), "track": TRACK, "reference": MP4,
            "kinds": kinds, "recording": recording}


def table(result: dict[str, Any]) -> str:
    """``run``'s result as the printed table: the machine, a row per source kind (MB a
    frame, opening, then frames/s and × the MP4's of reading alone and of each detector's
    replay), then the recording drive's cost."""
    m = result["machine"]
    lines = [f"machine: {m['cores']} cores of {m['cpu']} ({m['simd']}; pinned to one, "
             f"OpenCV threads {m['opencv_threads']}), Python {m['python']}; "
             f"{result['frames']} frames of {result['frame_size_px'][0]}×"
             f"{result['frame_size_px'][1]} px; medians of {result['rounds']} "
             f"round{'s' if result['rounds'] != 1 else ''}"]
    width = 1 + max(map(len, result["kinds"]))
    head = f"{'source kind':<{width}}{'MB/frame':>9}{'open ms':>9}"
    for mode in MODES:
        head += f"{mode + ' f/s':>12}{'× MP4':>7}"
    lines.append(head)
    for name, k in result["kinds"].items():
        row = f"{name:<{width}}{k['mb_per_frame']:>9.3f}{k['open_ms']:>9.1f}"
        for mode in MODES:
            row += f"{k[mode]['frames_per_s']:>12.0f}{k[mode]['ratio_to_mp4']:>6.2f}×"
        lines.append(row)
    r = result["recording"]
    lines.append(f"drive on {r['track']}, {r['drive_steps']} steps a drive: "
                 f"{r['without']['ms_per_step']:.3f} ms a step, with --mcap "
                 f"{r['with_mcap']['ms_per_step']:.3f} ms: {r['cost_ratio']:.2f}×; the MCAP "
                 f"{r['mb_per_frame']:.3f} MB a frame ({r['frames_recorded']} frames)")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=300,
                        help="frames of every recording (the replays' length)")
    parser.add_argument("--rounds", type=int, default=5,
                        help="rounds of turns (every kind, mode and drive once a round)")
    parser.add_argument("--drive-steps", type=int, default=300,
                        help="steps of each drive, with and without --mcap")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    for option, value, high in (("--frames", args.frames, MAX_FRAMES),
                                ("--rounds", args.rounds, 1000),
                                ("--drive-steps", args.drive_steps, MAX_DRIVE_STEPS)):
        if value < 1:
            parser.error(f"{option} must be ≥ 1")
        if value > high:
            parser.error(f"{option} must be ≤ {high}")
    result = run(args.frames, args.rounds, args.drive_steps, quiet=args.json)
    if args.json:
        print(json.dumps(result))
    else:
        print(table(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
