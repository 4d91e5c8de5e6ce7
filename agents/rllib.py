"""PPO with RLlib (Ray) on TfaldaTrack-v0: the same training as ``agents/train.py``, on a
local Ray or a Ray cluster.

    tfalda-sim train --backend rllib --timesteps 1000000 --env-runners 2 --out runs/rllib
    tfalda-sim train --backend rllib --ray-address auto --env-runners 32 --out runs/rllib

The env is registered with ``ray.tune.register_env`` under ``ENV_NAME``; its factory
imports ``tfalda_sim`` inside the Ray worker, so every node needs tfalda-sim installed
(the ``rllib`` extra). Writes ``OUT/checkpoint/`` (an RLlib Algorithm checkpoint, the
last finished iteration's) and ``OUT/train.json`` (the run and every iteration's env
steps, steps/s and mean episode return). Uses RLlib's current API stack (RLModule,
Learner, EnvRunner).
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import os
import platform
import shutil
import signal
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from tfalda_sim.interrupts import INTERRUPTS, STOP_SIGNALS, ignoring_stops, is_interrupt
from tfalda_sim.parallel import RayUnavailable, check_ray_address

from .train import TRAIN_SEEDS, TRAIN_SPEED_M_S, PpoConfig, env_kwargs, vehicle_flags

ENV_NAME: str = "tfalda-sim/TfaldaTrack-v0"
"""The env's name in Ray Tune's registry (what ``PPOConfig.environment`` is given)."""

RLLIB_EXTRA_HINT: str = "pip install 'tfalda-sim[rllib]'"
"""How to get RLlib: the optional extra."""

OUT_FILES: tuple[str, ...] = ("checkpoint/", "train.json")
"""What ``train_rllib`` writes into its ``out`` folder (folders end in ``/``)."""

CHECKPOINT_MODULE: tuple[str, ...] = ("learner_group", "learner", "rl_module", "default_policy")
"""Where an Algorithm checkpoint keeps the policy's RLModule (RLlib's component names)."""


class RllibUnavailable(RuntimeError):
    """RLlib (or one of its dependencies) is not installed, or Ray cannot be reached."""


def import_rllib() -> Any:
    """The ``ray`` module with RLlib importable, or ``RllibUnavailable`` naming the extra."""
    try:
        import ray
        import ray.rllib.algorithms.ppo  # RLlib's own dependencies (dm_tree, …) too
        import ray.tune
    except ImportError as exc:
        raise RllibUnavailable(f"--backend rllib needs RLlib ({exc.name or exc} is missing): "
                               f"{RLLIB_EXTRA_HINT}") from None
    return ray


@dataclass(frozen=True)
class RllibConfig:
    """How RLlib trains: ``PpoConfig``'s hyper-parameters mapped onto RLlib's PPO, plus
    the sampling set-up. ``train_batch`` env steps are collected per iteration by
    ``env_runners`` Ray actors (0: in the driver), then ``ppo.n_epochs`` passes of
    mini-batches of ``ppo.batch_size``. RLlib takes the learning rate as a constant: the
    sb3 path's linear decay (``lr_decay``) and its initial action noise
    (``log_std_init``) are not mapped."""

    train_batch: int = 2048  # env steps per iteration (RLlib has no n_steps × n_envs)
    env_runners: int = 2
    ppo: PpoConfig = field(default_factory=PpoConfig)

    def __post_init__(self) -> None:
        if self.train_batch < 1 or self.env_runners < 0:
            raise ValueError(f"need train_batch ≥ 1 and env_runners ≥ 0, got "
                             f"{self.train_batch} and {self.env_runners}")


def make_env(config: Any) -> Any:
    """The factory given to ``tune.register_env``: runs in each Ray worker, so it imports
    tfalda_sim there (registering ``TfaldaTrack-v0`` in that process) and makes the env
    through the registered id (Gymnasium's TimeLimit ends episodes after
    MAX_EPISODE_STEPS). ``config`` (an RLlib EnvContext, a dict) holds the env's
    keyword arguments."""
    import gymnasium

    import tfalda_sim  # noqa: F401  (registers the env id in this worker)

    return gymnasium.make("tfalda_sim:TfaldaTrack-v0", **dict(config))


def register_env() -> None:
    """Register ``make_env`` under ``ENV_NAME`` with Ray Tune (in this process; Ray ships
    the registry to the workers it starts)."""
    from ray.tune import register_env as tune_register_env

    tune_register_env(ENV_NAME, make_env)


def env_config(speed_m_s: float = TRAIN_SPEED_M_S, track: str | int | None = None,
               camera: str = "thesis", vehicle: str = "kinematic",
               timing: str = "ideal") -> dict[str, Any]:
    """The env's keyword arguments as RLlib's ``env_config``: sb3's (``env_kwargs``: a new
    generated track each reset from ``TRAIN_SEEDS``, or always ``track``; the camera) and
    the observation mode, "lanes" (the lane entries, speed and wheel angle). A camera
    file is read here and shipped as the camera itself: a cluster's nodes need not have
    the file; so is a timing file (``vehicle`` and ``timing`` as the env's)."""
    from tfalda_sim.camera import NAMED_CAMERAS, load_camera
    from tfalda_sim.timing import TIMINGS, load_timing

    cam: Any = camera if camera in NAMED_CAMERAS else load_camera(camera)
    tim: Any = timing if timing in TIMINGS else load_timing(timing)
    return env_kwargs(speed_m_s, TRAIN_SEEDS, track=track, camera=cam, vehicle=vehicle,
                      timing=tim) | {"observation": "lanes"}


def ppo_config(env_cfg: dict[str, Any], cfg: RllibConfig, seed: int) -> Any:
    """RLlib's ``PPOConfig`` (current API stack) for ``env_cfg``: ``PpoConfig``'s
    hyper-parameters, CPU only, a 64-64 MLP; an env runner that fails is an error, not
    restarted (a broken env would otherwise sample nothing, silently, forever); no
    sampling time-out: RLlib's default (60 s) ends a slow sample early with no steps, and
    an env runner's first sample (kernels compiled or loaded from the cache, on a busy
    host) can take longer, leaving an iteration that trained on nothing."""
    from ray.rllib.algorithms.ppo import PPOConfig

    p = cfg.ppo
    return (PPOConfig()
            .environment(ENV_NAME, env_config=env_cfg)
            .env_runners(num_env_runners=cfg.env_runners, num_envs_per_env_runner=1,
                         num_cpus_per_env_runner=1, sample_timeout_s=None)
            .learners(num_learners=0, num_gpus_per_learner=0)
            .training(train_batch_size_per_learner=cfg.train_batch,
                      minibatch_size=min(p.batch_size, cfg.train_batch), num_epochs=p.n_epochs,
                      lr=p.learning_rate, gamma=p.gamma, lambda_=p.gae_lambda,
                      clip_param=p.clip_range, entropy_coeff=p.ent_coef,
                      # as stable-baselines3: no KL penalty, gradients clipped at 0.5
                      use_kl_loss=False, grad_clip=0.5)
            .rl_module(model_config={"fcnet_hiddens": list(p.net_arch),
                                     "fcnet_activation": "tanh"})
            .fault_tolerance(restart_failed_env_runners=False)
            .debugging(seed=seed, log_level="ERROR"))


@dataclass(frozen=True)
class Iteration:
    """One finished training iteration, as reported."""

    iteration: int
    env_steps: int  # sampled in this iteration
    env_steps_total: int
    time_s: float
    steps_per_s: float
    episode_return_mean: float | None  # RLlib's mean over its last 100 episodes; None: none yet
    episodes_total: int


def _iteration(result: dict[str, Any], k: int, steps_before: int, time_s: float) -> Iteration:
    runners = result.get("env_runners", {})
    total = int(runners.get("num_env_steps_sampled_lifetime",
                            result.get("num_env_steps_sampled_lifetime", 0)))
    ret = runners.get("episode_return_mean")
    ret = float(ret) if ret is not None and math.isfinite(float(ret)) else None
    steps = total - steps_before
    return Iteration(iteration=k, env_steps=steps, env_steps_total=total, time_s=time_s,
                     steps_per_s=steps / time_s if time_s > 0 else 0.0,
                     episode_return_mean=ret,
                     episodes_total=int(runners.get("num_episodes_lifetime", 0)))


def _report(it: Iteration) -> str:
    ret = "–" if it.episode_return_mean is None else f"{it.episode_return_mean:.1f}"
    return (f"{it.env_steps_total} steps, {it.steps_per_s:.0f} steps/s, "
            f"mean episode return {ret}")


def _wait_for(event: threading.Event) -> None:
    """Wait for ``event`` in short steps: a Ctrl-C reaches the main thread at once."""
    while not event.wait(0.1):
        pass


@contextlib.contextmanager
def _keeping_stop_handlers() -> Iterator[None]:
    """Put the stop signals' handlers back after the block: connecting to Ray installs
    its C++ crash handler for SIGTERM (which aborts the process, leaving Ray's processes
    behind) and, in the main thread, a Python SIGTERM handler of its own; the CLI's
    clean stop (``tfalda_sim.interrupts``) must stay. A no-op outside the main thread."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    saved = {sig: signal.getsignal(sig) for sig in STOP_SIGNALS}
    try:
        yield
    finally:
        for sig, handler in saved.items():
            if handler is not None:  # None: not set from Python, nothing to put back
                signal.signal(sig, handler)


def _ray_error(address: str | None, exc: BaseException) -> RllibUnavailable:
    """The sweeps' one line for a failed ``ray.init`` (Ray's own advice names flags we do
    not have)."""
    from tfalda_sim.parallel import ray_init_failure

    return RllibUnavailable(ray_init_failure(address, exc))


@contextlib.contextmanager
def ray_session(address: str | None, num_cpus: int) -> Iterator[None]:
    """Connected to the Ray cluster at ``address`` ("auto", HOST:PORT) or to a local Ray
    with ``num_cpus`` CPUs started for the block and shut down after it. An already
    connected Ray is used as it is. Raises ``RllibUnavailable`` when Ray cannot start.

    A local Ray is started by a helper thread that lives until Ray is shut down: Ray ties
    its processes to the thread that started them (they die with it), a Ctrl-C in the
    middle of ``ray.init`` in the main thread would leave the processes it had started
    unknown to ``ray.shutdown`` (here the interrupt waits for the start, then shuts Ray
    down), and ``ray.init`` in the main thread replaces the SIGTERM handler, which must
    stay the CLI's clean stop."""
    import ray

    if ray.is_initialized():
        yield
        return
    kwargs: dict[str, Any] = {"include_dashboard": False, "logging_level": logging.ERROR,
                              "log_to_driver": False}
    if address is not None:
        try:
            check_ray_address(address)
        except RayUnavailable as exc:
            raise RllibUnavailable(str(exc)) from None
        try:
            with _keeping_stop_handlers():
                ray.init(address=address, **kwargs)
        except (ConnectionError, RuntimeError, ValueError, TimeoutError) as exc:
            with contextlib.suppress(Exception):
                ray.shutdown()
            raise _ray_error(address, exc) from None
        except BaseException:
            with ignoring_stops(), contextlib.suppress(Exception):
                ray.shutdown()  # a half-made connection
            raise
        try:
            yield
        finally:
            with ignoring_stops():
                ray.shutdown()
        return

    failure: list[BaseException] = []
    ready, release = threading.Event(), threading.Event()

    def hold() -> None:
        try:
            # "local": a new Ray even if RAY_ADDRESS names a cluster (that is --ray-address)
            ray.init(address="local", num_cpus=num_cpus, **kwargs)
        except BaseException as exc:  # reported in the main thread
            failure.append(exc)
        ready.set()
        release.wait()

    # Ray warns that it sets no SIGTERM handler outside the main thread: that is the point.
    worker_log = logging.getLogger("ray._private.worker")
    level = worker_log.level
    worker_log.setLevel(logging.ERROR)
    thread = threading.Thread(target=hold, name="ray-session", daemon=True)
    try:
        try:
            with _keeping_stop_handlers():
                thread.start()
                try:
                    _wait_for(ready)
                except BaseException:
                    with ignoring_stops():
                        _wait_for(ready)
                    raise
        finally:
            worker_log.setLevel(level)
        if failure:
            exc = failure[0]
            if isinstance(exc, (ConnectionError, RuntimeError, ValueError, TimeoutError)):
                raise _ray_error(None, exc) from None
            raise exc
        yield
    finally:
        with ignoring_stops():
            ray.shutdown()
            release.set()
            if thread.ident is not None:  # started
                thread.join()


def _save_checkpoint(algo: Any, staging: Path) -> None:
    """The algorithm's state as ``staging/checkpoint``, replacing the last one only once
    the new one is complete (a Ctrl-C while saving keeps the previous iteration's)."""
    new, old, final = staging / "checkpoint.new", staging / "checkpoint.old", staging / "checkpoint"
    shutil.rmtree(new, ignore_errors=True)
    algo.save_to_path(str(new))
    with ignoring_stops():
        if final.exists():
            os.replace(final, old)
        os.replace(new, final)
        shutil.rmtree(old, ignore_errors=True)


def _publish(staging: Path, out: Path) -> None:
    """Move ``checkpoint/`` and ``train.json`` from ``staging`` into ``out``: an earlier
    run's checkpoint folder is replaced as a whole (its files must not mix with the new
    ones), train.json replaced."""
    out.mkdir(parents=True, exist_ok=True)
    if (staging / "checkpoint").is_dir():
        target = out / "checkpoint"
        if target.exists():
            os.replace(target, staging / "checkpoint.old")
        os.replace(staging / "checkpoint", target)
    os.replace(staging / "train.json", out / "train.json")


def _runner_error(exc: BaseException) -> str | None:
    """What failed, in one line, if ``exc`` is a Ray actor/task failure (an env that
    raised in a worker, a worker that died); None for anything else."""
    from ray import exceptions as rex

    if isinstance(exc, rex.RayTaskError):
        cause = exc.cause if isinstance(exc.cause, BaseException) else exc
        text = str(cause).strip().splitlines()
        return f"{type(cause).__name__}: {text[-1] if text else ''}".rstrip(": ")
    if isinstance(exc, rex.RayError):
        text = str(exc).strip().splitlines()
        return f"{type(exc).__name__}: {text[0] if text else ''}".rstrip(": ")
    return None


def train_rllib(timesteps: int, seed: int, out: Path, *, config: RllibConfig | None = None,
                speed_m_s: float = TRAIN_SPEED_M_S, track: str | int | None = None,
                camera: str = "thesis", address: str | None = None,
                num_cpus: int | None = None, progress: bool = True,
                vehicle: str = "kinematic", timing: str = "ideal",
                on_iteration: Callable[[Iteration, int], None] | None = None
                ) -> dict[str, Any]:
    """Train PPO with RLlib for ``ceil(timesteps / train_batch)`` iterations and save it
    under ``out``; returns the summary written to train.json. ``address`` a Ray cluster
    ("auto", HOST:PORT; None: a local Ray with ``num_cpus`` CPUs, default the env runners'
    and at least 2); ``progress``: a bar and a line per iteration (env steps, steps/s, mean
    episode return) on stderr; ``on_iteration(it, iterations)`` after each iteration.

    Staged beside ``out`` and moved in at the end: an error before the first iteration
    leaves ``out`` as it was. A Ctrl-C, or an env runner that fails, ends the training
    early and keeps the checkpoint of the last finished iteration
    (``summary["interrupted"]``, ``summary["failed"]``)."""
    from .train import _existing_ancestor

    cfg = config or RllibConfig()
    out = Path(out)
    iterations = max(1, -(-timesteps // cfg.train_batch))
    ray = import_rllib()
    register_env()
    env_cfg = env_config(speed_m_s, track, camera, vehicle, timing)
    session = contextlib.ExitStack()  # Ray, shut down last
    shield = contextlib.ExitStack()  # after a Ctrl-C: ignore the next while saving
    algo = None
    done: list[Iteration] = []
    interrupted, failed = False, None
    rllib_log = logging.getLogger("ray.rllib")
    log_level = rllib_log.level
    rllib_log.setLevel(logging.ERROR)  # its start-up notes are not the user's business
    # Staged in the nearest existing folder (same file system: the final moves are renames).
    staging = Path(tempfile.mkdtemp(prefix=".tfalda-sim-", suffix=".tmp",
                                    dir=_existing_ancestor(out)))
    try:
        session.enter_context(ray_session(address, num_cpus or max(2, cfg.env_runners)))
        cpus = int(ray.cluster_resources().get("CPU", 0))
        if cfg.env_runners > cpus:
            where = f"the Ray cluster at {address}" if address else "this Ray"
            raise RllibUnavailable(f"--env-runners {cfg.env_runners} needs as many CPUs; "
                                   f"{where} has {cpus}")
        bar = tqdm(total=iterations, desc="train", unit="it", disable=not progress)
        shield.callback(bar.close)
        t_start = time.perf_counter()
        try:
            try:
                algo = ppo_config(env_cfg, cfg, seed).build_algo()
            except Exception as exc:  # e.g. a node without tfalda-sim, an env that raises
                if is_interrupt(exc):
                    raise
                text = str(exc).strip().splitlines()
                raise RllibUnavailable(f"RLlib could not start its env runners: "
                                       f"{type(exc).__name__}: {text[-1] if text else ''}"
                                       ) from None
            steps = 0
            for k in range(1, iterations + 1):
                t0 = time.perf_counter()
                result = algo.train()
                it = _iteration(result, k, steps, time.perf_counter() - t0)
                steps = it.env_steps_total
                _save_checkpoint(algo, staging)
                done.append(it)
                if progress:  # a line per iteration stays in the log (a cluster run's)
                    bar.write(f"iteration {k}/{iterations}: {_report(it)}", file=sys.stderr)
                    bar.set_postfix_str(_report(it), refresh=False)
                bar.update()
                if on_iteration is not None:
                    on_iteration(it, iterations)
        except INTERRUPTS as exc:
            if not is_interrupt(exc):
                raise
            interrupted = True  # keep the last finished iteration
            shield.enter_context(ignoring_stops())
        except RllibUnavailable:
            raise
        except Exception as exc:
            failed = _runner_error(exc)
            if failed is None:
                raise
        elapsed = time.perf_counter() - t_start
        if not done:
            if interrupted:
                raise KeyboardInterrupt
            raise RllibUnavailable(f"the training failed before its first iteration: {failed}")
        summary = _summary(timesteps, seed, speed_m_s, track, camera, cfg, address, out,
                           iterations, done, elapsed, vehicle, timing)
        summary.update(interrupted=interrupted, failed=failed)
        (staging / "train.json").write_text(json.dumps(summary, indent=2))
        _publish(staging, out)
    finally:
        with ignoring_stops():
            if algo is not None:
                with contextlib.suppress(Exception):
                    algo.stop()
            session.close()
            shutil.rmtree(staging, ignore_errors=True)
            rllib_log.setLevel(log_level)
        shield.close()
    return summary


def _summary(timesteps: int, seed: int, speed_m_s: float, track: str | int | None,
             camera: str, cfg: RllibConfig, address: str | None, out: Path, iterations: int,
             done: list[Iteration], elapsed: float, vehicle: str = "kinematic",
             timing: str = "ideal") -> dict[str, Any]:
    import ray

    cam = camera
    last = done[-1]
    return {"backend": "rllib", "timesteps": timesteps, "seed": seed, "speed_m_s": speed_m_s,
            "camera": cam, "vehicle": vehicle, "timing": timing, "track": track,
            "train_seeds": list(TRAIN_SEEDS),
            "iterations": iterations, "iterations_done": len(done),
            "timesteps_done": last.env_steps_total,
            "episode_return_mean": last.episode_return_mean,
            "config": {"train_batch": cfg.train_batch, "env_runners": cfg.env_runners,
                       **asdict(cfg.ppo), "net_arch": list(cfg.ppo.net_arch)},
            "ray_address": address, "ray": ray.__version__,
            "train_time_s": elapsed, "cores": os.cpu_count(),
            "python": platform.python_version(),
            "checkpoint": str(out / "checkpoint"),
            "history": [asdict(it) for it in done],
            # The CLI command that repeats this run (train_rllib()'s own arguments).
            "command": (f"tfalda-sim train --backend rllib --timesteps {timesteps} "
                        f"--env-runners {cfg.env_runners} --train-batch {cfg.train_batch} "
                        f"--seed {seed} --speed {speed_m_s:g} --out {out}"
                        + (f" --ray-address {address}" if address else "")
                        + (f" --camera {cam}" if cam != "thesis" else "")
                        + vehicle_flags(vehicle, timing)
                        + (f"  (Python: track={track!r})" if track is not None else ""))}


class RllibPolicy:
    """A policy trained by ``train_rllib``, from its checkpoint folder (no Ray needed):
    deterministic actions, the mean of the policy's Gaussian, clipped to [-1, 1]."""

    def __init__(self, checkpoint: str | Path) -> None:
        import_rllib()
        import torch
        from ray.rllib.core.rl_module.rl_module import RLModule

        module_dir = Path(checkpoint).joinpath(*CHECKPOINT_MODULE)
        if not module_dir.is_dir():
            raise FileNotFoundError(f"{checkpoint} is not an RLlib checkpoint of "
                                    f"`tfalda-sim train --backend rllib` (no {module_dir})")
        torch.set_num_threads(1)  # as PpoAgent: a policy this small gains nothing from more
        self.module = RLModule.from_checkpoint(str(module_dir))
        self._torch = torch

    def reset(self) -> None:
        pass

    def act(self, obs: np.ndarray) -> np.ndarray:
        from ray.rllib.core.columns import Columns

        batch = {Columns.OBS: self._torch.as_tensor(np.asarray(obs, np.float32)[None])}
        with self._torch.no_grad():
            out = self.module.forward_inference(batch)
        inputs = out[Columns.ACTION_DIST_INPUTS][0].numpy()
        mean = inputs[: inputs.shape[0] // 2]  # a diagonal Gaussian: means, then log-stds
        return np.clip(mean.astype(np.float32), -1.0, 1.0)
