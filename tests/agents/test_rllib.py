"""``tfalda-sim train --backend rllib``: PPO on RLlib, on a local Ray with 2 CPUs.

Two short trainings (≈ 20 s each on 2 cores): one in-process through ``main`` (JSON, a
camera profile passed through to the env, a Ctrl-C after two iterations keeping their
checkpoint, which restores and acts), one through the installed console script (every
iteration run, its steps/s and return reported). The rest needs no Ray to run.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tfalda_sim.agents import rllib
from tfalda_sim.cli import main


def _has_rllib() -> bool:
    try:
        rllib.import_rllib()
    except rllib.RllibUnavailable:
        return False
    return True


needs_rllib = pytest.mark.skipif(not _has_rllib(), reason="needs the rllib extra")

SCRIPT: str | None = shutil.which("tfalda-sim", path=str(Path(sys.executable).parent))
BATCH = 256
"""Env steps per iteration: tiny, so an iteration takes seconds."""


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def lanes_observation(camera: str = "thesis") -> np.ndarray:
    env = rllib.make_env(rllib.env_config(track="oval", camera=camera))
    obs, _ = env.reset(seed=0)
    env.close()
    return obs


@needs_rllib
def test_the_env_factory_passes_the_env_config_through() -> None:
    """What a Ray worker builds: the registered env with its time limit, "lanes"
    observations, the camera (a profile file shipped as the camera itself), the seeds."""
    from tfalda_sim import MAX_EPISODE_STEPS
    from tfalda_sim.camera import NAMED_CAMERAS, Camera, load_camera
    from tfalda_sim.camera.profile import named_camera_path, profile_dict

    cfg = rllib.env_config(speed_m_s=2.0, camera="reference-car")
    assert cfg["observation"] == "lanes" and cfg["track_seeds"] == (0, 1000)
    assert cfg["camera"] == "reference-car" and "reference-car" in NAMED_CAMERAS
    from_file = rllib.env_config(camera=str(named_camera_path("reference-car")))["camera"]
    assert isinstance(from_file, Camera)
    assert profile_dict(from_file) == profile_dict(load_camera("reference-car"))
    env = rllib.make_env(cfg)
    try:
        assert env.spec is not None and env.spec.max_episode_steps == MAX_EPISODE_STEPS
        obs, _ = env.reset(seed=3)
        assert env.observation_space.contains(obs) and obs.ndim == 1
        assert env.unwrapped.observation_mode.value == "lanes"
        assert env.unwrapped.speed_m_s == 2.0
    finally:
        env.close()


@needs_rllib
def test_the_ppo_config_is_the_sb3_one_on_rllibs_current_api_stack() -> None:
    from tfalda_sim.agents.train import PpoConfig

    cfg = rllib.ppo_config(rllib.env_config(), rllib.RllibConfig(train_batch=512,
                                                                 env_runners=3), seed=5)
    ppo = PpoConfig()
    assert cfg.enable_rl_module_and_learner and cfg.enable_env_runner_and_connector_v2
    assert cfg.env == rllib.ENV_NAME and cfg.env_config["observation"] == "lanes"
    assert (cfg.num_env_runners, cfg.train_batch_size_per_learner, cfg.seed) == (3, 512, 5)
    assert (cfg.lr, cfg.gamma, cfg.lambda_, cfg.clip_param, cfg.num_epochs) == (
        ppo.learning_rate, ppo.gamma, ppo.gae_lambda, ppo.clip_range, ppo.n_epochs)
    assert cfg.minibatch_size == ppo.batch_size and not cfg.use_kl_loss
    assert cfg.model_config["fcnet_hiddens"] == list(ppo.net_arch)
    assert not cfg.restart_failed_env_runners  # a broken env is an error, not a silent 0
    # a slow first sample (kernels loading on a busy host) waits, not an empty iteration
    assert cfg.sample_timeout_s is None


@needs_rllib
def test_interrupted_training_keeps_finished_iterations_and_restores(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Four iterations asked, a Ctrl-C as the third ends: exit 130, the first two kept as
    the checkpoint and in train.json; the checkpoint restores without Ray and acts."""
    real = rllib._iteration

    def ctrl_c_in_third(result: dict, k: int, steps: int, time_s: float) -> rllib.Iteration:
        if k == 3:
            raise KeyboardInterrupt
        return real(result, k, steps, time_s)

    monkeypatch.setattr(rllib, "_iteration", ctrl_c_in_third)
    out = tmp_path / "run"
    code, stdout, err = run(capsys, "train", "--backend", "rllib", "--timesteps",
                            str(4 * BATCH), "--train-batch", str(BATCH), "--env-runners", "1",
                            "--camera", "reference-car", "--seed", "3", "--out", str(out),
                            "--json")
    assert code == 130, err
    assert "kept the checkpoint of iteration 2 of 4" in err and "Traceback" not in err
    summary = json.loads(stdout)
    assert summary == json.loads((out / "train.json").read_text())
    assert summary["interrupted"] and summary["failed"] is None
    assert (summary["iterations"], summary["iterations_done"]) == (4, 2)
    assert summary["camera"] == "reference-car" and summary["backend"] == "rllib"
    history = summary["history"]
    assert [it["env_steps"] for it in history] == [BATCH, BATCH]
    assert summary["timesteps_done"] == history[-1]["env_steps_total"] == 2 * BATCH
    assert all(it["steps_per_s"] > 0 for it in history)
    assert math.isfinite(summary["episode_return_mean"])  # random policies leave the road
    assert sorted(p.name for p in out.iterdir()) == ["checkpoint", "train.json"]
    assert not list(tmp_path.glob(".tfalda-sim-*"))  # no staging folder left

    policy = rllib.RllibPolicy(out / "checkpoint")
    obs = lanes_observation("reference-car")
    action = policy.act(obs)
    assert action.shape == (1,) and action.dtype == np.float32
    assert np.all(np.abs(action) <= 1.0) and np.all(np.isfinite(action))
    assert np.array_equal(action, policy.act(obs))  # deterministic


@needs_rllib
@pytest.mark.skipif(SCRIPT is None, reason="the tfalda-sim console script is not installed")
def test_console_script_trains_every_iteration(tmp_path: Path) -> None:
    """As a user runs it: a local Ray, two iterations sampled in the driver (0 env
    runners), each reported on stderr with its steps/s and mean return."""
    env = {k: v for k, v in os.environ.items() if k not in ("TFALDA_SIM_DEBUG", "RAY_ADDRESS")}
    assert SCRIPT is not None
    proc = subprocess.run([SCRIPT, "train", "--backend", "rllib", "--timesteps", str(2 * BATCH),
                           "--train-batch", str(BATCH), "--env-runners", "0", "--out", "run"],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr and "internal error" not in proc.stderr
    assert "trained 512 steps in 2 iterations" in proc.stdout
    for k in (1, 2):
        assert f"iteration {k}/2: {k * BATCH} steps, " in proc.stderr
    assert "steps/s, mean episode return" in proc.stderr
    summary = json.loads((tmp_path / "run" / "train.json").read_text())
    assert summary["iterations_done"] == 2 and not summary["interrupted"]
    assert summary["config"]["env_runners"] == 0
    assert (tmp_path / "run" / "checkpoint" / "learner_group").is_dir()
    assert rllib.RllibPolicy(tmp_path / "run" / "checkpoint").act(lanes_observation()).shape == (1,)


@pytest.mark.parametrize(("argv", "message"), [
    (["--backend", "rllib", "--n-envs", "2"], "--n-envs is for --backend sb3, not rllib"),
    (["--ray-address", "auto"], "--ray-address is for --backend rllib, not sb3"),
    (["--backend", "sb3", "--env-runners", "1", "--train-batch", "64"],
     "--env-runners and --train-batch are for --backend rllib, not sb3"),
    (["--backend", "rllib", "--env-runners", "-1"], "expected an integer from 0"),
    (["--backend", "rllib", "--train-batch", "0"], "expected an integer from 1"),
    (["--backend", "rllib", "--train-batch", "1000001"], "from 1 to 1000000"),  # memory
])
def test_options_of_the_other_backend_are_refused(
        argv: list[str], message: str, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run(capsys, "train", *argv, "--out", str(tmp_path / "run"))
    assert code == 2 and message in err, err
    assert not (tmp_path / "run").exists()


def test_without_rllib_the_error_names_the_extra(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` raises ImportError
    code, _, err = run(capsys, "train", "--backend", "rllib", "--out", str(tmp_path / "run"))
    assert code == 2 and "pip install 'tfalda-sim[rllib]'" in err, err
    assert "Traceback" not in err and not (tmp_path / "run").exists()


def test_an_earlier_run_is_kept_without_force(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    """Checked before Ray starts; an sb3 run's folder is not mixed into either."""
    for earlier in ("train.json", "checkpoint", "policy.zip"):
        out = tmp_path / earlier.replace(".", "-")
        out.mkdir()
        (out / earlier).mkdir() if earlier == "checkpoint" else (out / earlier).write_text("{}")
        code, _, err = run(capsys, "train", "--backend", "rllib", "--out", str(out))
        assert code == 2 and "--force" in err, err
        assert [p.name for p in out.iterdir()] == [earlier]


@needs_rllib
def test_no_ray_cluster_at_the_address_is_a_clear_error(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    import ray

    if ray.is_initialized():
        pytest.skip("a Ray is connected in this process")
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    monkeypatch.setenv("RAY_TMPDIR", str(tmp_path / "ray"))  # no cluster recorded there
    code, _, err = run(capsys, "train", "--backend", "rllib", "--ray-address", "auto",
                       "--out", str(tmp_path / "run"))
    assert code == 2 and "could not connect to the Ray cluster at auto" in err, err
    # Our fix, not Ray's advice about flags this command does not have.
    assert "ray start --head" in err and "--address" not in err, err
    assert not ray.is_initialized() and not (tmp_path / "run").exists()


@needs_rllib
def test_an_address_nobody_listens_on_is_a_clear_error_at_once(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """ray.init would retry it for ever; the check before it names the address and why."""
    import ray

    if ray.is_initialized():
        pytest.skip("a Ray is connected in this process")
    with socket.socket() as sock:  # a port nothing listens on: bound, then released
        sock.bind(("127.0.0.1", 0))
        address = f"127.0.0.1:{sock.getsockname()[1]}"
    code, _, err = run(capsys, "train", "--backend", "rllib", "--ray-address", address,
                       "--out", str(tmp_path / "run"))
    assert code == 2, err
    assert f"could not connect to the Ray cluster at {address}: nothing listens" in err, err
    assert not ray.is_initialized() and not (tmp_path / "run").exists()


@needs_rllib
def test_an_env_that_cannot_start_is_a_clear_error(tmp_path: Path) -> None:
    """A worker whose env raises (as on a node without tfalda-sim): one line naming the
    error, Ray shut down, nothing written."""
    import ray

    with pytest.raises(rllib.RllibUnavailable, match="could not start its env runners: "
                                                      "ValueError: unknown track"):
        rllib.train_rllib(64, 0, tmp_path / "run", config=rllib.RllibConfig(
            train_batch=32, env_runners=1), track="no-such-track", progress=False)
    assert not ray.is_initialized() and not list(tmp_path.iterdir())
