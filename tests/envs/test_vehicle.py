"""TfaldaTrack-v0 with the dynamic car and the real car's timing: check_env in every mode and
through make_vec, same-seed rollouts, pickling, bad values refused; the kinematic car
stays the default, bit for bit."""

from __future__ import annotations

import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import tfalda_sim  # noqa: F401
from tfalda_sim.agents.pid import LanePid
from tfalda_sim.dynamics import DynamicsParams
from tfalda_sim.envs import TfaldaTrackEnv
from tfalda_sim.timing import Timing
from tfalda_sim.vehicle import REAL_SERVO

MODES = ("lanes", "image", "dict")


@pytest.mark.parametrize("mode", MODES)
def test_check_env_with_the_dynamic_car_and_the_real_cars_timing(mode: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gym.make("TfaldaTrack-v0", observation=mode, vehicle="dynamic",
                       timing="real-car", render_mode="rgb_array")
        check_env(env.unwrapped)
        env.close()


def _rollout(env: gym.Env, seed: int, steps: int = 120) -> list[np.ndarray]:
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    out = [obs]
    for _ in range(steps):
        obs, reward, terminated, truncated, info = env.step(
            rng.uniform(-1, 1, (1,)).astype(np.float32))
        out += [obs, np.float64(reward), np.array([info["speed_m_s"], info["steer_rad"]])]
        if terminated or truncated:
            obs, _ = env.reset()
            out.append(obs)
    return out


def test_same_seed_same_rollout_and_the_env_pickles() -> None:
    make = lambda: TfaldaTrackEnv(vehicle="dynamic", timing="real-car")  # noqa: E731
    a, b = _rollout(make(), 5), _rollout(make(), 5)
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    env = make()
    env.reset(seed=1)
    for _ in range(10):
        env.step(np.array([0.3], np.float32))
    clone = pickle.loads(pickle.dumps(env))
    for _ in range(10):
        action = np.array([-0.2], np.float32)
        assert np.array_equal(env.step(action)[0], clone.step(action)[0])


def test_the_kinematic_car_is_the_default_bit_for_bit() -> None:
    a = _rollout(TfaldaTrackEnv(), 2)
    b = _rollout(TfaldaTrackEnv(vehicle="kinematic", timing=Timing()), 2)
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    c = _rollout(TfaldaTrackEnv(vehicle="dynamic"), 2)
    assert not all(np.array_equal(x, y) for x, y in zip(a, c, strict=True))


def test_make_vec_with_the_dynamic_car() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        venv = gym.make_vec("TfaldaTrack-v0", num_envs=2, vehicle="dynamic",
                            timing="real-car")
        sync = gym.make_vec("TfaldaTrack-v0", num_envs=2, vectorization_mode="sync",
                            vehicle="dynamic", timing="real-car")
        try:
            got, want = venv.reset(seed=4)[0], sync.reset(seed=4)[0]
            assert np.array_equal(got, want)
            for _ in range(30):
                action = np.full((2, 1), 0.4, np.float32)
                assert np.array_equal(venv.step(action)[0], sync.step(action)[0])
        finally:
            venv.close()
            sync.close()


def test_the_pid_keeps_the_dynamic_car_in_its_lane_at_cruise_speed() -> None:
    env = TfaldaTrackEnv(track=7, vehicle="dynamic", timing="real-car", speed_m_s=1.5)
    pid = LanePid()
    obs, info = env.reset(seed=0, options={"start": (0.5, -0.2, 0.0)})
    pid.reset()
    for _ in range(500):
        obs, _, terminated, _, info = env.step(pid.act(obs))
        assert not terminated, info
    assert info["distance_m"] > 12.0


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"vehicle": "hovercraft"}, "vehicle"),
    ({"vehicle": 3}, "vehicle"),
    ({"timing": "fast"}, "timing must be one of ideal, real-car"),
    ({"timing": Timing(camera_latency_s=0.04, servo=REAL_SERVO)}, None),
    ({"vehicle": DynamicsParams(cog_to_front_m=0.5)}, "shorter than the wheelbase"),
])
def test_bad_vehicle_arguments_are_refused_with_their_name(kwargs: dict,
                                                           message: str | None) -> None:
    if message is None:  # accepted
        TfaldaTrackEnv(**kwargs).reset(seed=0)
        return
    with pytest.raises((ValueError, TypeError), match=message):
        TfaldaTrackEnv(**kwargs)
