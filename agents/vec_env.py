"""``TfaldaTrackVectorEnv`` as a stable-baselines3 ``VecEnv``: what ``tfalda-sim train`` steps.

SB3's ``SubprocVecEnv`` runs every env in a worker process that blocks on its pipe between
steps while the trainer's process waits for them; on this 2-core VM a worker woken on an
idle core stepped about 30 % slower. ``TfaldaTrackVectorEnv`` steps the first slice of envs
in the trainer's own process and lets its workers poll before they block
(``tfalda_sim.envs.vector``); this adapter gives it SB3's interface:

- autoreset on the same step (the vector env's ``SAME_STEP`` mode): a finished env's last
  observation is in ``infos[i]["terminal_observation"]``, ``infos[i]`` is its last step's
  info plus ``"TimeLimit.truncated"`` (truncated and not terminated), and the new
  episode's reset info is in ``reset_infos[i]``, as ``SubprocVecEnv`` gives them;
- ``seed(s)`` then ``reset()`` seeds env ``i`` with ``s + i`` (SB3's ``make_vec_env``).

A rollout through it equals one through ``make_vec_env(…, vec_env_cls=DummyVecEnv)`` (tests),
so a PPO run trains the same policy either way. Episode statistics come from SB3's
``VecMonitor`` on top (``make_sb3_vec_env``). Needs the ``rl`` extra.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env import VecEnv, VecMonitor

from tfalda_sim.envs.vector import TfaldaTrackVectorEnv


class Sb3VectorEnv(VecEnv):
    """SB3's ``VecEnv`` API over a ``TfaldaTrackVectorEnv`` in ``SAME_STEP`` mode (it is
    closed with this adapter)."""

    def __init__(self, venv: TfaldaTrackVectorEnv) -> None:
        if venv.autoreset_mode is not AutoresetMode.SAME_STEP:
            raise ValueError("Sb3VectorEnv needs a TfaldaTrackVectorEnv with "
                             "autoreset_mode=AutoresetMode.SAME_STEP (SB3 resets an env on "
                             "the step its episode ends)")
        self.venv = venv
        super().__init__(venv.num_envs, venv.single_observation_space,
                         venv.single_action_space)
        self._actions: np.ndarray | None = None

    def reset(self) -> np.ndarray:
        options = self._options[0]
        if any(o != options for o in self._options[1:]):
            raise ValueError("Sb3VectorEnv resets every env with the same options; "
                             f"set_options gave different ones: {self._options}")
        seeds = self._seeds if any(s is not None for s in self._seeds) else None
        obs, infos = self.venv.reset(seed=seeds, options=options or None)
        self.reset_infos = split_infos(infos, self.num_envs)
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        if self._actions is None:
            raise RuntimeError("step_wait() without step_async(actions) before it")
        actions, self._actions = self._actions, None
        # Each env's info dict as the env gave it (no merge into columns and split back).
        obs, rewards, terminated, truncated, infos = self.venv.step_per_env(actions)
        done = terminated | truncated
        step_infos: list[dict[str, Any]] = []
        for i, info in enumerate(infos):
            info = dict(info)  # ours to change (an env may keep its dict)
            if done[i]:
                # SubprocVecEnv: the last step's info + the last observation; the new
                # episode's reset info apart.
                final = dict(info.pop("final_info"))
                final["terminal_observation"] = info.pop("final_obs")
                self.reset_infos[i] = info
                info = final
            info["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
            step_infos.append(info)
        return obs, rewards.astype(np.float32), done, step_infos

    def close(self) -> None:
        self.venv.close()

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        return list(self.venv.get_attr_on(list(self._get_indices(indices)), attr_name))

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        chosen = list(self._get_indices(indices))
        self.venv.set_attr(attr_name, [value] * len(chosen), indices=chosen)  # as is, each

    def env_method(self, method_name: str, *method_args: Any, indices: Any = None,
                   **method_kwargs: Any) -> list[Any]:
        return list(self.venv.call_on(list(self._get_indices(indices)), method_name,
                                      *method_args, **method_kwargs))

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: Any = None
                       ) -> list[bool]:
        values = self.venv.is_wrapped(wrapper_class)
        return [values[i] for i in self._get_indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        return list(self.venv.render())


def split_infos(merged: dict[str, Any], n: int) -> list[dict[str, Any]]:
    """Gymnasium's vector infos (``key``: one entry per env, ``_key``: which envs have it)
    back into one dict per env (numpy scalars as Python numbers)."""
    out: list[dict[str, Any]] = [{} for _ in range(n)]
    for key, column in merged.items():
        mask = merged.get(f"_{key}")
        if mask is None:  # a mask itself (or a key without one: not Gymnasium's layout)
            continue
        parts = split_infos(column, n) if isinstance(column, dict) else None
        for i in range(n):
            if mask[i]:
                value = parts[i] if parts is not None else column[i]
                out[i][key] = value.item() if isinstance(value, np.generic) else value
    return out


def make_sb3_vec_env(n_envs: int, seed: int, *, workers: int | None = None,
                     **env_kwargs: Any) -> VecMonitor:
    """``n_envs`` training envs (``TfaldaTrackVectorEnv``'s keywords) for SB3, seeded
    ``seed + i`` at the first reset, with episode statistics (``VecMonitor``)."""
    venv = TfaldaTrackVectorEnv(n_envs, workers=workers,
                                autoreset_mode=AutoresetMode.SAME_STEP, **env_kwargs)
    adapter = Sb3VectorEnv(venv)
    adapter.seed(seed)
    return VecMonitor(adapter)
