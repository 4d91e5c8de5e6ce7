"""Policy files for the tests: stable-baselines3 saves (pickled), one carrying a payload,
and the committed policy as it was before it was converted to the safe format."""

from __future__ import annotations

import base64
import io
import json
import pickle
import subprocess
import zipfile
from pathlib import Path
from typing import Any

import gymnasium as gym
import pytest

from tfalda_sim import agents

COMMITTED = Path(agents.__file__).resolve().parent / "policies" / "ppo.zip"
REPO = Path(agents.__file__).resolve().parents[1]


class _Spaces(gym.Env):
    """An env of given spaces that is never stepped: what SB3's PPO needs to exist."""

    def __init__(self, observation_space: Any, action_space: Any) -> None:
        self.observation_space, self.action_space = observation_space, action_space


def sb3_save(policy: Any, path: Path) -> Path:
    """``policy``'s weights saved by stable-baselines3's own ``PPO.save`` (its ``data``
    entry full of pickles)."""
    from stable_baselines3 import PPO

    model = PPO("MlpPolicy", _Spaces(policy.observation_space, policy.action_space),
                n_steps=64, batch_size=64, device="cpu",
                policy_kwargs={"net_arch": [64, 64]})
    model.policy.load_state_dict(policy.state_dict())
    model.save(path)
    return path


class _Payload:
    """Unpickled, it runs ``code``: what a malicious policy file carries."""

    def __init__(self, code: str) -> None:
        self.code = code

    def __reduce__(self) -> tuple[Any, tuple[str]]:
        return exec, (self.code,)


def evil_policy(path: Path, marker: Path) -> Path:
    """A valid SB3 policy (the committed weights) whose ``data`` carries a pickle that
    creates ``marker`` when the file is loaded."""
    from tfalda_sim.agents.policy_file import load_policy

    sb3_save(load_policy(COMMITTED), path)
    with zipfile.ZipFile(path) as z:
        entries = {name: z.read(name) for name in z.namelist()}
    data = json.loads(entries["data"])
    code = f"import pathlib; pathlib.Path({str(marker)!r}).write_text('ran')"
    data["_last_obs"] = {":type:": "<class 'numpy.ndarray'>",
                         ":serialized:": base64.b64encode(pickle.dumps(_Payload(code))).decode()}
    entries["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(path, "w") as z:
        for name, content in entries.items():
            z.writestr(name, content)
    return path


def old_committed_policy() -> bytes:
    """The committed policy as stable-baselines3 saved it (the newest version of
    agents/policies/ppo.zip in the git history with SB3's ``data`` entry)."""
    try:
        commits = subprocess.run(
            ["git", "log", "--format=%H", "--", "agents/policies/ppo.zip"], cwd=REPO,
            capture_output=True, text=True, check=True, timeout=60).stdout.split()
    except (OSError, subprocess.SubprocessError):
        pytest.skip("needs the git history of agents/policies/ppo.zip")
    for commit in commits:
        blob = subprocess.run(["git", "show", f"{commit}:agents/policies/ppo.zip"], cwd=REPO,
                              capture_output=True, check=True, timeout=60).stdout
        with zipfile.ZipFile(io.BytesIO(blob)) as z:
            if "data" in z.namelist():
                return blob
    pytest.skip("no stable-baselines3 save of agents/policies/ppo.zip in the git history")
