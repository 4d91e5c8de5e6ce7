"""--vehicle and --timing on drive, stress, evaluate-agent, train and limits: refused at the
parser in one line when bad, passed to every env the command makes (its worker processes'
too), and named in the output."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.cli_helpers import tfalda

BLIND = {"camera_latency_s": 1.0}
"""A timing no car keeps its lane with: every observation a second old."""

COMMANDS = {
    "drive": ["drive", "--track", "oval", "--laps", "1"],
    "stress": ["stress", "--seeds", "0:1", "--faults", "none", "--out", "OUT"],
    "evaluate-agent": ["evaluate-agent", "--seeds", "0:1", "--laps", "1", "--out", "OUT.json"],
    "train": ["train", "--timesteps", "64", "--out", "OUT"],
    "limits": ["limits", "--seeds", "0:1", "--laps", "1", "--out", "OUT.json"],
}

BAD = {
    "unknown vehicle": (["--vehicle", "bike"],
                        "argument --vehicle: invalid choice: 'bike' (choose from 'kinematic', "
                        "'dynamic')"),
    "unknown timing": (["--timing", "slow"],
                       "argument --timing: unknown timing 'slow'; use ideal, real-car, randomized "
                       "or a "
                       ".json timing file"),
    "missing file": (["--timing", "none.json"],
                     "argument --timing: timing file none.json: No such file or directory"),
    "not JSON": (["--timing", "text.json"], "argument --timing: timing file text.json is not JSON"),
    "unknown key": (["--timing", "key.json"],
                    "argument --timing: timing file key.json: unknown key 'latency'; use "
                    "camera_latency_s"),
    "negative latency": (["--timing", "negative.json"],
                         "argument --timing: timing file negative.json: Timing.camera_latency_s "
                         "must lie in [0, 1.0] s, got -0.02"),
    "NaN": (["--timing", "nan.json"],
            "argument --timing: timing file nan.json: Timing.actuator_latency_s must be a "
            "finite number, got nan"),
}


def _timing_files(folder: Path) -> None:
    (folder / "text.json").write_text("camera_latency_s = 0.02\n")
    (folder / "key.json").write_text(json.dumps({"latency": 0.02}))
    (folder / "negative.json").write_text(json.dumps({"camera_latency_s": -0.02}))
    (folder / "nan.json").write_text('{"actuator_latency_s": NaN}')
    (folder / "blind.json").write_text(json.dumps(BLIND))


def _refused(argv: list[str], message: str, tmp_path: Path) -> None:
    run = tfalda(*argv, cwd=tmp_path, code=2)
    last = run.err.strip().splitlines()[-1]
    assert last.startswith(f"tfalda-sim {argv[0]}: error: "), str(run)
    assert message in last, str(run)
    assert run.out == "", str(run)
    assert not list(tmp_path.glob("OUT*")), "an output was written"


@pytest.mark.parametrize("case", sorted(BAD))
def test_drive_refuses_a_bad_vehicle_or_timing_in_one_line(case: str, tmp_path: Path) -> None:
    _timing_files(tmp_path)
    extra, message = BAD[case]
    _refused([*COMMANDS["drive"], *extra], message, tmp_path)


@pytest.mark.parametrize("command", sorted(set(COMMANDS) - {"drive"}))
@pytest.mark.parametrize("case", ["unknown vehicle", "missing file", "negative latency"])
def test_every_command_refuses_a_bad_vehicle_or_timing_at_the_parser(
        command: str, case: str, tmp_path: Path) -> None:
    _timing_files(tmp_path)
    extra, message = BAD[case]
    _refused([*COMMANDS[command], *extra], message, tmp_path)


def test_the_vehicle_choices_are_the_envs() -> None:
    from tfalda_sim.agents.command import VEHICLE_CHOICES
    from tfalda_sim.envs.tfalda_track import VEHICLES

    assert VEHICLE_CHOICES == VEHICLES


def test_drive_names_the_vehicle_and_timing_in_its_json_and_table(tmp_path: Path) -> None:
    doc = tfalda("drive", "--track", "oval", "--laps", "1", "--speed", "2", "--vehicle",
                 "dynamic", "--timing", "real-car", "--json", cwd=tmp_path).json()
    assert doc["vehicle"] == "dynamic" and doc["timing"] == "real-car"
    assert doc["laps_completed"] == 1
    default = tfalda("drive", "--track", "oval", "--laps", "1", "--speed", "2", "--json",
                     cwd=tmp_path).json()
    assert default["vehicle"] == "kinematic" and default["timing"] == "ideal"
    # Another car and pipeline: another drive.
    assert doc["mean_abs_cross_track_m"] != default["mean_abs_cross_track_m"]
    _timing_files(tmp_path)
    run = tfalda("drive", "--track", "oval", "--laps", "1", "--speed", "2", "--timing",
                 "blind.json", "--no-recover", cwd=tmp_path, code=1)  # it leaves the road
    assert "kinematic car, blind.json timing" in run.out, str(run)


def test_evaluate_agent_passes_the_timing_to_its_worker_processes(tmp_path: Path) -> None:
    """Two seeds on two workers: with every observation a second old, each run leaves
    the road (with the ideal timing both complete the lap, test_console_scripts)."""
    _timing_files(tmp_path)
    doc = tfalda("evaluate-agent", "--seeds", "10003:10005", "--laps", "1", "--workers", "2",
                 "--timing", "blind.json", "--vehicle", "dynamic", "--json",
                 cwd=tmp_path, code=0).json()
    assert doc["timing"] == "blind.json" and doc["vehicle"] == "dynamic"
    assert [(r["seed"], r["success"], r["ended"]) for r in doc["runs"]] == [
        (10003, False, "departure"), (10004, False, "departure")]


def test_stress_passes_the_timing_to_its_worker_processes(tmp_path: Path) -> None:
    _timing_files(tmp_path)
    doc = tfalda("stress", "--seeds", "10003:10004", "--faults", "none", "--workers", "2",
                 "--timing", "blind.json", "--out", "DIR", "--json", cwd=tmp_path).json()
    assert doc["timing"] == "blind.json" and doc["vehicle"] == "kinematic"
    assert [row["on_road_rate"] for row in doc["summary"]] == [0.0, 0.0]
    report = json.loads((tmp_path / "DIR" / "stress.json").read_text())
    assert report["timing"] == "blind.json"


def test_the_jobs_carry_the_vehicle_and_the_timing_read() -> None:
    """A worker on another host need not have the timing file: the jobs carry it read."""
    from tfalda_sim.agents.evaluate import evaluation_jobs
    from tfalda_sim.agents.stress import battery_jobs
    from tfalda_sim.timing import TIMINGS

    (job,) = evaluation_jobs("pid", None, range(3, 4), 1, (1.5,), "thesis", False,
                             "dynamic", "real-car")
    assert job[-2:] == ("dynamic", TIMINGS["real-car"])
    first = next(battery_jobs(range(3, 4), ["none"], "thesis", "dynamic", "real-car"))
    assert first == (3, "none", True, "thesis", "dynamic", TIMINGS["real-car"])
    # The default car's jobs read as before.
    assert next(battery_jobs(range(3, 4), ["none"])) == (3, "none", True, "thesis")


def test_a_dynamic_car_drives_otherwise_in_a_worker_job() -> None:
    from tfalda_sim.agents.evaluate import run_job
    from tfalda_sim.timing import TIMINGS

    runs = {v: run_job(("pid", None, 10003, 1, 3.0, "thesis", False, v, TIMINGS["ideal"]))
            for v in ("kinematic", "dynamic")}
    assert runs["kinematic"]["steps"] > 0 and runs["dynamic"]["steps"] > 0
    assert runs["kinematic"]["mean_abs_cross_track_m"] != runs["dynamic"][
        "mean_abs_cross_track_m"]


def test_the_training_env_gets_the_vehicle_and_timing() -> None:
    from tfalda_sim.agents.rllib import env_config
    from tfalda_sim.agents.train import env_kwargs

    kwargs = env_kwargs(1.5, vehicle="dynamic", timing="real-car")
    assert kwargs["vehicle"] == "dynamic" and kwargs["timing"] == "real-car"
    cfg = env_config(vehicle="dynamic", timing="real-car")
    assert cfg["vehicle"] == "dynamic" and cfg["timing"] == "real-car"


def test_rllib_ships_a_timing_file_read(tmp_path: Path) -> None:
    """A cluster's nodes need not have the file (as a camera file)."""
    from tfalda_sim.agents.rllib import env_config
    from tfalda_sim.timing import Timing

    (tmp_path / "blind.json").write_text(json.dumps(BLIND))
    cfg = env_config(timing=str(tmp_path / "blind.json"))
    assert cfg["timing"] == Timing(camera_latency_s=1.0)


def test_train_names_the_vehicle_and_timing(tmp_path: Path) -> None:
    pytest.importorskip("stable_baselines3", reason="train needs the rl extra")
    _timing_files(tmp_path)
    doc = tfalda("train", "--timesteps", "64", "--n-envs", "1", "--vehicle", "dynamic",
                 "--timing", "blind.json", "--out", "out/tr", "--json", cwd=tmp_path).json()
    assert doc["vehicle"] == "dynamic" and doc["timing"] == "blind.json"
    assert "--vehicle dynamic --timing blind.json" in doc["command"]
    summary = json.loads((tmp_path / "out" / "tr" / "train.json").read_text())
    assert summary["vehicle"] == "dynamic" and summary["timing"] == "blind.json"
