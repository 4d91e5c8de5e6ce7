"""Trajectories, the thesis' scenarios and the scenario runner."""

from __future__ import annotations

import json
import pickle
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from tfalda_sim.evaluation import (
    LOW_CONFIDENCE,
    WITH_LIS,
    WITHOUT_LIS,
    RunResult,
    Scenario,
    ScenarioKind,
    Trajectory,
    generated_scenario,
    run_scenario,
    thesis_scenario,
)
from tfalda_sim.evaluation.scenarios import THESIS_SPEED_M_S
from tfalda_sim.perception import DetectorConfig
from tfalda_sim.rendering import Effects, Renderer
from tfalda_sim.tracks import load_named

CONFIGS = {WITH_LIS: DetectorConfig.thesis(), WITHOUT_LIS: DetectorConfig.without_lis()}


@pytest.fixture(scope="module")
def renderer() -> Renderer:
    return Renderer()


@pytest.fixture(scope="module")
def straight_runs(renderer: Renderer) -> dict[str, RunResult]:
    return run_scenario(thesis_scenario(ScenarioKind.STRAIGHT), CONFIGS, renderer=renderer)


def test_ideal_line_lies_on_the_right_lane_centre() -> None:
    track = load_named("oval")
    traj = Trajectory.along_lane(track, n_frames=200, speed_m_s=2.0, s_start_m=0.3)
    for k in range(0, 200, 17):
        loc = track.locate(*traj.poses[k, :2])
        assert loc.lateral_m == pytest.approx(-0.2, abs=1e-6)
    # the speed is the car's, along its lane (outside a curve: longer than the centre)
    steps = np.hypot(*np.diff(traj.poses[:, :2], axis=0).T)
    assert steps == pytest.approx(np.full(199, 2.0 / 50), rel=1e-3)
    assert np.diff(traj.times_s) == pytest.approx(np.full(199, 0.02))


def test_stride_two_takes_every_second_camera_frame() -> None:
    track = load_named("straight")
    t1 = Trajectory.along_lane(track, n_frames=20, speed_m_s=8.3, stride=1)
    t2 = Trajectory.along_lane(track, n_frames=10, speed_m_s=8.3, stride=2)
    assert np.allclose(t2.poses, t1.poses[::2]) and np.allclose(t2.times_s, t1.times_s[::2])


def test_trajectory_refuses_to_run_off_an_open_track_or_the_road() -> None:
    track = load_named("straight")
    with pytest.raises(ValueError, match="beyond the open track"):
        Trajectory.along_lane(track, n_frames=1000, speed_m_s=4.0)
    with pytest.raises(ValueError, match="off the road"):
        Trajectory.along_lane(track, n_frames=5, speed_m_s=1.0, lateral_m=0.5)
    with pytest.raises(ValueError, match="speed_m_s"):
        Trajectory.along_lane(track, n_frames=5, speed_m_s=float("nan"))


def test_recorded_trajectory_round_trips_and_bad_files_are_named(tmp_path: Path) -> None:
    traj = Trajectory.along_lane(load_named("oval"), n_frames=30, speed_m_s=1.5)
    traj.save(tmp_path / "t.json")
    back = Trajectory.load(tmp_path / "t.json")
    for name in ("poses", "times_s", "speeds_m_s", "s_m"):
        assert np.array_equal(getattr(back, name), getattr(traj, name))
    doc = json.loads((tmp_path / "t.json").read_text())
    doc["frames"][3]["speed"] = 1.0
    (tmp_path / "bad.json").write_text(json.dumps(doc))
    with pytest.raises(ValueError, match="frame 3 must have exactly"):
        Trajectory.load(tmp_path / "bad.json")
    (tmp_path / "junk.json").write_text("{not json")
    with pytest.raises(ValueError, match="cannot read trajectory"):
        Trajectory.load(tmp_path / "junk.json")
    doc = json.loads((tmp_path / "t.json").read_text())
    doc["frames"][1]["t_s"] = 0.0
    (tmp_path / "time.json").write_text(json.dumps(doc))
    with pytest.raises(ValueError, match="increase strictly"):
        Trajectory.load(tmp_path / "time.json")


def test_thesis_scenarios_have_the_thesis_frame_numbers() -> None:
    straight = thesis_scenario(ScenarioKind.STRAIGHT)
    curve = thesis_scenario(ScenarioKind.CURVE)
    track = thesis_scenario(ScenarioKind.TRACK)
    assert list(straight.seqs) == list(range(80))
    assert list(curve.seqs) == list(range(80, 161))
    assert list(track.seqs) == list(range(183))
    # the curve drive is the track drive's frames 80–160 (section 4.2.2)
    assert np.allclose(curve.trajectory.poses, track.trajectory.poses[80:161])
    # the car drives 80 frames through the 180° left curve (section 4.2.3's frames
    # 81–160, seen one metre ahead), straight before and after
    yaw = np.unwrap(track.trajectory.poses[:, 2])
    turning = np.diff(yaw) > 1e-9
    assert 79 <= turning.sum() <= 81
    assert yaw[-1] - yaw[0] == pytest.approx(np.pi)
    assert np.all(np.diff(yaw) > -1e-12)  # a left curve only
    steps = np.hypot(*np.diff(track.trajectory.poses[:, :2], axis=0).T)
    assert steps == pytest.approx(np.full(182, THESIS_SPEED_M_S / 50), rel=1e-3)
    with pytest.raises(ValueError, match="beyond the open track"):
        thesis_scenario(ScenarioKind.TRACK, speed_m_s=8.3)  # 30 km/h every frame: too far


def test_generated_scenarios_drop_the_cartons_and_keep_the_geometry() -> None:
    sc = generated_scenario(5, max_frames=40)
    assert sc.track.obstacles == () and sc.seed == 5 and len(sc.trajectory) == 40
    from tfalda_sim.tracks import generate

    assert sc.track.segments == generate(5).segments
    full = generated_scenario(5)
    # one lap of the right lane: after the last frame the next two steps close the loop
    gap = np.hypot(*(full.trajectory.poses[-1, :2] - full.trajectory.poses[0, :2]))
    step = THESIS_SPEED_M_S / 50
    assert step - 1e-6 < gap <= 2 * step + 1e-6


def test_runs_are_deterministic_and_shaped(renderer: Renderer,
                                           straight_runs: dict[str, RunResult]) -> None:
    again = run_scenario(thesis_scenario(ScenarioKind.STRAIGHT), CONFIGS, renderer=renderer)
    for label in CONFIGS:
        a, b = straight_runs[label], again[label]
        for name in ("lanes", "hit_rates", "accuracy", "rois", "roi_reset", "fault_count"):
            assert np.array_equal(getattr(a, name), getattr(b, name), equal_nan=True), name
        assert a.lanes.shape == (80, 4, 4) and a.hit_rates.shape == (80, 4)
        assert list(a.seq) == list(range(80))
    pickle.loads(pickle.dumps(straight_runs))


def test_summary_figures_follow_from_the_frames(straight_runs: dict[str, RunResult]) -> None:
    for run in straight_runs.values():
        s = run.summary()
        conf = run.hit_rates.mean(axis=1)
        assert s["mean_confidence"] == pytest.approx(conf.mean())
        assert s["min_confidence"] == pytest.approx(conf.min())
        assert s["frames_below_0_75"] == int((conf < LOW_CONFIDENCE).sum())
        assert s["roi_resets"] == int(run.roi_reset.sum())
        assert s["per_roi_false_negatives"] == run.false_negative.sum(axis=0).tolist()
    # the straight drive: both runs keep the lanes on the markings (thesis figure 4.2)
    assert straight_runs[WITH_LIS].summary()["mean_confidence"] > 0.95
    assert straight_runs[WITHOUT_LIS].summary()["roi_resets"] == 0


def test_a_blacked_out_drive_fails_the_metric_and_resets_the_lis(renderer: Renderer) -> None:
    dark = replace(thesis_scenario(ScenarioKind.STRAIGHT), effects=Effects(gain=0.0))
    runs = run_scenario(dark, {WITH_LIS: DetectorConfig.thesis()}, renderer=renderer)
    s = runs[WITH_LIS].summary()
    assert s["mean_confidence"] < 0.5
    assert s["roi_resets"] >= 1  # lanes on nothing: the fault counter passes its limit


def test_frame_hook_sees_every_frame(renderer: Renderer) -> None:
    seen = []
    sc = Scenario("short", load_named("straight"),
                  Trajectory.along_lane(load_named("straight"), n_frames=5, speed_m_s=1.0))
    run_scenario(sc, CONFIGS, renderer=renderer,
                 on_frame=lambda seq, frame, truth, obs: seen.append((seq, frame.shape,
                                                                       sorted(obs))))
    assert seen == [(k, (480, 752), sorted(CONFIGS)) for k in range(5)]


def test_runner_rejects_empty_configs_and_bad_epsilon(renderer: Renderer) -> None:
    sc = thesis_scenario(ScenarioKind.STRAIGHT)
    with pytest.raises(ValueError, match="configs is empty"):
        run_scenario(sc, {}, renderer=renderer)
    with pytest.raises(ValueError, match="epsilon_px"):
        run_scenario(sc, CONFIGS, renderer=renderer, epsilon_px=float("nan"))
