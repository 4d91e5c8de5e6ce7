"""A short PPO run completes, saves its policy and improves the mean return."""

from __future__ import annotations

import contextlib
import json

import numpy as np
import pytest
import torch
from stable_baselines3 import PPO

from tfalda_sim.agents.drive import PpoAgent
from tfalda_sim.agents.policy_file import load_policy, save_policy
from tfalda_sim.agents.train import PpoConfig, train
from tfalda_sim.envs import TfaldaTrackEnv


def mean_return(policy: PpoAgent, episodes: int = 3, steps: int = 300) -> float:
    env = TfaldaTrackEnv(track="oval")
    returns = []
    for k in range(episodes):
        obs, _ = env.reset(seed=k)
        total = 0.0
        for _ in range(steps):
            obs, reward, terminated, _, _ = env.step(policy.act(obs))
            total += reward
            if terminated:
                break
        returns.append(total)
    return float(np.mean(returns))


def test_short_ppo_training_improves_the_return(tmp_path) -> None:
    torch.set_num_threads(1)
    # A constant rate and σ = 1 (the defaults decay the rate over a run of 100 k steps).
    config = PpoConfig(n_steps=512, batch_size=128, learning_rate=1e-3, log_std_init=0.0,
                       lr_decay=False)
    # An untrained policy of the same architecture: the starting point.
    untrained = PPO("MlpPolicy", TfaldaTrackEnv(track="oval"), seed=0, device="cpu",
                    policy_kwargs={"net_arch": list(config.net_arch)})
    save_policy(untrained.policy, tmp_path / "untrained.zip")
    summary = train(6144, 1, 0, tmp_path / "run", config=config, progress=False,
                    subprocess=False, track="oval")
    assert (tmp_path / "run" / "policy.zip").is_file()
    assert json.loads((tmp_path / "run" / "train.json").read_text())["timesteps"] == 6144
    assert summary["train_time_s"] > 0 and list((tmp_path / "run" / "tb").iterdir())
    before = mean_return(PpoAgent(tmp_path / "untrained.zip"))
    after = mean_return(PpoAgent(tmp_path / "run" / "policy.zip"))
    assert after > before + 50.0, (before, after)


def test_training_works_with_gradients_off_and_leaves_the_mode_as_it_was(tmp_path) -> None:
    """A caller (or an earlier run cut by Ctrl-C inside torch's no_grad) with gradients
    off: training turns them on for itself and gives the caller its mode back."""
    config = PpoConfig(n_steps=64, batch_size=32, n_epochs=1)
    torch.set_grad_enabled(False)
    try:
        summary = train(64, 1, 0, tmp_path / "run", config=config, progress=False,
                        subprocess=False, track="oval")
        assert not torch.is_grad_enabled()
    finally:
        torch.set_grad_enabled(True)
    assert summary["timesteps_done"] >= 64 and (tmp_path / "run" / "policy.zip").is_file()


def test_config_reaches_the_model_and_the_run_reports_its_rate(tmp_path) -> None:
    """The exploration noise and the learning-rate decay of PpoConfig are the saved
    model's (the policy's and a checkpoint's); train.json has the rate; the caller's torch
    threads are left as they were."""
    torch.set_num_threads(2)
    config = PpoConfig(n_steps=128, batch_size=64, n_epochs=1, learning_rate=1e-3,
                       log_std_init=-1.0, lr_decay=True)
    summary = train(128, 1, 0, tmp_path / "run", config=config, progress=False,
                    subprocess=False, track="oval", checkpoint_steps=128)
    assert torch.get_num_threads() == 2
    assert summary["steps_per_s"] > 0 and summary["config"]["log_std_init"] == -1.0
    policy = load_policy(tmp_path / "run" / "policy.zip")
    assert abs(float(policy.log_std.detach().mean()) + 1.0) < 0.05  # one small update
    # The schedule is training state: in SB3's checkpoint, not in the policy file.
    model = PPO.load(tmp_path / "run" / "checkpoints" / "ppo_128_steps.zip", device="cpu")
    assert model.lr_schedule(1.0) == 1e-3 and model.lr_schedule(0.25) == 2.5e-4


def test_train_writes_a_policy_that_loads_without_unpickling(tmp_path) -> None:
    """policy.zip is the architecture as JSON and the weights as tensors (no SB3 pickles),
    and holds the trained weights."""
    import zipfile

    from tfalda_sim.agents.policy_file import META_ENTRY, WEIGHTS_ENTRY

    config = PpoConfig(n_steps=64, batch_size=32, n_epochs=1)
    saved = []
    learn = PPO.learn

    def keep(self, *args, **kwargs):
        model = learn(self, *args, **kwargs)
        saved.append({k: v.clone() for k, v in self.policy.state_dict().items()})
        return model

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(PPO, "learn", keep)
        train(64, 1, 0, tmp_path / "run", config=config, progress=False, subprocess=False,
              track="oval")
    path = tmp_path / "run" / "policy.zip"
    with zipfile.ZipFile(path) as z:
        assert sorted(z.namelist()) == sorted([META_ENTRY, WEIGHTS_ENTRY])
    state = load_policy(path).state_dict()  # trust=False
    assert all(torch.equal(v, state[k]) for k, v in saved[0].items())


def _saved_params(path) -> list[torch.Tensor]:
    return [p.detach().clone() for p in load_policy(path).parameters()]


def test_distribution_checks_are_off_while_training_change_no_number_and_come_back(
        tmp_path, monkeypatch) -> None:
    """``train`` runs with torch.distributions' checks off (a forward pass ≈ 40 % cheaper),
    trains the same parameters bit for bit as with them on, and leaves the caller's
    setting as it was, on or off."""
    from torch.distributions import Distribution

    import tfalda_sim.agents.train as train_module

    seen: list[bool] = []
    learn = PPO.learn

    def spy(self, *args, **kwargs):
        seen.append(Distribution._validate_args)
        return learn(self, *args, **kwargs)

    monkeypatch.setattr(PPO, "learn", spy)
    config = PpoConfig(n_steps=128, batch_size=64, n_epochs=2)
    kwargs = {"config": config, "progress": False, "subprocess": False, "track": "oval"}
    before = Distribution._validate_args
    try:
        for setting in (True, False):
            Distribution.set_default_validate_args(setting)
            train(256, 1, 3, tmp_path / f"off-{setting}", **kwargs)
            assert Distribution._validate_args is setting
        assert seen == [False, False]
        # The same run with the checks left on: the same parameters, bit for bit.
        Distribution.set_default_validate_args(True)
        monkeypatch.setattr(train_module, "distribution_checks_off", contextlib.nullcontext)
        train(256, 1, 3, tmp_path / "on", **kwargs)
        assert seen[-1] is True
    finally:
        Distribution.set_default_validate_args(before)
    on = _saved_params(tmp_path / "on" / "policy.zip")
    off = _saved_params(tmp_path / "off-True" / "policy.zip")
    assert all(torch.equal(a, b) for a, b in zip(on, off, strict=True))


def test_ppo_agent_acts_the_same_with_the_checks_off_and_restores_them() -> None:
    from torch.distributions import Distribution

    from tfalda_sim.agents.drive import DEFAULT_POLICY

    agent = PpoAgent(DEFAULT_POLICY)
    env = TfaldaTrackEnv(track="oval")
    obs, _ = env.reset(seed=0)
    seen: list[bool] = []
    predict = agent.policy.predict

    def spy(*args, **kwargs):
        seen.append(Distribution._validate_args)
        return predict(*args, **kwargs)

    agent.policy.predict = spy
    before = Distribution._validate_args
    try:
        Distribution.set_default_validate_args(True)
        fast = agent.act(obs)
        assert seen == [False] and Distribution._validate_args is True
        with torch.no_grad():
            tensor, _ = agent.policy.obs_to_tensor(obs)
            mean = agent.policy.get_distribution(tensor).mode()  # checks on
    finally:
        Distribution.set_default_validate_args(before)
    assert np.array_equal(fast, np.clip(mean.numpy().reshape(fast.shape), -1.0, 1.0))


def test_a_ctrl_c_while_the_policy_is_saved_leaks_no_file_and_writes_no_run(
        tmp_path, monkeypatch) -> None:
    """A Ctrl-C inside SB3's zip writer (the CLI fuzz's alarm once landed there): the
    policy file is closed (SB3 leaves a path it opened open on an exception: a
    ResourceWarning when collected) and the run leaves no folder."""
    import gc
    import sys
    import warnings
    import zipfile

    def interrupted(self, *args, **kwargs):
        raise KeyboardInterrupt

    unraisable: list = []
    monkeypatch.setattr(zipfile.ZipFile, "writestr", interrupted)
    monkeypatch.setattr(sys, "unraisablehook", unraisable.append)
    config = PpoConfig(n_steps=64, batch_size=32, n_epochs=1)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ResourceWarning)  # a leaked file: unraisable
        with pytest.raises(KeyboardInterrupt):
            train(64, 1, 0, tmp_path / "run", config=config, progress=False,
                  subprocess=False, track="oval")
        gc.collect()
    leaks = [u for u in unraisable if isinstance(u.exc_value, ResourceWarning)]
    assert not leaks, [str(u.exc_value) for u in leaks]
    assert not (tmp_path / "run").exists() and not list(tmp_path.glob(".tfalda-sim-*"))


def test_a_ctrl_c_while_the_finished_policy_is_saved_is_held(tmp_path, monkeypatch) -> None:
    """A real Ctrl-C (SIGINT) after the training while torch writes the policy: its zip
    writer once broke on it ("unexpected pos", an internal error of the CLI). The run is
    saved whole and published; the Ctrl-C is held there and noted (``tfalda-sim train``
    then exits 130)."""
    import os
    import signal

    from tfalda_sim.agents import policy_file
    from tfalda_sim.interrupts import held_stop, stop_signals_interrupt

    save = policy_file.save_policy

    def save_with_a_ctrl_c(*args, **kwargs):
        os.kill(os.getpid(), signal.SIGINT)
        return save(*args, **kwargs)

    monkeypatch.setattr(policy_file, "save_policy", save_with_a_ctrl_c)
    config = PpoConfig(n_steps=64, batch_size=32, n_epochs=1)
    with stop_signals_interrupt():
        summary = train(64, 1, 0, tmp_path / "run", config=config, progress=False,
                        subprocess=False, track="oval")
        assert held_stop() == signal.SIGINT
    assert not summary["interrupted"]  # the training had finished
    load_policy(tmp_path / "run" / "policy.zip")  # whole
    assert json.loads((tmp_path / "run" / "train.json").read_text())["timesteps_done"] >= 64


def test_a_ctrl_c_during_a_checkpoint_waits_for_it_then_ends_the_training(
        tmp_path, monkeypatch) -> None:
    """A real Ctrl-C while SB3 writes a checkpoint is held until the checkpoint is
    written, then stops the training as anywhere else: the run keeps the policy so far
    and the whole checkpoint."""
    import os
    import signal

    from stable_baselines3.common.callbacks import CheckpointCallback

    on_step = CheckpointCallback._on_step
    sent: list[int] = []

    def on_step_with_a_ctrl_c(self) -> bool:
        if self.n_calls % self.save_freq == 0 and not sent:
            sent.append(self.n_calls)
            os.kill(os.getpid(), signal.SIGINT)
        return on_step(self)

    monkeypatch.setattr(CheckpointCallback, "_on_step", on_step_with_a_ctrl_c)
    config = PpoConfig(n_steps=64, batch_size=32, n_epochs=1)
    summary = train(256, 1, 0, tmp_path / "run", config=config, progress=False,
                    subprocess=False, track="oval", checkpoint_steps=32)
    assert sent == [32]
    assert summary["interrupted"] and summary["timesteps_done"] < 256
    checkpoints = sorted((tmp_path / "run" / "checkpoints").glob("ppo_*.zip"))
    assert [c.name for c in checkpoints] == ["ppo_32_steps.zip"]
    PPO.load(checkpoints[0])  # whole
    load_policy(tmp_path / "run" / "policy.zip")
