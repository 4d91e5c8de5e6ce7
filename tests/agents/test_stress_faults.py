"""The stress battery's new faults (latency spike, dropped frames, wet patch, servo
offset) with and without the LIS reset stage, the battery in seconds on cameras of other
frame rates, and the stress command with them through the console script."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.cli_helpers import tfalda
from tfalda_sim.agents import stress
from tfalda_sim.agents.stress import FAULTS, StressRun, run_one
from tfalda_sim.camera import load_camera, save_camera

NEW = ("latency_spike", "frame_drops", "wet_patch", "servo_offset")


def test_the_new_faults_are_in_the_battery() -> None:
    assert set(NEW) <= set(FAULTS)
    assert list(FAULTS)[:9] == ["none", "blackout", "overexposed", "glare", "marking_gap",
                                "lateral_kick", "camera_shake", "obstacle", "fast_curve"]


@pytest.mark.parametrize("fault", NEW)
def test_each_new_fault_runs_with_and_without_the_reset_stage(fault: str) -> None:
    runs = [run_one(10003, fault, stage) for stage in (True, False)]
    assert [r.roi_reset_stage for r in runs] == [True, False]
    assert all(isinstance(r, StressRun) and r.fault == fault for r in runs)
    assert runs[1].roi_resets == 0  # without the stage the LIS never resets


def test_the_wet_patch_changes_nothing_for_the_kinematic_car() -> None:
    wet, dry = run_one(10003, "wet_patch", True), run_one(10003, "none", True)
    assert (wet.on_road, wet.roi_resets) == (dry.on_road, dry.roi_resets)


@pytest.mark.parametrize("rate, steps", [(50.0, 150 + 25 + 150), (30.0, 90 + 15 + 90)],
                         ids=["thesis 50 Hz", "30 Hz"])
def test_the_battery_is_in_seconds_on_any_frame_rate(rate: float, steps: int, tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """A blackout run: 3 s before, the 0.5 s blackout, 3 s after — in that camera's
    frames."""
    camera = save_camera(load_camera("thesis").replace(frame_rate_hz=rate),
                         tmp_path / "camera.yaml")
    counted = []
    step = stress.TfaldaTrackEnv.step

    def counting(env, action):
        counted.append(env._step_count + 1)
        return step(env, action)

    monkeypatch.setattr(stress.TfaldaTrackEnv, "step", counting)
    run = run_one(10003, "blackout", True, camera=str(camera))
    assert run.on_road and counted[-1] == steps


def test_the_stress_command_runs_the_new_faults(tmp_path: Path) -> None:
    run = tfalda("stress", "--seeds", "10003:10004", "--faults", ",".join(NEW), "--workers",
                 "1", "--out", "DIR", "--json", cwd=tmp_path)
    doc = run.json()  # strict JSON: no NaN
    assert [(r["fault"], r["roi_reset_stage"]) for r in doc["summary"]] == [
        (f, stage) for f in NEW for stage in (True, False)]
    assert doc["runs"] == doc["jobs"] == 8 and doc["interrupted"] is False
    out = tmp_path / "DIR"
    report = json.loads((out / "stress.json").read_text())
    assert [r["fault"] for r in report["summary"]][::2] == list(NEW)
    assert report["onset_s"] == 3.0 and report["after_s"] == 3.0
    table = (out / "stress.md").read_text()
    assert all(f"| {f} | on |" in table and f"| {f} | off |" in table for f in NEW)
    assert len((out / "stress.jsonl").read_text().splitlines()) == 8
    assert (out / "stress.png").stat().st_size > 1000


def test_the_stress_command_refuses_an_unknown_fault_in_one_line(tmp_path: Path) -> None:
    run = tfalda("stress", "--faults", "latency_spike,wet", "--out", "DIR", cwd=tmp_path,
                 code=2)
    last = run.err.strip().splitlines()[-1]
    assert "unknown fault(s) wet" in last and "wet_patch" in last and "servo_offset" in last
    assert not (tmp_path / "DIR").exists()
