"""Runs recorded with ``--mcap`` / ``--rosbag``: ``drive``'s MCAP read back with the
``mcap`` library has every channel, one message per frame driven, and replays through
TFALDA + LIS to exactly the live run's lanes; the ROS 2 bag holds the same; ``stress``
and ``evaluate`` record their one drive; a late pipeline records each processed frame
once; bad combinations are refused before any work."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from tests.cli_helpers import tfalda
from tfalda_sim.agents.drive import drive, make_agent
from tfalda_sim.perception import DetectorConfig, TfaldaDetector
from tfalda_sim.sources import open_source
from tfalda_sim.tracks import load_named

CHANNELS = {"/camera/image/compressed": "sensor_msgs/msg/CompressedImage",
            "/camera/camera_info": "sensor_msgs/msg/CameraInfo",
            "/camera/annotations": "foxglove_msgs/msg/ImageAnnotations",
            "/tfalda/lanes": "tfalda_msgs/msg/Lanes",
            "/tfalda/lis": "tfalda_msgs/msg/LisState",
            "/car/pose": "geometry_msgs/msg/PoseStamped",
            "/car/odometry": "nav_msgs/msg/Odometry",
            "/truth/cross_track": "tfalda_msgs/msg/CrossTrack",
            "/topdown/image/compressed": "sensor_msgs/msg/CompressedImage"}
"""Every channel of a drive's recording and its schema."""

STEPS = 40


def read_mcap(path: Path) -> tuple[Counter[str], dict[str, str], list[np.ndarray]]:
    """Message counts and schema names by topic, and the live lanes of /tfalda/lanes."""
    counts: Counter[str] = Counter()
    schemas: dict[str, str] = {}
    lanes = []
    with open(path, "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        for schema, channel, _, msg in reader.iter_decoded_messages():
            counts[channel.topic] += 1
            schemas[channel.topic] = schema.name
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            if channel.topic == "/tfalda/lanes":
                lanes.append(np.array(msg.lanes, np.float64).reshape(4, 4))
    return counts, schemas, lanes


def replayed_lanes(path: Path) -> list[np.ndarray]:
    det = TfaldaDetector(DetectorConfig.thesis())
    return [det.process(f.image).lanes for f in open_source(path).frames()]


def test_a_drive_recorded_to_mcap_replays_to_the_live_lanes(tmp_path: Path) -> None:
    track = load_named("oval")
    path = tmp_path / "drive.mcap"
    result = drive(make_agent("pid"), track, laps=1, max_steps=STEPS, mcap=path)
    assert result.steps == STEPS
    counts, schemas, live = read_mcap(path)
    assert schemas == CHANNELS
    # the start's frame and one a step: what the detector processed
    assert set(counts.values()) == {STEPS + 1}
    again = replayed_lanes(path)
    assert len(again) == len(live) == STEPS + 1
    for a, b in zip(again, live, strict=True):
        np.testing.assert_array_equal(a, b)  # NaN rows equal too
    run = tfalda("replay", path, "--detector", "tfalda", "--per-frame", "p.jsonl", "--json",
                 cwd=tmp_path).json()
    assert run["kind"] == "mcap" and run["topic"] == "/camera/image/compressed"
    assert run["frames"] == STEPS + 1 and run["recording_rate_hz"] == pytest.approx(50.0)
    assert run["rate_note"] is None
    lines = [json.loads(x) for x in (tmp_path / "p.jsonl").read_text().splitlines()]
    for line, lanes in zip(lines, live, strict=True):
        want = [None if not np.isfinite(r).all() else [round(float(v), 3) for v in r]
                for r in lanes]
        assert line["lanes"] == want


def test_the_rosbag_holds_the_same_and_replays_the_same(tmp_path: Path) -> None:
    track = load_named("oval")
    bag = tmp_path / "drive"
    drive(make_agent("pid"), track, laps=1, max_steps=12, rosbag=bag)
    mcap = tmp_path / "drive.mcap"
    drive(make_agent("pid"), track, laps=1, max_steps=12, mcap=mcap)
    assert (bag / "metadata.yaml").is_file()
    source = open_source(bag)
    assert source.info.kind == "ros2-mcap" and source.info.frame_count == 13
    assert source.info.camera_info is not None
    for a, b in zip(source.frames(), open_source(mcap).frames(), strict=True):
        np.testing.assert_array_equal(a.image, b.image)
    np.testing.assert_array_equal(np.array(replayed_lanes(bag)), np.array(replayed_lanes(mcap)))


def test_a_late_pipeline_records_each_processed_frame_once(tmp_path: Path) -> None:
    path = tmp_path / "late.mcap"
    drive(make_agent("pid"), load_named("oval"), laps=1, max_steps=STEPS, mcap=path,
          timing="real-car")
    counts, _, live = read_mcap(path)
    # 2 frames late: the last results have not arrived; none is recorded twice
    assert counts["/camera/image/compressed"] < STEPS + 1
    frames = list(open_source(path).frames())
    assert len({f.image.tobytes() for f in frames}) == len(frames)
    for a, b in zip(replayed_lanes(path), live, strict=True):
        np.testing.assert_array_equal(a, b)


def test_drive_stress_and_evaluate_record_through_the_console_script(tmp_path: Path) -> None:
    d = tfalda("drive", "--track", "oval", "--laps", "1", "--mcap", "d.mcap", "--json",
               cwd=tmp_path).json()
    assert d["recording"] == "d.mcap"
    counts, _, _ = read_mcap(tmp_path / "d.mcap")
    assert counts["/camera/image/compressed"] == d["steps"] + 1
    st = tfalda("stress", "--seeds", "10000:10001", "--faults", "blackout", "--out", "st",
                "--rosbag", "st-bag", "--json", cwd=tmp_path).json()
    assert st["recording"] == "st-bag" and (tmp_path / "st-bag" / "metadata.yaml").is_file()
    assert open_source(tmp_path / "st-bag").info.frame_count > 100
    ev = tfalda("evaluate", "--scenario", "straight", "--mcap", "ev.mcap", "--json",
                cwd=tmp_path).json()
    counts, schemas, _ = read_mcap(tmp_path / "ev.mcap")
    assert counts["/camera/image/compressed"] == ev["summary"]["with LIS"]["frames"]
    assert "/truth/cross_track" in schemas and "/topdown/image/compressed" not in schemas


@pytest.mark.parametrize("argv, says", [
    (["stress", "--seeds", "10000:10002", "--faults", "blackout", "--mcap", "s.mcap"],
     "records one drive"),
    (["stress", "--seeds", "10000:10001", "--mcap", "s.mcap"], "records one drive"),
    (["drive", "--mcap", "a.mcap", "--rosbag", "b"], "not allowed with argument"),
    (["drive", "--mcap", "a.mp4"], ".mcap"),
    (["evaluate", "--scenario", "random", "--seeds", "0:3", "--mcap", "e.mcap"],
     "single seed"),
])
def test_recording_options_refused_before_any_work(argv: list[str], says: str,
                                                   tmp_path: Path) -> None:
    run = tfalda(*argv, cwd=tmp_path, code=2)
    assert says in run.err
    assert not [p for p in tmp_path.iterdir()]


def test_an_existing_recording_needs_force(tmp_path: Path) -> None:
    (tmp_path / "d.mcap").write_bytes(b"old")
    run = tfalda("drive", "--track", "oval", "--laps", "1", "--mcap", "d.mcap", cwd=tmp_path,
                 code=2)
    assert "--force" in run.err and (tmp_path / "d.mcap").read_bytes() == b"old"


def test_ctrl_c_keeps_the_recording_of_the_frames_driven(tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch
                                                         ) -> None:
    from tfalda_sim.envs import TfaldaTrackEnv

    real, steps = TfaldaTrackEnv.step, []

    def ctrl_c_at_eleventh(self: TfaldaTrackEnv, action: np.ndarray):
        steps.append(1)
        if len(steps) == 11:
            raise KeyboardInterrupt
        return real(self, action)

    monkeypatch.setattr(TfaldaTrackEnv, "step", ctrl_c_at_eleventh)
    path = tmp_path / "cut.mcap"
    old = tmp_path / "old.mcap"
    result = drive(make_agent("pid"), load_named("oval"), laps=1, mcap=path)
    assert result.ended == "interrupted" and result.steps == 10
    counts, _, _ = read_mcap(path)
    assert counts["/camera/image/compressed"] == 11  # the start and the ten steps
    # an error (not a Ctrl-C) leaves an existing recording as it was
    old.write_bytes(b"keep")
    steps.clear()
    monkeypatch.setattr(TfaldaTrackEnv, "step", lambda self, a: (_ for _ in ()).throw(
        RuntimeError("a broken env")))
    with pytest.raises(RuntimeError, match="broken"):
        drive(make_agent("pid"), load_named("oval"), laps=1, mcap=old)
    assert old.read_bytes() == b"keep"
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []
