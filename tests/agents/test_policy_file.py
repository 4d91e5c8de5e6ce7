"""Policy files load without running code: the safe format (agents/policy_file.py), the
refusal of pickled files without --trust-policy, and the committed policy converted."""

from __future__ import annotations

import io
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch

from tests.agents.policy_files import (
    COMMITTED,
    evil_policy,
    old_committed_policy,
    sb3_save,
)
from tests.cli_helpers import tfalda
from tfalda_sim.agents.drive import PpoAgent, make_agent
from tfalda_sim.agents.policy_file import (
    META_ENTRY,
    WEIGHTS_ENTRY,
    PolicyFileError,
    UntrustedPolicyError,
    load_policy,
    save_policy,
)

REFUSED = "a policy file with pickled objects can run code when loaded"

COMMANDS = {
    "drive": ["drive", "--agent", "ppo", "--track", "oval", "--laps", "1", "--json"],
    "evaluate-agent": ["evaluate-agent", "--agent", "ppo", "--seeds", "10000:10001",
                       "--laps", "1", "--workers", "1", "--json"],
}


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_a_pickled_policy_runs_no_code_without_trust_policy(command: str,
                                                           tmp_path: Path) -> None:
    """The payload in the file's data would create the marker when unpickled: refused
    with one line naming the file, why and the fix; the marker never appears."""
    marker = tmp_path / "marker"
    evil = evil_policy(tmp_path / "evil.zip", marker)
    run = tfalda(*COMMANDS[command], "--policy", evil, cwd=tmp_path, code=2)
    lines = run.err.strip().splitlines()
    assert len(lines) == 1, str(run)
    assert str(evil) in lines[0] and REFUSED in lines[0] and "--trust-policy" in lines[0]
    assert not marker.exists() and run.out == ""


def test_the_python_api_refuses_a_pickled_policy_unless_trusted(tmp_path: Path) -> None:
    marker = tmp_path / "marker"
    evil = evil_policy(tmp_path / "evil.zip", marker)
    for load in (lambda: PpoAgent(evil), lambda: make_agent("ppo", evil),
                 lambda: load_policy(evil)):
        with pytest.raises(UntrustedPolicyError, match="pickled objects can run code"):
            load()
        assert not marker.exists()
    # Trusted, SB3 loads it, and that is what trusting means: its pickles run.
    agent = make_agent("ppo", evil, trust_policy=True)
    assert marker.read_text() == "ran"
    assert isinstance(agent, PpoAgent) and agent.act(np.zeros(42, np.float32)).shape == (1,)


def test_trust_policy_loads_a_pickled_policy_on_the_command_line(tmp_path: Path) -> None:
    marker = tmp_path / "marker"
    evil = evil_policy(tmp_path / "evil.zip", marker)
    run = tfalda(*COMMANDS["drive"], "--policy", evil, "--trust-policy", "--no-recover",
                 cwd=tmp_path)
    assert run.json()["laps_completed"] == 1
    assert marker.exists()  # the documented meaning of --trust-policy


def test_weights_with_other_objects_than_tensors_are_refused(tmp_path: Path) -> None:
    """torch's weights-only reader refuses any other pickled object in policy.pth."""
    path = tmp_path / "odd.zip"
    save_policy(load_policy(COMMITTED), path)
    with zipfile.ZipFile(path) as z:
        meta = z.read(META_ENTRY)
    weights = io.BytesIO()
    torch.save({"log_std": torch.zeros(1), "extra": Path("x")}, weights)
    with zipfile.ZipFile(path, "w") as z:
        z.writestr(META_ENTRY, meta)
        z.writestr(WEIGHTS_ENTRY, weights.getvalue())
    with pytest.raises(UntrustedPolicyError, match=f"other than tensors in its {WEIGHTS_ENTRY}"):
        load_policy(path)


def test_the_committed_policy_loads_safely_with_the_actions_it_had(tmp_path: Path) -> None:
    """Converted from stable-baselines3's save to the safe format: no pickles in the file,
    the same weights bit for bit, the same actions."""
    from stable_baselines3 import PPO

    with zipfile.ZipFile(COMMITTED) as z:
        assert sorted(z.namelist()) == sorted([META_ENTRY, WEIGHTS_ENTRY])
    old = tmp_path / "old.zip"
    old.write_bytes(old_committed_policy())
    before = PPO.load(old, device="cpu").policy
    after = PpoAgent(COMMITTED)  # trust=False
    old_state, new_state = before.state_dict(), after.policy.state_dict()
    assert old_state.keys() == new_state.keys()
    for key, value in old_state.items():
        assert torch.equal(value, new_state[key]), key
    space = before.observation_space
    rng = np.random.default_rng(0)
    observations = rng.uniform(space.low, space.high, (500, *space.shape)).astype(np.float32)
    # One observation at a time, as the agent acts (a batch rounds differently).
    old_actions = np.stack([before.predict(obs, deterministic=True)[0] for obs in observations])
    new_actions = np.stack([after.act(obs) for obs in observations])
    assert np.array_equal(np.clip(old_actions, -1, 1), new_actions)
    assert len(np.unique(new_actions)) > 100  # not all at the clip bounds
    # The old file itself is now refused without trust.
    with pytest.raises(UntrustedPolicyError):
        load_policy(old)


def test_save_and_load_round_trip_a_policy(tmp_path: Path) -> None:
    policy = load_policy(COMMITTED)
    path = tmp_path / "again.zip"
    save_policy(policy, path)
    again = load_policy(path)
    assert path.read_bytes()[:2] == b"PK"
    for key, value in policy.state_dict().items():
        assert torch.equal(value, again.state_dict()[key])
    assert again.observation_space == policy.observation_space
    assert again.action_space == policy.action_space


def test_an_sb3_save_is_refused_naming_its_pickles(tmp_path: Path) -> None:
    path = sb3_save(load_policy(COMMITTED), tmp_path / "sb3.zip")
    with pytest.raises(PolicyFileError, match="':serialized:' entries in its data"):
        load_policy(path)
    assert load_policy(path, trust=True).state_dict().keys() == (
        load_policy(COMMITTED).state_dict().keys())
