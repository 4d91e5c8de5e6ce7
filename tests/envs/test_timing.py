"""The pipeline's timing in TfaldaTrack-v0: with k frames of camera latency the
observation at step t is the one computed from step t − k's frame; dropped frames and
jitter keep the newest result; the same seed gives the same rollout; timings are checked
and read from files; the ideal timing changes nothing."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import pytest

from tfalda_sim.envs import TfaldaTrackEnv
from tfalda_sim.timing import TIMINGS, Timing, load_timing, resolve_timing
from tfalda_sim.vehicle import ServoParams

ACTIONS = [np.array([0.25 * np.sin(0.2 * t)], np.float32) for t in range(60)]


def _observations(env: TfaldaTrackEnv, seed: int = 0) -> tuple[list[np.ndarray], list[dict]]:
    obs, info = env.reset(seed=seed, options={"track": "oval", "start": (1.0, -0.2, 0.0)})
    out, infos = [obs], [info]
    for action in ACTIONS:
        obs, _, terminated, _, info = env.step(action)
        assert not terminated
        out.append(obs)
        infos.append(info)
    return out, infos


@pytest.mark.parametrize("frames", [1, 2, 3])
def test_k_frames_of_camera_latency_give_step_t_minus_k_s_observation(frames: int) -> None:
    ideal, _ = _observations(TfaldaTrackEnv())
    late, infos = _observations(TfaldaTrackEnv(timing=Timing(camera_latency_s=frames / 50)))
    for t in range(len(late)):
        assert np.array_equal(late[t], ideal[max(t - frames, 0)]), t
    assert sum(info["roi_reset"] for info in infos) == 0


def test_the_ideal_timing_is_todays_loop_bit_for_bit() -> None:
    a, _ = _observations(TfaldaTrackEnv())
    b, _ = _observations(TfaldaTrackEnv(timing="ideal"))
    c, _ = _observations(TfaldaTrackEnv(timing=Timing(servo=ServoParams())))
    assert all(np.array_equal(x, y) and np.array_equal(x, z) for x, y, z in zip(a, b, c,
                                                                              strict=True))


def test_jitter_delivers_frames_in_order_and_drops_repeat_the_last_by_seed() -> None:
    """With jitter every observation is one of the ideal loop's (the detector sees every
    frame), never newer than the latency allows and never older than the one before;
    dropped frames (the detector never sees them) repeat the last observation. The same
    seed gives the same rollout, another seed another."""
    ideal, _ = _observations(TfaldaTrackEnv(), seed=5)
    jittery, _ = _observations(TfaldaTrackEnv(timing=Timing(camera_latency_s=0.02,
                                                            jitter_s=0.03)), seed=5)
    index = [next(k for k, o in enumerate(ideal) if np.array_equal(o, seen))
             for seen in jittery]
    assert all(k <= max(t - 1, 0) for t, k in enumerate(index))
    assert index == sorted(index)
    assert len(set(index)) < len(index) and any(t - k >= 2 for t, k in enumerate(index))
    timing = Timing(camera_latency_s=0.02, frame_drop_probability=0.3, jitter_s=0.03)
    a, _ = _observations(TfaldaTrackEnv(timing=timing), seed=5)
    b, _ = _observations(TfaldaTrackEnv(timing=timing), seed=5)
    c, _ = _observations(TfaldaTrackEnv(timing=timing), seed=6)
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    assert not all(np.array_equal(x, y) for x, y in zip(a, c, strict=True))
    repeats = sum(np.array_equal(x, y) for x, y in itertools.pairwise(a))
    assert 5 <= repeats < len(a) - 10


def test_presets_and_timing_files(tmp_path: Path) -> None:
    real = TIMINGS["real-car"]
    assert real.camera_latency_s == pytest.approx(0.04) and real.servo.lag_s > 0
    assert resolve_timing("real-car") is real and resolve_timing(real) is real
    path = tmp_path / "car.json"
    path.write_text(json.dumps({"camera_latency_s": 0.06, "servo": {"lag_s": 0.03}}))
    assert load_timing(path) == Timing(camera_latency_s=0.06, servo=ServoParams(lag_s=0.03))
    assert resolve_timing(str(path)) == load_timing(path)


@pytest.mark.parametrize(("doc", "message"), [
    ({"camera_latency": 0.04}, "unknown key 'camera_latency'"),
    ({"camera_latency_s": -0.01}, r"camera_latency_s must lie in \[0, 1.0\] s, got -0.01"),
    ({"jitter_s": "fast"}, "jitter_s must be a finite number"),
    ({"frame_drop_probability": 1.0}, r"frame_drop_probability must lie in \[0, 1\)"),
    ({"servo": {"lag": 0.1}}, "servo must be an object with lag_s, dead_band_rad"),
    ([1, 2], "must hold one JSON object"),
])
def test_bad_timing_files_are_refused_naming_the_problem(doc: object, message: str,
                                                         tmp_path: Path) -> None:
    path = tmp_path / "t.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=message):
        load_timing(path)
    path.write_text("{not json")
    with pytest.raises(ValueError, match="is not JSON"):
        load_timing(path)
    with pytest.raises(ValueError, match=r"no such file|No such file"):
        load_timing(tmp_path / "missing.json")


def test_bad_timing_values_are_refused() -> None:
    with pytest.raises(ValueError, match="actuator_latency_s"):
        Timing(actuator_latency_s=float("nan"))
    with pytest.raises(ValueError, match="timing must be one of"):
        TfaldaTrackEnv(timing="laggy")


def test_odometry_noise_is_seeded_and_only_on_speed_and_steering() -> None:
    noisy = Timing(speed_noise_m_s=0.05, steer_noise_rad=0.01)
    ideal, _ = _observations(TfaldaTrackEnv(), seed=2)
    a, _ = _observations(TfaldaTrackEnv(timing=noisy), seed=2)
    b, _ = _observations(TfaldaTrackEnv(timing=noisy), seed=2)
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    for x, y in zip(a, ideal, strict=True):
        assert np.array_equal(x[:-2], y[:-2])  # the lanes: as without noise
        assert not np.array_equal(x[-2:], y[-2:])  # speed, steering: noisy


def test_domain_randomization_draws_a_timing_per_episode_by_seed() -> None:
    from tfalda_sim.rendering import DomainRandomization
    from tfalda_sim.timing import TimingRandomization

    def timings(seed: int) -> list[Timing]:
        env = TfaldaTrackEnv(domain_randomization=True, randomization=DomainRandomization(
            timing=TimingRandomization()))
        env.reset(seed=seed)
        out = [env.episode_timing]
        for _ in range(3):
            env.reset()
            out.append(env.episode_timing)
        return out

    a = timings(3)
    assert a == timings(3) and a != timings(4)
    assert len(set(a)) == 4 and all(t.camera_latency_s <= 0.06 for t in a)
    assert all(t.servo.lag_s > 0 for t in a)
    # Without timing ranges the randomised env keeps its timing and draws as before.
    env = TfaldaTrackEnv(domain_randomization=True, timing="real-car")
    env.reset(seed=3)
    assert env.episode_timing is TIMINGS["real-car"]
    with pytest.raises(ValueError, match="camera_latency_s must be a range"):
        TimingRandomization(camera_latency_s=(0.05, 0.01))


def test_a_randomized_timing_is_drawn_per_episode_without_domain_randomization() -> None:
    env = TfaldaTrackEnv(timing="randomized")
    env.reset(seed=1)
    first = env.episode_timing
    env.reset()
    assert env.episode_timing != first and isinstance(first, Timing)
    again = TfaldaTrackEnv(timing="randomized")
    again.reset(seed=1)
    assert again.episode_timing == first
    # The photometric effects stay the env's: only the timing is drawn.
    assert env.domain_randomization is False
