"""The recorder: a run's steps written as plain MCAP and as a ROS 2 bag read back exactly,
with both readers, on every channel; only the channels with data; published whole or not
at all."""

from __future__ import annotations

import math
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from mcap.reader import make_reader

from tests.tfalda_sim.recording.readback import (
    CAMERA_INFO,
    Readback,
    read_bag,
    read_mcap,
    stamp_ns,
    steps,
)
from tfalda_sim import __version__
from tfalda_sim.fileio import TEMP_PREFIX, remove_stale_temps, temp_path
from tfalda_sim.recording import (
    CAMERA_TOPIC,
    CUSTOM_DATA_KEY,
    RecordedStep,
    Recorder,
    RecordingFormat,
)
from tfalda_sim.recording.channels import CHANNELS

START_NS = 1_700_000_000_123_456_789
"""The runs' start in most tests [ns since the Unix epoch]: stamps to compare exactly."""

ALL_TOPICS = {ch.topic for ch in CHANNELS}
TRUTH_TOPICS = {"/car/pose", "/car/odometry", "/truth/cross_track"}


def target(tmp_path: Path, fmt: RecordingFormat) -> Path:
    return tmp_path / ("run.mcap" if fmt is RecordingFormat.MCAP else "run_bag")


def record(path: Path, fmt: RecordingFormat, run: list[RecordedStep], **kwargs: Any) -> None:
    with Recorder(path, fmt, **{"start_ns": START_NS, **kwargs}) as rec:
        for step in run:
            rec.write(step)
        assert rec.frames == len(run)


def readers(path: Path, fmt: RecordingFormat) -> list[Readback]:
    """Every way the recording is read: an MCAP by ``mcap``; a bag by rosbags and its
    MCAP file by ``mcap`` (the schemas Foxglove sees when it opens that file)."""
    if fmt is RecordingFormat.MCAP:
        return [read_mcap(path)]
    return [read_bag(path), read_mcap(path / f"{path.name}.mcap")]


def leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith(TEMP_PREFIX))


def decode(msg: Any) -> np.ndarray:
    return cv2.imdecode(np.frombuffer(bytes(msg.data), np.uint8), cv2.IMREAD_UNCHANGED)


def yaw_of(q: Any) -> float:
    return 2.0 * math.atan2(q.z, q.w)


def wrapped(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


@pytest.mark.parametrize("fmt", list(RecordingFormat))
def test_a_run_reads_back_exactly_on_every_channel(tmp_path: Path, fmt: RecordingFormat
                                                   ) -> None:
    run = steps(12)
    path = target(tmp_path, fmt)
    record(path, fmt, run, camera_info=CAMERA_INFO, source="oval seed 7")
    assert leftovers(tmp_path) == []
    for back in readers(path, fmt):
        assert set(back.types) == ALL_TOPICS
        assert {t: back.counts[t] for t in ALL_TOPICS} == dict.fromkeys(ALL_TOPICS, len(run))
        assert {t: len(back.messages[t]) for t in ALL_TOPICS} == \
            dict.fromkeys(ALL_TOPICS, len(run))
        assert {back.types[ch.topic] for ch in CHANNELS} >= {
            "sensor_msgs/msg/CompressedImage", "foxglove_msgs/msg/ImageAnnotations",
            "tfalda_msgs/msg/Lanes", "tfalda_msgs/msg/LisState", "nav_msgs/msg/Odometry"}
        for ch in CHANNELS:
            assert back.types[ch.topic] == ch.msgtype
            if back.encodings:
                assert back.encodings[ch.topic] == "ros2msg"
            # Every message of a step is stamped (header and log time) with its time.
            assert back.times[ch.topic] == [START_NS + round(s.t_s * 1e9) for s in run]
        m = back.messages
        for k, step in enumerate(run):
            img = m[CAMERA_TOPIC][k]
            assert img.format == "png" and img.header.frame_id == "camera"
            assert stamp_ns(img.header.stamp) == START_NS + round(step.t_s * 1e9)
            np.testing.assert_array_equal(decode(img), step.frame)
            top = decode(m["/topdown/image/compressed"][k])
            assert top.shape == step.top_view.shape  # JPEG: the picture, not its bytes
            info = m["/camera/camera_info"][k]
            assert (info.width, info.height) == (752, 480)
            assert info.distortion_model == "equidistant"
            np.testing.assert_array_equal(np.reshape(info.k, (3, 3)), CAMERA_INFO.K)
            np.testing.assert_array_equal(info.d, CAMERA_INFO.D)
            lanes = m["/tfalda/lanes"][k]
            np.testing.assert_array_equal(np.reshape(lanes.lanes, (4, 4)), step.lanes)
            np.testing.assert_array_equal(np.asarray(lanes.accepted, bool), step.accepted)
            np.testing.assert_array_equal(np.reshape(lanes.rois, (4, 4)), step.rois)
            np.testing.assert_array_equal(np.reshape(lanes.segments, (-1, 4)), step.segments)
            lis = m["/tfalda/lis"][k]
            assert (lis.fault_counter, lis.roi_reset, lis.state) == \
                (step.fault_counter, step.roi_reset, step.state)
            np.testing.assert_array_equal(np.asarray(lis.replaced, bool), ~step.accepted)
            pose = m["/car/pose"][k]
            assert pose.header.frame_id == "map"
            assert (pose.pose.position.x, pose.pose.position.y) == step.pose[:2]
            assert wrapped(yaw_of(pose.pose.orientation) - step.pose[2]) == \
                pytest.approx(0.0, abs=1e-12)
            odom = m["/car/odometry"][k]
            assert odom.twist.twist.linear.x == step.speed_m_s
            assert odom.pose.pose.position.x == step.pose[0]
            assert m["/truth/cross_track"][k].cross_track_m == step.cross_track_m
    # The keys the frame sources look for to find the camera among the image topics.
    if fmt is RecordingFormat.MCAP:
        assert read_mcap(path).metadata == {
            "camera_topic": CAMERA_TOPIC, "source": "oval seed 7", "version": __version__}
    else:
        assert read_bag(path).metadata == {
            CUSTOM_DATA_KEY: CAMERA_TOPIC, "tfalda_sim.source": "oval seed 7",
            "tfalda_sim.version": __version__}
        assert sorted(p.name for p in path.iterdir()) == ["metadata.yaml", "run_bag.mcap"]


def _points(annotations: Any, rgba: tuple[float, ...]) -> list[np.ndarray]:
    return [np.array([(p.x, p.y) for p in a.points]) for a in annotations.points
            if (a.outline_color.r, a.outline_color.g, a.outline_color.b,
                a.outline_color.a) == rgba]


def test_the_annotations_draw_the_lanes_rois_segments_and_truth(tmp_path: Path) -> None:
    from tfalda_sim.recording import channels as c

    run = steps(4)
    path = tmp_path / "a.mcap"
    record(path, RecordingFormat.MCAP, run)
    back = read_mcap(path)
    for step, ann in zip(run, back.messages["/camera/annotations"], strict=True):
        # Lines at the detector's pixel centres (+0.5 in Foxglove's corner coordinates).
        kept = [row for row, ok in zip(step.lanes, step.accepted, strict=True)
                if ok and np.isfinite(row).all()]
        gone = [row for row, ok in zip(step.lanes, step.accepted, strict=True)
                if not ok and np.isfinite(row).all()]
        for rows, colour in ((kept, c.ACCEPTED_COLOR), (gone, c.REPLACED_COLOR),
                             (list(step.segments), c.SEGMENT_COLOR),
                             (list(step.truth_lanes), c.TRUTH_COLOR)):
            drawn = _points(ann, colour)
            if not rows:
                assert drawn == []
                continue
            (pts,) = drawn
            np.testing.assert_allclose(pts, np.reshape(rows, (-1, 2)) + 0.5)
        rois = _points(ann, c.ROI_COLOR)
        assert len(rois) == sum(1 for _, _, w, h in step.rois if w > 0 and h > 0)
        x, y, w, h = next(r for r in step.rois if r[2] > 0 and r[3] > 0)
        np.testing.assert_array_equal(rois[0], [(x, y), (x + w, y), (x + w, y + h),
                                                (x, y + h)])
        assert all(a.type == 2 for a in ann.points if a.outline_color.b == c.ROI_COLOR[2])
        (text,) = ann.texts
        assert step.state in text.text
        assert {stamp_ns(a.timestamp) for a in [*ann.points, *ann.texts]} == \
            {START_NS + round(step.t_s * 1e9)}


@pytest.mark.parametrize("fmt", list(RecordingFormat))
def test_a_run_without_ground_truth_has_no_truth_or_pose_channels(
        tmp_path: Path, fmt: RecordingFormat) -> None:
    path = target(tmp_path, fmt)
    record(path, fmt, steps(3, truth=False, lis=False, top_view=False))
    for back in readers(path, fmt):
        assert set(back.types) == {CAMERA_TOPIC, "/camera/annotations", "/tfalda/lanes"}
        assert not set(back.types) & TRUTH_TOPICS


def test_a_replay_of_footage_has_the_camera_only(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    path = tmp_path / "f.mcap"
    frames = [rng.integers(0, 256, (48, 64), dtype=np.uint8) for _ in range(3)]
    with Recorder(path, RecordingFormat.MCAP, source="footage.mp4") as rec:
        for k, frame in enumerate(frames):
            rec.write(RecordedStep(t_s=k / 30, frame=frame))
    back = read_mcap(path)
    assert set(back.types) == {CAMERA_TOPIC}
    for frame, img in zip(frames, back.messages[CAMERA_TOPIC], strict=True):
        np.testing.assert_array_equal(decode(img), frame)


def test_a_hough_step_records_segments_and_empty_lane_fields(tmp_path: Path) -> None:
    segs = np.array([[1.0, 2.0, 3.0, 4.0], [5.5, 6.5, 7.5, 8.5]])
    path = tmp_path / "h.mcap"
    with Recorder(path, RecordingFormat.MCAP) as rec:
        rec.write(RecordedStep(t_s=0.0, frame=np.zeros((8, 8), np.uint8), segments=segs))
    (lanes,) = read_mcap(path).messages["/tfalda/lanes"]
    assert list(lanes.lanes) == [] and list(lanes.accepted) == [] and list(lanes.rois) == []
    np.testing.assert_array_equal(np.reshape(lanes.segments, (-1, 4)), segs)


@pytest.mark.parametrize("fmt", list(RecordingFormat))
def test_close_without_keep_leaves_nothing_and_the_old_file_as_it_was(
        tmp_path: Path, fmt: RecordingFormat) -> None:
    path = target(tmp_path, fmt)
    record(path, fmt, steps(2, seed=1))
    before = sorted((p.name, p.read_bytes()) for p in path.parent.rglob("*") if p.is_file())
    rec = Recorder(path, fmt)
    for step in steps(3, seed=2):
        rec.write(step)
    rec.close(keep=False)
    assert sorted((p.name, p.read_bytes()) for p in path.parent.rglob("*")
                  if p.is_file()) == before
    assert leftovers(tmp_path) == []
    fresh = tmp_path / ("fresh.mcap" if fmt is RecordingFormat.MCAP else "fresh")
    with pytest.raises(RuntimeError), Recorder(fresh, fmt) as rec:
        rec.write(steps(1)[0])
        raise RuntimeError("the command failed")
    assert not fresh.exists() and leftovers(tmp_path) == []


@pytest.mark.parametrize("fmt", list(RecordingFormat))
def test_a_finished_recording_replaces_an_old_one(tmp_path: Path, fmt: RecordingFormat
                                                  ) -> None:
    path = target(tmp_path, fmt)
    record(path, fmt, steps(5, seed=1))
    record(path, fmt, steps(2, seed=2))
    for back in readers(path, fmt):
        assert back.counts[CAMERA_TOPIC] == 2
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize("fmt", list(RecordingFormat))
def test_a_run_interrupted_mid_step_keeps_every_whole_step(
        tmp_path: Path, fmt: RecordingFormat) -> None:
    """A Ctrl-C while a step is being written lands after it: closing with keep=True then
    gives a valid recording of every step up to it, each on every channel."""
    run = steps(6)
    path = target(tmp_path, fmt)
    rec = Recorder(path, fmt, camera_info=CAMERA_INFO)
    sink = rec._sink
    assert sink is not None
    writes = 0
    plain = sink.write

    def write_then_ctrl_c(*args: Any) -> None:
        nonlocal writes
        writes += 1
        plain(*args)
        if writes == 3 * len(CHANNELS) + 2:  # inside the fourth step
            signal.raise_signal(signal.SIGINT)

    sink.write = write_then_ctrl_c  # type: ignore[method-assign]
    with pytest.raises(KeyboardInterrupt):
        for step in run:
            rec.write(step)
    assert rec.frames == 4
    rec.close(keep=True)
    for back in readers(path, fmt):
        assert set(back.types) == ALL_TOPICS
        assert set(back.counts.values()) == {4}
        for step, img in zip(run, back.messages[CAMERA_TOPIC], strict=False):
            np.testing.assert_array_equal(decode(img), step.frame)


def test_a_long_run_is_written_in_chunks(tmp_path: Path) -> None:
    """The file is streamed: noise frames of ≈ 360 kB fill a chunk every few steps."""
    path = tmp_path / "long.mcap"
    record(path, RecordingFormat.MCAP, steps(12, top_view=False))
    with open(path, "rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None and len(summary.chunk_indexes) >= 3
    assert {ci.compression for ci in summary.chunk_indexes} == {"zstd"}


def test_steps_must_come_in_time_order_and_keep_one_frame_size(tmp_path: Path) -> None:
    path = tmp_path / "t.mcap"
    a, b = steps(2)
    with Recorder(path, RecordingFormat.MCAP, camera_info=CAMERA_INFO) as rec:
        rec.write(b)
        with pytest.raises(ValueError, match="time order"):
            rec.write(a)
        with pytest.raises(ValueError, match="frame size"):
            rec.write(RecordedStep(t_s=1.0, frame=np.zeros((10, 10), np.uint8)))
        rec.write(RecordedStep(t_s=1.0, frame=a.frame))  # the recorder is still usable
    assert read_mcap(path).counts[CAMERA_TOPIC] == 2
    with pytest.raises(ValueError, match="camera_info"), \
            Recorder(tmp_path / "u.mcap", RecordingFormat.MCAP, camera_info=CAMERA_INFO) as r:
        r.write(RecordedStep(t_s=0.0, frame=np.zeros((10, 10), np.uint8)))
    assert not (tmp_path / "u.mcap").exists()


@pytest.mark.parametrize(("fields", "message"), [
    ({"frame": np.zeros((4, 4), np.float32)}, "uint8"),
    ({"frame": np.zeros((4, 4, 3), np.uint8)}, "shape"),
    ({"t_s": -1.0}, "t_s"),
    ({"t_s": math.nan}, "t_s"),
    ({"lanes": np.zeros((3, 4))}, "lanes"),
    ({"accepted": np.ones(4, bool)}, "needs lanes"),
    ({"rois": np.zeros((4, 4))}, "rois"),
    ({"segments": np.zeros(4)}, "segments"),
    ({"state": "TRACKING"}, "all"),
    ({"speed_m_s": 1.0}, "needs pose"),
    ({"pose": (0.0, math.inf, 0.0)}, "pose"),
    ({"top_view": np.zeros((4, 4), np.uint8)}, "top_view"),
])
def test_a_step_refuses_wrong_fields(fields: dict[str, Any], message: str) -> None:
    kwargs: dict[str, Any] = {"t_s": 0.0, "frame": np.zeros((4, 4), np.uint8), **fields}
    with pytest.raises(ValueError, match=message):
        RecordedStep(**kwargs)


def test_paths_and_formats_are_checked_before_any_file(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"\.mcap"):
        Recorder(tmp_path / "run.bag", RecordingFormat.MCAP)
    with pytest.raises(ValueError, match="compress_frames"):
        Recorder(tmp_path / "run.mcap", RecordingFormat.MCAP, compress_frames="webp")
    folder = tmp_path / "photos"
    folder.mkdir()
    (folder / "holiday.jpg").write_bytes(b"precious")
    with pytest.raises(OSError, match=f"cannot write {folder}: .*not a ROS 2 bag"):
        Recorder(folder, RecordingFormat.ROSBAG)
    assert (folder / "holiday.jpg").read_bytes() == b"precious"
    (tmp_path / "dir.mcap").mkdir()
    with pytest.raises(OSError, match=r"dir\.mcap: a folder is in its place"):
        Recorder(tmp_path / "dir.mcap", RecordingFormat.MCAP)
    (tmp_path / "dir.mcap").rmdir()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["photos"]


def test_jpeg_frames_are_smaller_and_say_so(tmp_path: Path) -> None:
    path = tmp_path / "j.mcap"
    record(path, RecordingFormat.MCAP, steps(2, top_view=False), compress_frames="jpeg")
    img = read_mcap(path).messages[CAMERA_TOPIC][0]
    assert img.format == "jpeg" and decode(img).shape == (480, 752)


def test_a_killed_runs_bag_folder_is_removed_by_the_next(tmp_path: Path) -> None:
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True).stdout.strip()
    name = temp_path(tmp_path).name.replace(f"-{__import__('os').getpid()}.", f"-{dead}.")
    stale = tmp_path / name
    (stale / "run").mkdir(parents=True)
    (stale / "run" / "run.mcap").write_bytes(b"x" * 100)
    mine = temp_path(tmp_path)
    mine.mkdir()  # this process' own: a recording in progress
    assert remove_stale_temps(tmp_path) == [stale]
    assert not stale.exists() and mine.is_dir()


def test_a_recording_starts_at_the_time_it_was_made(tmp_path: Path) -> None:
    """By default the stamps are wall-clock times (Foxglove shows when the run was), and
    the first frame's is not 0, which ROS tools read as "no stamp"."""
    before = time.time_ns()
    path = tmp_path / "now.mcap"
    with Recorder(path, RecordingFormat.MCAP) as rec:
        for step in steps(3, truth=False, top_view=False):
            rec.write(step)
    after = time.time_ns()
    times = read_mcap(path).times[CAMERA_TOPIC]
    assert before <= times[0] <= after
    assert np.diff(times).tolist() == [20_000_000, 20_000_000]


@pytest.mark.parametrize("fmt", list(RecordingFormat))
def test_our_frame_sources_read_a_recording_back_frame_identically(
        tmp_path: Path, fmt: RecordingFormat) -> None:
    """The replay's reader finds the camera among the two image topics by the recording's
    metadata, and gets every frame, time and the camera_info as the run had them."""
    from tfalda_sim.sources.open import open_source

    run = steps(5)
    path = target(tmp_path, fmt)
    record(path, fmt, run, camera_info=CAMERA_INFO)
    source = open_source(path)
    assert source.info.topic == CAMERA_TOPIC
    assert source.info.camera_info is not None
    np.testing.assert_array_equal(source.info.camera_info.K, CAMERA_INFO.K)
    assert not [n for n in source.info.notes if "stamp" in n]
    frames = list(source.frames())
    assert len(frames) == len(run)
    for got, step in zip(frames, run, strict=True):
        np.testing.assert_array_equal(got.image, step.frame)
        assert got.t_s == pytest.approx(step.t_s, abs=1e-9)
