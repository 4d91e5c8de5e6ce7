"""``agents.vec_env``: TfaldaTrackVectorEnv as an SB3 VecEnv equals SB3's own vector envs."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from gymnasium.vector import AutoresetMode
from gymnasium.wrappers import TimeLimit
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv

from tfalda_sim.agents.train import env_kwargs
from tfalda_sim.agents.vec_env import Sb3VectorEnv, make_sb3_vec_env, split_infos
from tfalda_sim.envs.vector import TfaldaTrackVectorEnv

KWARGS = env_kwargs(speed_m_s=1.5)


def _make_env(**kwargs: Any) -> Any:
    """One env as SB3's make_vec_env builds it for DummyVecEnv (the reference)."""
    import gymnasium

    return gymnasium.make("tfalda_sim:TfaldaTrack-v0", **kwargs)


def sb3_rollout(venv: Any, seed: int, steps: int) -> list[Any]:
    """Observations, rewards, dones and infos of a hard-steering rollout; an episode's
    statistics as (return rounded to 1e-4, length): SB3's Monitor sums the rewards in
    float64, its VecMonitor in float32, and both add wall-clock times."""
    venv.seed(seed)
    out: list[Any] = [venv.reset()]
    rng = np.random.default_rng(seed)
    for _ in range(steps):
        obs, rewards, dones, infos = venv.step(
            rng.uniform(-0.2, 1.0, (venv.num_envs, 1)).astype(np.float32))
        for info in infos:
            if "episode" in info:
                episode = info.pop("episode")
                info["episode"] = (round(float(episode["r"]), 4), int(episode["l"]))
        out.append((obs, rewards, dones, infos))
    out.append(venv.unwrapped.reset_infos)  # (VecMonitor keeps an empty list of its own)
    venv.close()
    return out


def assert_same(a: Any, b: Any) -> None:
    if isinstance(a, dict):
        assert a.keys() == b.keys(), (a.keys(), b.keys())
        for key in a:
            assert_same(a[key], b[key])
    elif isinstance(a, tuple | list):
        assert len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            assert_same(x, y)
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.dtype == b.dtype
        assert np.array_equal(a, b)
    else:
        assert type(a) is type(b) and a == b, (a, b)


@pytest.mark.parametrize("workers", [None, 1])
def test_rollout_equals_sb3_dummy_vec_env(workers: int | None) -> None:
    ours = sb3_rollout(make_sb3_vec_env(2, seed=3, workers=workers, **KWARGS), 3, 150)
    dummy = sb3_rollout(make_vec_env(_make_env, n_envs=2, seed=3, vec_env_cls=DummyVecEnv,
                                     env_kwargs=KWARGS), 3, 150)
    assert_same(ours, dummy)
    dones = np.array([step[2] for step in ours[1:-1]])
    assert dones.any()  # episodes ended: terminal_observation and reset_infos were compared
    ends = [info for step in ours[1:-1] for info in step[3] if "terminal_observation" in info]
    assert ends and all("episode" in info for info in ends)


def test_ppo_trains_the_same_policy_as_on_sb3s_vec_env(tmp_path, monkeypatch) -> None:
    torch = pytest.importorskip("torch")
    monkeypatch.setenv("SB3_LOGDIR", str(tmp_path))  # SB3's logger folder, else in /tmp
    from stable_baselines3 import PPO

    def params(venv: Any) -> list[Any]:
        model = PPO("MlpPolicy", venv, n_steps=64, batch_size=32, n_epochs=2, seed=4,
                    device="cpu", verbose=0)
        model.learn(256)
        venv.close()
        return [p.detach().clone() for p in model.policy.parameters()]

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        ours = params(make_sb3_vec_env(2, seed=4, **KWARGS))
        dummy = params(make_vec_env(_make_env, n_envs=2, seed=4, vec_env_cls=DummyVecEnv,
                                    env_kwargs=KWARGS))
    finally:
        torch.set_num_threads(threads)
    assert all(torch.equal(a, b) for a, b in zip(ours, dummy, strict=True))


def test_attributes_methods_and_wrappers() -> None:
    venv = make_sb3_vec_env(2, seed=0, track="oval")
    try:
        venv.reset()
        assert venv.get_attr("observation_mode", indices=[1])[0].value == "lanes"
        frames = venv.env_method("camera_frame", indices=0)
        assert len(frames) == 1 and frames[0].shape == (480, 752)
        venv.set_attr("probe_value", 7, indices=[1])
        assert venv.get_attr("probe_value", indices=[1]) == [7]
        venv.set_attr("probe_pair", (10, 20))  # one value for every env, as SB3 does
        assert venv.get_attr("probe_pair") == [(10, 20), (10, 20)]
        assert callable(venv.get_attr("camera_frame")[0])  # SB3: attributes, never called
        assert venv.env_is_wrapped(TimeLimit) == [True, True]
        assert venv.env_is_wrapped(Monitor) == [False, False]
    finally:
        venv.close()


def test_needs_same_step_autoreset_and_equal_options() -> None:
    venv = TfaldaTrackVectorEnv(2, workers=1, track="oval")
    with pytest.raises(ValueError, match="SAME_STEP"):
        Sb3VectorEnv(venv)
    venv.close()
    adapter = Sb3VectorEnv(TfaldaTrackVectorEnv(2, workers=1, track="oval",
                                                autoreset_mode=AutoresetMode.SAME_STEP))
    try:
        adapter.set_options([{"a": 1}, {"a": 2}])
        with pytest.raises(ValueError, match="same options"):
            adapter.reset()
        with pytest.raises(RuntimeError, match="step_async"):
            adapter.step_wait()
    finally:
        adapter.close()


def test_split_infos_inverts_gymnasiums_layout() -> None:
    merged = {"a": np.array([1.0, 2.0]), "_a": np.array([True, False]),
              "b": {"c": np.array([3, 4]), "_c": np.array([True, True])},
              "_b": np.array([False, True])}
    assert split_infos(merged, 2) == [{"a": 1.0}, {"b": {"c": 4}}]
    assert type(split_infos(merged, 2)[0]["a"]) is float
