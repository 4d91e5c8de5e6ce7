"""PPO (stable-baselines3) on TfaldaTrack-v0's lane observations, on vectorised envs.

    tfalda-sim train --timesteps 120000 --n-envs 2 --seed 0 --out runs/ppo

Training tracks are the generated seeds of ``TRAIN_SEEDS``; ``tfalda-sim evaluate-agent``
tests on the held-out ``TEST_SEEDS``. Writes TensorBoard logs (``OUT/tb``), checkpoints
(``OUT/checkpoints``, stable-baselines3 saves), the final policy (``OUT/policy.zip``, in the
format that loads without unpickling: ``policy_file.py``) and ``OUT/train.json`` (the
command's arguments, the training time, the machine). Needs the ``rl`` extra.
"""

from __future__ import annotations

import contextlib
import json
import os
import platform
import shutil
import tempfile
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from tfalda_sim.interrupts import INTERRUPTS, deferring_stops, holding_stops, is_interrupt

TRAIN_SEEDS: tuple[int, int] = (0, 1000)
"""Generated track seeds ``[low, high)`` the policy is trained on."""

TEST_SEEDS: tuple[int, int] = (10_000, 10_100)
"""Held-out generated track seeds ``[low, high)`` for evaluation (never trained on)."""

TRAIN_SPEED_M_S: float = 1.5
"""Cruise speed during training [m/s]."""


@dataclass(frozen=True)
class PpoConfig:
    """The PPO hyper-parameters used (stable-baselines3 names). Tuned for few env steps
    (docs/agents.md): short rollouts and small minibatches (more updates per step), a
    high learning rate decayed to 0 (the policy settles by the end of a short run) and
    steering noise of σ ≈ 0.37 instead of 1 (with σ = 1 the clipped random steering
    leaves the road every ~60 steps and the mean action learns slowly)."""

    n_steps: int = 512
    batch_size: int = 128
    n_epochs: int = 10
    learning_rate: float = 1e-3
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    ent_coef: float = 0.0
    net_arch: tuple[int, ...] = (64, 64)
    log_std_init: float = -1.0
    """Initial log standard deviation of the Gaussian steering noise."""
    lr_decay: bool = True
    """Decay the learning rate linearly to 0 over the run."""
    target_kl: float | None = None


@contextlib.contextmanager
def distribution_checks_off() -> Iterator[None]:
    """torch.distributions' argument and sample checks off inside (the previous setting
    restored after). They only raise on a NaN or out-of-support parameter and change no
    number, yet they cost ≈ 40 % of a forward pass of the 64-64 policy (≈ 440 → 270 µs
    here), once per env step in the rollouts; PyTorch's documentation of
    ``Distribution.set_default_validate_args`` names this switch for speed. A NaN action
    still stops a run: the env refuses it with a clear error."""
    from torch.distributions import Distribution

    before = Distribution._validate_args  # the class default that setting replaces
    Distribution.set_default_validate_args(False)
    try:
        yield
    finally:
        Distribution.set_default_validate_args(before)


def env_kwargs(speed_m_s: float = TRAIN_SPEED_M_S, seeds: tuple[int, int] = TRAIN_SEEDS,
               track: str | int | None = None, camera: Any = "thesis",
               vehicle: str = "kinematic", timing: Any = "ideal") -> dict[str, Any]:
    """Arguments of the training env: a new generated track each reset from ``seeds``
    (or always ``track``), seen by ``camera`` (a profile name or file), the car
    ``vehicle`` with the pipeline's ``timing`` (a name, a timing file or a ``Timing``)."""
    return {"track": track, "track_seeds": seeds, "speed_m_s": speed_m_s, "camera": camera,
            "vehicle": vehicle, "timing": timing}


OUT_FILES: tuple[str, ...] = ("policy.zip", "train.json", "tb/", "checkpoints/")
"""What ``train`` writes into its ``out`` folder (folders end in ``/``)."""


def _progress_callback(total: int) -> Any:
    """A tqdm progress bar as an SB3 callback (SB3's own needs rich, which we do not
    depend on)."""
    from stable_baselines3.common.callbacks import BaseCallback
    from tqdm import tqdm

    class TqdmCallback(BaseCallback):
        def _on_training_start(self) -> None:
            # The rate is per env step, over the run so far (updates included): the
            # rollouts alone would flatter it.
            self.bar = tqdm(total=total, desc="train", unit="step", smoothing=0)

        def _on_step(self) -> bool:
            self.bar.update(self.training_env.num_envs)
            return True

        def _on_training_end(self) -> None:
            self.bar.close()

        def close(self) -> None:
            """Close the bar also when the training ended early (Ctrl-C)."""
            if hasattr(self, "bar"):
                self.bar.close()

    return TqdmCallback()


def _whole_checkpoints() -> type:
    """SB3's ``CheckpointCallback`` whose saves a Ctrl-C cannot cut: the stop is held
    until the checkpoint is written, then ends the training as anywhere else (a Ctrl-C
    inside torch's zip writer turned into a RuntimeError, an internal error)."""
    from stable_baselines3.common.callbacks import CheckpointCallback

    class WholeCheckpoints(CheckpointCallback):
        def _on_step(self) -> bool:
            if self.n_calls % self.save_freq:  # no checkpoint this step (most): no
                return super()._on_step()  # signal handlers swapped in the rollout
            with deferring_stops():
                return super()._on_step()

    return WholeCheckpoints


def _publish_run(staging: Path, out: Path) -> None:
    """Move a finished (or interrupted) run from its staging folder into ``out``: files
    replace files of the same name (policy.zip, train.json, checkpoints), and the
    TensorBoard run folder is added beside earlier ones under the next free name
    (PPO_2, …) — an earlier run's logs are never deleted."""
    out.mkdir(parents=True, exist_ok=True)
    for entry in staging.iterdir():
        target = out / entry.name
        if not entry.is_dir():
            os.replace(entry, target)
            continue
        target.mkdir(exist_ok=True)
        for child in entry.iterdir():
            dest = target / child.name
            if child.is_dir():
                stem, k = child.name.rsplit("_", 1) if "_" in child.name else (child.name, "1")
                n = int(k) if k.isascii() and k.isdigit() else 1
                while dest.exists():
                    n += 1
                    dest = target / f"{stem}_{n}"
            os.replace(child, dest)
    shutil.rmtree(staging, ignore_errors=True)


def _existing_ancestor(path: Path) -> Path:
    p = path.absolute().parent
    while not p.exists():
        p = p.parent
    return p


def train(timesteps: int, n_envs: int, seed: int, out: Path, *, config: PpoConfig | None = None,
          speed_m_s: float = TRAIN_SPEED_M_S, progress: bool = True,
          subprocess: bool = True, track: str | int | None = None, camera: str = "thesis",
          checkpoint_steps: int = 100_000, vehicle: str = "kinematic",
          timing: str = "ideal") -> dict[str, Any]:
    """Train PPO and save it under ``out``; returns the summary written to train.json.
    ``track`` fixes the track (default: the generated ``TRAIN_SEEDS``); ``camera`` is the
    car's camera (a profile name or file), ``vehicle`` its model and ``timing`` its
    pipeline's timing (a name or a timing file).

    The run is written to a staging folder beside ``out`` and moved into ``out`` when it
    ends: an error leaves ``out`` as it was. A Ctrl-C ends the training early and keeps
    the policy so far (``summary["interrupted"]``, ``summary["timesteps_done"]``); one
    while a checkpoint is written waits for it, one while the policy is saved is held
    (``holding_stops``: ``tfalda-sim train`` then exits 130)."""
    import cv2
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import CallbackList

    from .policy_file import save_policy
    from .vec_env import make_sb3_vec_env

    checkpoints = _whole_checkpoints()

    cfg = config or PpoConfig()
    out = Path(out)
    # One torch thread (restored at the end): during rollouts the env workers hold the
    # cores, and a 64-64 MLP's minibatch updates gain nothing from a second one.
    threads, cv2_threads = torch.get_num_threads(), cv2.getNumThreads()
    # Gradients on, whatever the caller's mode (restored at the end): a Ctrl-C landing
    # inside torch's no_grad exit in an earlier run in this process can leave them off.
    grad = torch.is_grad_enabled()
    torch.set_grad_enabled(True)
    torch.set_num_threads(1)
    cv2.setNumThreads(1)  # this process steps envs too (the vector env's first slice)
    # Staged in the nearest existing folder (same file system, so the final moves are
    # renames): a failed or early-interrupted run creates no folder at all.
    staging = Path(tempfile.mkdtemp(prefix=".tfalda-sim-", suffix=".tmp",
                                    dir=_existing_ancestor(out)))
    shield = contextlib.ExitStack()  # after a Ctrl-C: ignore the next while saving
    try:
        # TfaldaTrackVectorEnv through SB3's VecEnv API: this process steps the first
        # slice of envs, a worker per further core the others (agents/vec_env.py).
        venv = make_sb3_vec_env(n_envs, seed, workers=None if subprocess else 1,
                                **env_kwargs(speed_m_s, track=track, camera=camera,
                                             vehicle=vehicle, timing=timing))
        interrupted = False
        try:
            lr = cfg.learning_rate
            model = PPO("MlpPolicy", venv, n_steps=cfg.n_steps, batch_size=cfg.batch_size,
                        n_epochs=cfg.n_epochs,
                        learning_rate=(lambda rest: rest * lr) if cfg.lr_decay else lr,
                        gamma=cfg.gamma, gae_lambda=cfg.gae_lambda, clip_range=cfg.clip_range,
                        ent_coef=cfg.ent_coef, target_kl=cfg.target_kl,
                        policy_kwargs={"net_arch": list(cfg.net_arch),
                                       "log_std_init": cfg.log_std_init},
                        seed=seed, device="cpu", verbose=0,
                        tensorboard_log=str(staging / "tb"))
            callbacks = [checkpoints(max(1, checkpoint_steps // n_envs),
                                     str(staging / "checkpoints"), name_prefix="ppo")]
            bar = None
            if progress:  # PPO learns in whole rollouts of n_steps per env
                rollout = cfg.n_steps * n_envs
                bar = _progress_callback(-(-timesteps // rollout) * rollout)
                callbacks.append(bar)
            t0 = time.perf_counter()
            try:
                with distribution_checks_off():
                    model.learn(timesteps, callback=CallbackList(callbacks))
            except INTERRUPTS as exc:
                if not is_interrupt(exc):
                    raise
                interrupted = True  # keep the policy so far
            finally:
                # From here the run is saved whole: a Ctrl-C while torch writes the
                # policy broke its zip writer ("unexpected pos"); it is held and noted.
                shield.enter_context(holding_stops())
                if bar is not None:
                    bar.close()
            elapsed = time.perf_counter() - t0
            # The architecture as JSON and the weights as tensors, not SB3's pickles: a
            # policy file must load without running code (policy_file.py). Into a file of
            # our own: a writer cut by an exception must not leak an open file.
            with (staging / "policy.zip").open("wb") as file:
                save_policy(model.policy, file)
        finally:
            # Also after a Ctrl-C: the workers ignore it, and a worker that a cut message
            # leaves waiting is terminated after 5 s (TfaldaTrackVectorEnv.close).
            venv.close()
        summary = _summary(timesteps, n_envs, seed, speed_m_s, track, cfg, elapsed, out,
                           camera, vehicle, timing)
        summary.update(interrupted=interrupted, timesteps_done=int(model.num_timesteps),
                       steps_per_s=model.num_timesteps / elapsed if elapsed > 0 else None)
        (staging / "train.json").write_text(json.dumps(summary, indent=2))
        _publish_run(staging, out)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
        shield.close()
        torch.set_num_threads(threads)
        torch.set_grad_enabled(grad)
        cv2.setNumThreads(cv2_threads)
    return summary


def _summary(timesteps: int, n_envs: int, seed: int, speed_m_s: float,
             track: str | int | None, cfg: PpoConfig, elapsed: float, out: Path,
             camera: str = "thesis", vehicle: str = "kinematic",
             timing: str = "ideal") -> dict[str, Any]:
    return {"timesteps": timesteps, "n_envs": n_envs, "seed": seed, "speed_m_s": speed_m_s,
            "camera": camera, "vehicle": vehicle, "timing": timing,
               "track": track, "train_seeds": list(TRAIN_SEEDS), "config": asdict(cfg) | {
                   "net_arch": list(cfg.net_arch)},
               "train_time_s": elapsed, "cores": os.cpu_count(),
               "python": platform.python_version(),
               # The CLI command that repeats this run (train()'s own arguments).
               "command": (f"tfalda-sim train --timesteps {timesteps} --n-envs {n_envs} "
                           f"--seed {seed} --speed {speed_m_s:g} --out {out}"
                           + (f" --camera {camera}" if camera != "thesis" else "")
                           + vehicle_flags(vehicle, timing)
                           + (f"  (Python: track={track!r})" if track is not None else ""))}


def vehicle_flags(vehicle: str, timing: str) -> str:
    """The ``--vehicle`` and ``--timing`` of a run's repeating command (none at their
    defaults)."""
    return ((f" --vehicle {vehicle}" if vehicle != "kinematic" else "")
            + (f" --timing {timing}" if timing != "ideal" else ""))
