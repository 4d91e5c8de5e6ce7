"""Stable-Baselines3 accepts the env: its checker, vectorised envs, a few PPO steps."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from stable_baselines3 import PPO
from stable_baselines3.common.env_checker import check_env
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

from tfalda_sim.envs import TfaldaTrackEnv


@pytest.mark.parametrize("mode", ["lanes", "image", "dict"])
def test_sb3_check_env_passes_with_warnings_as_errors(mode: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(TfaldaTrackEnv(track="oval", observation=mode), warn=True)


@pytest.mark.parametrize("vec_cls", [DummyVecEnv, SubprocVecEnv])
def test_sb3_vec_envs_step_and_ppo_collects_a_rollout(vec_cls: type) -> None:
    venv = make_vec_env(TfaldaTrackEnv, n_envs=2, seed=0, vec_env_cls=vec_cls,
                        env_kwargs={"track": "oval"})
    try:
        obs = venv.reset()
        assert obs.shape == (2, 42)
        obs, rewards, _dones, infos = venv.step(np.zeros((2, 1), np.float32))
        assert rewards.shape == (2,) and "cross_track_m" in infos[0]
        model = PPO("MlpPolicy", venv, n_steps=16, batch_size=16, n_epochs=1, seed=0,
                    device="cpu")
        model.learn(32)
        assert model.num_timesteps >= 32
    finally:
        venv.close()
