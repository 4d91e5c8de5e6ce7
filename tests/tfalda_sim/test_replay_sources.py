"""``replay`` over every frame source: rendered camera frames written as a ROS 1 bag, a
ROS 2 bag (sqlite3 and MCAP storage), a plain MCAP file and an image folder replay through
both detectors to exactly the detections of the frames fed to the detectors directly;
``--per-frame`` lines; the recording's and the processing frame rate; the recording's
bad inputs through the console script."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from tests.cli_helpers import tfalda
from tests.tfalda_sim.sources.recordings import (
    write_image_folder,
    write_mcap,
    write_ros1_bag,
    write_ros2_bag,
)
from tfalda_sim.cli import main
from tfalda_sim.perception import DetectorConfig, HoughDetector, TfaldaDetector
from tfalda_sim.replay import Detector, HoughPreset, replay
from tfalda_sim.replay.per_frame import lanes_record, segments_record
from tfalda_sim.sources import FrameRange

FRAMES = 8
RATE_HZ = 25.0
"""The recordings' frame rate (half the thesis camera's 50 frames/s) [1/s]."""
T0_NS = 1_700_000_000_000_000_000
"""The recordings' first time stamp (an epoch time, as a car's clock gives) [ns]."""


@pytest.fixture(scope="module")
def frames() -> list[np.ndarray]:
    """Camera frames of the simulator driving the oval's straight into its curve."""
    from tfalda_sim.envs import TfaldaTrackEnv

    env = TfaldaTrackEnv(track="oval")
    env.reset(seed=0, options={"start": (2.0, -0.2, 0.05)})
    out = [env.camera_frame()]
    for _ in range(FRAMES - 1):
        env.step(np.array([0.2], np.float32))
        out.append(env.camera_frame())
    return out


def stamps(n: int = FRAMES) -> list[int]:
    return [T0_NS + round(k * 1e9 / RATE_HZ) for k in range(n)]


WRITERS: dict[str, Callable[[Path, list[np.ndarray]], Path]] = {
    "ros1": lambda d, f: write_ros1_bag(d / "run.bag", f, stamps()),
    "ros2-sqlite3": lambda d, f: write_ros2_bag(d / "run", f, stamps(), storage="sqlite3"),
    "ros2-mcap": lambda d, f: write_ros2_bag(d / "run", f, stamps(), storage="mcap",
                                             compressed="png"),
    "mcap": lambda d, f: write_mcap(d / "run.mcap", f, stamps(), encoding="bgr8"),
    "images": lambda d, f: write_image_folder(d / "frames", f)[0].parent,
}


def direct(frames: list[np.ndarray], detector: Detector) -> list[dict]:
    """The per-frame records of the frames fed to the detector directly."""
    if detector is Detector.TFALDA:
        det = TfaldaDetector(DetectorConfig.thesis())
        return [lanes_record(k, 0, k / RATE_HZ, det.process(f)) for k, f in enumerate(frames)]
    hough = HoughDetector(HoughPreset.SIMULATOR.config())
    return [segments_record(k, 0, k / RATE_HZ, hough.detect(f)) for k, f in enumerate(frames)]


@pytest.mark.parametrize("kind", list(WRITERS))
def test_every_source_replays_to_the_detections_of_its_frames(
        kind: str, frames: list[np.ndarray], tmp_path: Path) -> None:
    source = WRITERS[kind](tmp_path, frames)
    for detector in Detector:
        per_frame = tmp_path / f"{detector.value}.jsonl"
        result = replay(source, detector, per_frame=per_frame,
                        rate_hz=RATE_HZ if kind == "images" else None)
        assert result["kind"] == kind and result["frames"] == FRAMES
        assert result["recording_rate_hz"] == pytest.approx(RATE_HZ)
        lines = [json.loads(line) for line in per_frame.read_text().splitlines()]
        assert lines == direct(frames, detector)
        assert any(line.get("lanes") or line.get("segments") for line in lines)


def test_per_frame_lines_follow_the_loops_and_a_range(frames: list[np.ndarray],
                                                      tmp_path: Path) -> None:
    bag = write_ros2_bag(tmp_path / "run", frames, stamps(), storage="mcap")
    out = tmp_path / "p.jsonl"
    result = replay(bag, Detector.TFALDA, loops=2, per_frame=out,
                    frames=FrameRange(2, 6))
    lines = [json.loads(line) for line in out.read_text().splitlines()]
    assert result["frames"] == 8 and result["loops_completed"] == 2
    assert [(d["frame"], d["loop"]) for d in lines] == [(k, lp) for lp in (0, 1)
                                                         for k in range(2, 6)]
    # t_s: the recording's own time from its first frame, not the range's
    assert [d["t_s"] for d in lines[:4]] == pytest.approx([k / RATE_HZ for k in range(2, 6)])
    keys = {"frame", "loop", "t_s", "lanes", "accepted", "fault_counter", "roi_reset", "state"}
    assert all(set(d) == keys and len(d["lanes"]) == 4 and len(d["accepted"]) == 4
               for d in lines)


def test_a_recording_at_another_rate_than_the_profile_is_said(frames: list[np.ndarray],
                                                              tmp_path: Path) -> None:
    bag = write_ros1_bag(tmp_path / "run.bag", frames, stamps())
    result = tfalda("replay", str(bag), "--detector", "tfalda", "--json", cwd=tmp_path).json()
    assert result["recording_rate_hz"] == pytest.approx(RATE_HZ)
    assert result["camera_rate_hz"] == 50.0 and "25 frames/s" in result["rate_note"]
    assert result["frames_per_s"] > 0
    text = tfalda("replay", str(bag), "--detector", "hough", cwd=tmp_path)
    assert text.code == 0
    assert "recorded at 25 frames/s" in text.out and "processed at" in text.out
    assert "note: the recording runs at 25 frames/s, the camera profile at 50" in text.out
    same = write_ros1_bag(tmp_path / "fifty.bag", frames,
                          [T0_NS + k * 20_000_000 for k in range(FRAMES)])
    assert tfalda("replay", str(same), "--detector", "tfalda", "--json", cwd=tmp_path).json()[
        "rate_note"] is None


def test_the_console_script_replays_a_bag_topic_to_per_frame_lines(
        frames: list[np.ndarray], tmp_path: Path) -> None:
    bag = write_ros2_bag(tmp_path / "run", frames, stamps(), storage="sqlite3",
                         extra_topics=["/other/image_raw"])
    out = tmp_path / "p.jsonl"
    run = tfalda("replay", str(bag), "--detector", "hough", "--per-frame", str(out),
                 cwd=tmp_path, code=2)
    assert run.code == 2 and "--topic" in run.err and "/other/image_raw" in run.err
    assert not out.exists()
    ok = tfalda("replay", str(bag), "--detector", "hough", "--topic", "/other/image_raw",
                "--frames", "1:4", "--per-frame", str(out), "--json", cwd=tmp_path).json()
    assert ok["topic"] == "/other/image_raw" and ok["frames"] == 3
    assert [json.loads(x)["frame"] for x in out.read_text().splitlines()] == [1, 2, 3]
    again = tfalda("replay", str(bag), "--detector", "hough", "--topic", "/other/image_raw",
                   "--per-frame", str(out), cwd=tmp_path, code=2)
    assert again.code == 2 and "--force" in again.err


BAD = {
    "truncated bag": lambda d, f: _cut(write_ros1_bag(d / "run.bag", f, stamps())),
    "corrupt mcap": lambda d, f: _garbage(d / "x.mcap", b"\x89MCAP0\r\n" + b"\x00" * 64),
    "unknown storage": lambda d, f: _storage(write_ros2_bag(d / "run", f, stamps())),
    "missing topic": lambda d, f: write_mcap(d / "run.mcap", f, stamps()),
    "unsupported encoding": lambda d, f: write_mcap(d / "run.mcap", f, stamps(),
                                                    raw=_yuv(f)),
    "empty topic": lambda d, f: write_ros1_bag(d / "run.bag", [], []),
    # header stamps going back while the messages arrive in order
    "time stamps going back": lambda d, f: write_mcap(
        d / "run.mcap", f, [*stamps()[:4], stamps()[1], *stamps()[5:]], log_times_ns=stamps()),
    "a folder with no images": lambda d, f: _empty(d / "none"),
}


def _yuv(frames: list[np.ndarray]) -> dict[int, bytes]:
    """Every frame as a serialized Image claiming an encoding nobody decodes here."""
    from dataclasses import replace

    from tests.tfalda_sim.sources.recordings import IMAGE, ROS2_STORE, image_message

    out = {}
    for k, f in enumerate(frames):
        _, msg = image_message(ROS2_STORE, f, stamps()[k], encoding="mono8")
        out[k] = bytes(ROS2_STORE.serialize_cdr(replace(msg, encoding="yuv422"), IMAGE))
    return out


def _cut(path: Path) -> Path:
    data = path.read_bytes()
    path.write_bytes(data[:len(data) // 2])
    return path


def _garbage(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


def _storage(folder: Path) -> Path:
    meta = folder / "metadata.yaml"
    text = meta.read_text()
    meta.write_text(text.replace("storage_identifier: sqlite3", "storage_identifier: foo"))
    return folder


def _empty(folder: Path) -> Path:
    folder.mkdir()
    (folder / "notes.txt").write_text("no frames here")
    return folder


@pytest.mark.parametrize("case", list(BAD))
def test_bad_recordings_get_one_clear_line_and_leave_outputs_alone(
        case: str, frames: list[np.ndarray], tmp_path: Path) -> None:
    source = BAD[case](tmp_path, frames)
    out = tmp_path / "p.jsonl"
    out.write_text("keep me\n")
    extra = ["--topic", "/nowhere"] if case == "missing topic" else []
    run = tfalda("replay", str(source), "--detector", "tfalda", "--per-frame", str(out),
                 "--force", *extra, cwd=tmp_path, code=2)
    errors = [ln for ln in run.err.splitlines() if ln.startswith("error: ")]
    # one line (after the progress bar of the frames read before a damaged one)
    assert len(errors) == 1 and run.err.rstrip().splitlines()[-1] == errors[0]
    assert out.read_text() == "keep me\n"


def test_frames_of_a_changing_size_are_converted_and_said(frames: list[np.ndarray],
                                                         tmp_path: Path) -> None:
    import cv2

    mixed = [f if k % 2 == 0 else cv2.resize(f, (376, 240)) for k, f in enumerate(frames)]
    bag = write_mcap(tmp_path / "run.mcap", mixed, stamps())
    doc = tfalda("replay", str(bag), "--detector", "tfalda", "--json", cwd=tmp_path).json()
    assert doc["frames"] == FRAMES
    assert any("376×240" in c for c in doc["conversions"])


def test_ctrl_c_keeps_the_per_frame_lines_of_the_finished_frames(
        frames: list[np.ndarray], tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    from tfalda_sim.replay import loop

    bag = write_mcap(tmp_path / "run.mcap", frames, stamps())
    real, calls = loop._frame_step, []

    def ctrl_c_at_fifth(*args: object, **kw: object):
        calls.append(1)
        if len(calls) == 5:
            raise KeyboardInterrupt
        return real(*args, **kw)

    monkeypatch.setattr(loop, "_frame_step", ctrl_c_at_fifth)
    out = tmp_path / "p.jsonl"
    assert main(["replay", str(bag), "--detector", "tfalda", "--per-frame", str(out)]) == 130
    assert [json.loads(x)["frame"] for x in out.read_text().splitlines()] == [0, 1, 2, 3]
    capsys.readouterr()


@pytest.mark.parametrize("option", ["--mcap", "--rosbag"])
def test_a_replay_recorded_replays_to_the_same_lanes(option: str, frames: list[np.ndarray],
                                                     tmp_path: Path) -> None:
    bag = write_ros1_bag(tmp_path / "run.bag", frames, stamps())
    out = "again.mcap" if option == "--mcap" else "again"
    first = tfalda("replay", bag, "--detector", "tfalda", "--loops", "2", option, out,
                   "--per-frame", "a.jsonl", "--json", cwd=tmp_path).json()
    assert first["recording"] == out
    second = tfalda("replay", out, "--detector", "tfalda", "--per-frame", "b.jsonl", "--json",
                    cwd=tmp_path).json()
    assert second["frames"] == 2 * FRAMES
    # our recordings carry the camera's calibration: its own profile says nothing, another
    # is said, with what to do
    assert second["camera_info_note"] is None
    other = tfalda("replay", out, "--detector", "tfalda", "--camera", "reference-car",
                   "--json", cwd=tmp_path).json()
    assert "is not the camera profile's" in other["camera_info_note"]
    assert second["recording_rate_hz"] == pytest.approx(RATE_HZ)
    a = [json.loads(x) for x in (tmp_path / "a.jsonl").read_text().splitlines()]
    b = [json.loads(x) for x in (tmp_path / "b.jsonl").read_text().splitlines()]
    assert [x["lanes"] for x in a] == [x["lanes"] for x in b]
    assert [x["t_s"] for x in b] == pytest.approx([k / RATE_HZ for k in range(2 * FRAMES)])
