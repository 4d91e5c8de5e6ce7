"""tfalda-sim drive / stress / train on the command line."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import Any

import cv2
import pytest

from tfalda_sim import agents
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
    for key in ("mean_abs_cross_track_m", "departures", "roi_resets", "agent", "speed_m_s"):
        assert key in summary
    cap = cv2.VideoCapture(str(video))
    assert cap.isOpened() and cap.get(cv2.CAP_PROP_FRAME_COUNT) == summary["steps"]
    # The camera video holds the bare grey frames, for the replay.
    from tfalda_sim.sources import open_source

    first = next(open_source(camera).frames()).image
    assert open_source(camera).info.frame_count == summary["steps"]
    from tfalda_sim.video import is_grey

    assert first.ndim == 2 or is_grey(first)  # the bare grey frames
    assert summary["camera_video"] == str(camera)
    # An existing video is not overwritten without --force.
    code, _, err = run(capsys, "drive", "--track", "oval", "--video", str(video))
    assert code == 2 and "--force" in err


def test_drive_takes_a_track_file_as_the_track_it_holds(tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]
                                                        ) -> None:
    """A file written by `track generate` drives as its seed, and loses its cartons unless
    --obstacles, as a seed's track does. With them the car runs into one and is put back
    just past it (it was put back inside it: an internal error)."""
    path = tmp_path / "six.json"
    assert run(capsys, "track", "generate", "--seed", "6", "--out", str(path))[0] == 0
    lanes = {o["lane"] for o in json.loads(path.read_text())["obstacles"]}
    assert "right" in lanes, "seed 6 has a carton in the right lane: the test needs one"
    figures = {}
    for track in ("6", str(path)):
        for obstacles in ([], ["--obstacles"]):
            code, out, err = run(capsys, "drive", "--track", track, "--laps", "1", "--json",
                                 *obstacles)
            assert code == 0, err
            doc = json.loads(out)
            assert doc["track"] == ("seed-6" if track == "6" else "six.json")
            assert doc["laps_completed"] == 1 and doc["departures"] == (1 if obstacles else 0)
            figures[track, bool(obstacles)] = {k: doc[k] for k in (
                "lap_times_s", "steps", "departures", "roi_resets", "mean_abs_cross_track_m")}
    for obstacles in (False, True):
        assert figures["6", obstacles] == figures[str(path), obstacles]
    assert figures["6", True] != figures["6", False]  # the carton is in the way


def test_a_ctrl_c_while_the_car_is_put_back_counts_the_episode_once(
        monkeypatch: pytest.MonkeyPatch) -> None:
    from tfalda_sim.agents import drive as driving
    from tfalda_sim.agents.pid import LanePid
    from tfalda_sim.tracks import generate

    left_at: list[float] = []

    def interrupted(env: Any, track: Any, s_m: float, *args: Any) -> None:
        left_at.append(s_m)
        raise KeyboardInterrupt

    monkeypatch.setattr(driving, "_recover", interrupted)
    result = driving.drive(LanePid(), generate(6), laps=1)  # it runs into the carton
    assert result.ended == "interrupted" and result.departures == 1 and len(left_at) == 1
    assert result.distance_m == pytest.approx(left_at[0], abs=0.05)  # not twice that


def test_a_carton_on_the_start_line_of_a_track_file_is_a_clear_error(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The rules let a track file put a carton where the drive starts; the generator never
    does. With --obstacles: one line naming it and the fix, not an internal error."""
    path = tmp_path / "blocked.json"
    assert run(capsys, "track", "generate", "--seed", "6", "--out", str(path))[0] == 0
    doc = json.loads(path.read_text())
    doc["obstacles"][0].update(s_m=0.0, lane="right", offset_m=0.0)
    path.write_text(json.dumps(doc))
    code, _, err = run(capsys, "drive", "--track", str(path), "--laps", "1", "--obstacles")
    assert code == 2, err
    assert f"--track {path}: the start pose" in err and "inside a carton" in err, err
    assert "leave out --obstacles" in err and "internal error" not in err
    code, out, err = run(capsys, "drive", "--track", str(path), "--laps", "1", "--json")
    assert code == 0 and json.loads(out)["laps_completed"] == 1, err


@pytest.mark.parametrize("argv, message", [
    (["drive", "--track", "straight"], "not a loop"),
    (["drive", "--track", "broken.json"], "broken.json: no such file"),
    (["drive", "--track", "nowhere"], "neither a named track"),
    (["drive", "--agent", "ppo", "--policy", "missing.zip"], "no policy file"),
    (["drive", "--speed", "9"], "top speed"),
    (["stress", "--faults", "blackout,bogus"], "unknown fault(s) bogus"),
])
def test_bad_arguments_exit_2_naming_the_problem(capsys: pytest.CaptureFixture[str],
                                                 argv: list[str], message: str) -> None:
    code, _, err = run(capsys, *argv)
    assert code == 2 and message in err


def _policy_file(kind: str, folder: Path) -> Path:
    """A --policy file the agents cannot drive with."""
    path = folder / f"{kind}.zip"
    if kind == "not-a-zip":
        path.write_bytes(b"PK? no")
    elif kind == "another-zip":
        with zipfile.ZipFile(path, "w") as z:
            z.writestr("data", '{"x": 1}')
    elif kind == "cut-short":
        whole = (Path(agents.__file__).parent / "policies" / "ppo.zip").read_bytes()
        path.write_bytes(whole[:len(whole) // 2])
    elif kind == "stable-baselines3":  # pickles: refused without --trust-policy
        from tests.agents.policy_files import COMMITTED, sb3_save
        from tfalda_sim.agents.policy_file import load_policy

        sb3_save(load_policy(COMMITTED), path)
    else:  # a PPO policy of another env (Pendulum: observations of 3, not the lane vector)
        import gymnasium as gym
        from stable_baselines3 import PPO

        from tfalda_sim.agents.policy_file import save_policy

        model = PPO("MlpPolicy", gym.make("Pendulum-v1"), n_steps=64, batch_size=64,
                    device="cpu")
        save_policy(model.policy, path)
    return path


@pytest.mark.parametrize("kind, message", [
    ("not-a-zip", "is not a PPO policy saved by `tfalda-sim train` (the file"),
    ("another-zip", "is not a PPO policy saved by `tfalda-sim train` ("),
    ("cut-short", "is not a PPO policy saved by `tfalda-sim train` ("),
    ("stable-baselines3", "holds pickled Python objects (':serialized:' entries in its data, "
                          "as stable-baselines3 saves them), and a policy file with pickled "
                          "objects can run code when loaded; add --trust-policy"),
    ("pendulum", "is a policy for observations of shape (3,) and actions of shape (1,); the "
                 "env gives (42,)"),
])
@pytest.mark.parametrize("command", [["drive", "--laps", "1", "--video", "out.mp4"],
                                     ["evaluate-agent", "--seeds", "0:1", "--out", "out.json"]])
def test_a_policy_file_the_agents_cannot_use_is_named_with_why(
        kind: str, message: str, command: list[str], tmp_path: Path,
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """Corrupt, foreign or another env's policies: exit 2 and one line, not an internal
    error at the first step; nothing written."""
    path = _policy_file(kind, tmp_path)
    monkeypatch.chdir(tmp_path)
    code, _, err = run(capsys, *command, "--agent", "ppo", "--policy", str(path))
    assert code == 2, err
    assert f"{path} {message}" in err, err
    assert "internal error" not in err and not (tmp_path / command[-1]).exists()


def test_stress_writes_json_markdown_and_png(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(capsys, "stress", "--seeds", "10003:10004", "--faults", "blackout",
                       "--workers", "1", "--out", str(tmp_path), "--json")
    assert code == 0
    rows = json.loads(out)["summary"]
    assert [(r["fault"], r["roi_reset_stage"]) for r in rows] == [("blackout", True),
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


def _forbid(monkeypatch: pytest.MonkeyPatch, target: str) -> None:
    def refuse(*_: object, **__: object) -> None:
        raise AssertionError(f"{target} ran although the command should have stopped first")
    monkeypatch.setattr(target, refuse)


def test_stress_keeps_an_earlier_report_without_force(tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch,
                                                      capsys: pytest.CaptureFixture[str]
                                                      ) -> None:
    """The issue's reproduction: stress overwrote stress.md/.json/.png in --out."""
    (tmp_path / "stress.md").write_text("earlier")
    _forbid(monkeypatch, "tfalda_sim.agents.stress.run_job")
    code, _, err = run(capsys, "stress", "--seeds", "10003:10004", "--out", str(tmp_path))
    assert code == 2 and "stress.md exists; add --force" in err
    assert (tmp_path / "stress.md").read_text() == "earlier"
    # --out naming a file is refused before the computation, not after it.
    (tmp_path / "existing.json").write_text("{}")
    code, _, err = run(capsys, "stress", "--out", str(tmp_path / "existing.json"))
    assert code == 2 and "is a file; give a folder" in err


def test_stress_force_replaces_the_report(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "stress.md").write_text("earlier")
    code, out, _ = run(capsys, "stress", "--seeds", "10003:10004", "--faults", "lateral_kick",
                       "--workers", "1", "--out", str(tmp_path), "--force", "--json")
    assert code == 0 and json.loads(out)["runs"] == 2
    assert "lateral_kick" in (tmp_path / "stress.md").read_text()
    runs = (tmp_path / "stress.jsonl").read_text().splitlines()
    assert [json.loads(r)["roi_reset_stage"] for r in runs] == [True, False]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["stress.json", "stress.jsonl",
                                                          "stress.md", "stress.png"]


def test_a_failed_training_leaves_no_out_folder(tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    """The issue's reproduction created --out's tb/PPO_1 before failing."""
    pytest.importorskip("stable_baselines3")

    def broken(*_: object, **__: object) -> None:
        raise RuntimeError("the learner failed")

    monkeypatch.setattr("stable_baselines3.PPO.learn", broken)
    monkeypatch.setenv("TFALDA_SIM_DEBUG", "")
    code, _, err = run(capsys, "train", "--timesteps", "100", "--n-envs", "1", "--out",
                       str(tmp_path / "out" / "tr"), "--json")
    assert code == 1 and "internal error: RuntimeError: the learner failed" in err
    assert not (tmp_path / "out").exists()  # not even the parent folder
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("argv, message", [
    (["train", "--n-envs", "100000"], "expected an integer from 1 to 64"),
    (["train", "--seed", "-3"], "seed must be an integer"),
    (["evaluate-agent", "--speeds", "1.5,9"], "the car's top speed"),
    (["evaluate-agent", "--laps", "0"], "expected an integer from 1"),
    (["drive", "--laps", "1" + "0" * 400], "expected an integer"),
])
def test_agent_commands_refuse_bad_values_at_the_parser(capsys: pytest.CaptureFixture[str],
                                                        argv: list[str], message: str) -> None:
    code, _, err = run(capsys, *argv)
    assert code == 2 and "usage:" in err and message in err
