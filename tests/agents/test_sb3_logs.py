"""stable-baselines3's logger leaves no empty tempdir/SB3-<time> folders behind: a model
that learns without a log folder gets that folder from SB3 (tests do so), and one was
left in /tmp by every such run of the suite."""

from __future__ import annotations

import tempfile
from pathlib import Path

import gymnasium as gym
import pytest


def _sb3_folders(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.glob("SB3-*"))


def test_a_model_learning_without_a_log_folder_leaves_none_in_the_temp_folder(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from stable_baselines3 import PPO

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # SB3's fallback goes here
    model = PPO("MlpPolicy", gym.make("Pendulum-v1"), n_steps=16, batch_size=16, n_epochs=1,
                device="cpu", verbose=0)
    model.learn(16)
    assert _sb3_folders(tmp_path) == []


def test_a_short_training_leaves_none_in_the_temp_folder(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``train`` logs to OUT/tb, also with no SB3_LOGDIR set."""
    from tfalda_sim.agents.train import PpoConfig, train

    temp = tmp_path / "temp"
    temp.mkdir()
    monkeypatch.delenv("SB3_LOGDIR", raising=False)
    monkeypatch.setattr(tempfile, "tempdir", str(temp))
    train(64, 1, 0, tmp_path / "run", config=PpoConfig(n_steps=64, batch_size=32, n_epochs=1),
          progress=False, subprocess=False, track="oval")
    assert _sb3_folders(temp) == [] and (tmp_path / "run" / "policy.zip").is_file()
