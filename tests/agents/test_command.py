"""tfalda-sim drive / stress / train on the command line."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import pytest

from tfalda_sim.cli import main


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_drive_reports_laps_as_json_and_writes_a_video(tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    video = tmp_path / "drive.mp4"
    camera = tmp_path / "camera.mp4"
    code, out, _ = run(capsys, "drive", "--track", "oval", "--laps", "1", "--video", str(video),
                       "--camera-video", str(camera), "--json")
    assert code == 0
    summary = json.loads(out)
    assert summary["laps_completed"] == 1 and len(summary["lap_times_s"]) == 1
    for key in ("mean_abs_cross_track_m", "departures", "lis_resets", "agent", "speed_m_s"):
        assert key in summary
    cap = cv2.VideoCapture(str(video))
    assert cap.isOpened() and cap.get(cv2.CAP_PROP_FRAME_COUNT) == summary["steps"]
    # The camera video holds the bare grey frames, for the replay.
    from tfalda_sim.video import VideoReader

    reader = VideoReader(camera)
    assert reader.info.frame_count == summary["steps"] and not reader.info.colour
    assert summary["camera_video"] == str(camera)
    # An existing video is not overwritten without --force.
    code, _, err = run(capsys, "drive", "--track", "oval", "--video", str(video))
    assert code == 2 and "--force" in err


@pytest.mark.parametrize("argv, message", [
    (["drive", "--track", "straight"], "not a loop"),
    (["drive", "--track", "nowhere"], "neither a named track"),
    (["drive", "--agent", "ppo", "--policy", "missing.zip"], "no policy file"),
    (["drive", "--speed", "9"], "top speed"),
    (["stress", "--faults", "blackout,bogus"], "unknown fault(s) bogus"),
])
def test_bad_arguments_exit_2_naming_the_problem(capsys: pytest.CaptureFixture[str],
                                                 argv: list[str], message: str) -> None:
    code, _, err = run(capsys, *argv)
    assert code == 2 and message in err


def test_stress_writes_json_markdown_and_png(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(capsys, "stress", "--seeds", "10003:10004", "--faults", "blackout",
                       "--workers", "1", "--out", str(tmp_path), "--json")
    assert code == 0
    rows = json.loads(out)["summary"]
    assert [(r["fault"], r["lis_reset_stage"]) for r in rows] == [("blackout", True),
                                                                 ("blackout", False)]
    for name in ("stress.json", "stress.md", "stress.png"):
        assert (tmp_path / name).stat().st_size > 100


def test_train_refuses_to_replace_a_policy(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "policy.zip").write_bytes(b"x")
    code, _, err = run(capsys, "train", "--out", str(tmp_path), "--timesteps", "10")
    assert code == 2 and "exists" in err
    assert (tmp_path / "policy.zip").read_bytes() == b"x"


def test_the_committed_ppo_policy_drives_a_lap(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(capsys, "drive", "--agent", "ppo", "--track", "oval", "--laps", "1",
                       "--no-recover", "--json")
    summary = json.loads(out)
    assert code == 0 and summary["laps_completed"] == 1 and summary["departures"] == 0
