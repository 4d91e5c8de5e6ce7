"""``gymnasium.make_vec("TfaldaTrack-v0", num_envs=N)``: N envs stepped by worker processes.

Gymnasium's ``AsyncVectorEnv`` runs one process per env and talks to each through a pipe
per step; on a 2-core machine two such envs ran *slower* than one (0.74×): every worker
let OpenCV start a thread per core (4 busy threads on 2 cores), and the parent spent a
core's share on per-env pipe round trips and on merging 14 info entries per env.

Here at most one worker process per core steps a slice of the envs in a loop (a batch:
one message per worker and step, not per env), OpenCV runs single-threaded in the workers
(the parallelism is the processes'), observations travel through shared memory, and the
parent merges the infos as flat columns. Everything else is Gymnasium's semantics:
``AutoresetMode.NEXT_STEP``, seeds ``seed + i`` for env ``i``, the infos of
``SyncVectorEnv`` (``key`` and ``_key`` arrays); a rollout equals ``SyncVectorEnv``'s bit for
bit. With one worker (one env, or one CPU) the envs run in this process.

Workers ignore Ctrl-C (the parent closes them) and die with the parent (Linux
``PR_SET_PDEATHSIG``), like the sweep workers of ``tfalda_sim.parallel``.
"""

from __future__ import annotations

import contextlib
import ctypes
import multiprocessing
import os
import signal
import sys
import traceback
from collections.abc import Sequence
from multiprocessing.connection import Connection
from typing import Any, ClassVar

import cv2
import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import (
    batch_space,
    create_shared_memory,
    read_from_shared_memory,
)

from tfalda_sim import ENV_ID, MAX_EPISODE_STEPS
from tfalda_sim.parallel import available_cpus

_PR_SET_PDEATHSIG = 1  # linux/prctl.h

_ERRORS: dict[str, type[Exception]] = {e.__name__: e for e in (
    ValueError, TypeError, RuntimeError, KeyError, AttributeError, NotImplementedError)}
"""Exceptions a worker's env may raise that the parent raises again as the same type."""


class TfaldaTrackVectorEnv(VectorEnv):
    """``num_envs`` copies of ``TfaldaTrack-v0`` (each with Gymnasium's ``TimeLimit`` of
    ``max_episode_steps``), stepped by ``workers`` processes (default: one per CPU this
    process may use, at most one per env; 1 runs them in this process). Every other
    keyword is ``TfaldaTrackEnv``'s.

    ``reset(seed=s)`` seeds env ``i`` with ``s + i`` (a list gives one seed per env);
    ``options`` go to every env. Autoreset: ``NEXT_STEP`` (the step after an episode
    ended resets that env and returns its first observation with reward 0)."""

    metadata: ClassVar[dict[str, Any]] = {"autoreset_mode": AutoresetMode.NEXT_STEP,
                                          "render_modes": ["rgb_array"]}

    def __init__(self, num_envs: int = 1, *, workers: int | None = None,
                 max_episode_steps: int = MAX_EPISODE_STEPS, **env_kwargs: Any) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, int | np.integer) or (
                num_envs < 1):
            raise ValueError(f"num_envs must be an int ≥ 1, got {num_envs!r}")
        if workers is not None and (isinstance(workers, bool) or not isinstance(
                workers, int | np.integer) or workers < 1):
            raise ValueError(f"workers must be None or an int ≥ 1, got {workers!r}")
        self.num_envs = int(num_envs)
        self._kwargs = {**env_kwargs, "max_episode_steps": max_episode_steps}
        probe = gym.make(ENV_ID, **self._kwargs)  # checks the arguments here, not in a worker
        self.single_observation_space = probe.observation_space
        self.single_action_space = probe.action_space
        self.render_mode = probe.render_mode
        self.metadata = {**self.metadata, "render_fps": probe.metadata["render_fps"]}
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        n_workers = min(self.num_envs, workers if workers is not None else available_cpus())
        # Contiguous slices: worker w steps envs slices[w]:slices[w + 1].
        self._slices = np.linspace(0, self.num_envs, n_workers + 1).round().astype(int)
        self._local: list[gym.Env] | None = None
        self._conns: list[Connection] = []
        self._procs: list[multiprocessing.process.BaseProcess] = []
        self._autoreset = np.zeros(self.num_envs, dtype=np.bool_)
        self.closed = False
        if n_workers == 1:
            self._local = [probe] + [gym.make(ENV_ID, **self._kwargs)
                                     for _ in range(self.num_envs - 1)]
            self._observations = self.observation_space.sample()  # batch buffer, overwritten
            return
        probe.close()
        # spawn, not fork: a fork copies OpenCV's thread pool mid-state (a worker then hung
        # in cv2.setNumThreads); spawned workers are still our children (PR_SET_PDEATHSIG).
        ctx = multiprocessing.get_context("spawn")
        self._shm = create_shared_memory(self.single_observation_space, self.num_envs, ctx)
        self._observations = read_from_shared_memory(self.single_observation_space,
                                                      self._shm, self.num_envs)
        for w in range(n_workers):
            parent, child = ctx.Pipe()
            proc = ctx.Process(target=_worker, name=f"tfalda-vec-{w}", daemon=True, args=(
                child, self._shm, self.single_observation_space, self.num_envs,
                self._kwargs, int(self._slices[w]), int(self._slices[w + 1]), os.getpid()))
            proc.start()
            child.close()
            self._conns.append(parent)
            self._procs.append(proc)
        self._gather("init")

    # ------------------------------------------------------------------ protocol
    def _send(self, command: str, per_worker: Sequence[Any]) -> None:
        for w, (conn, data) in enumerate(zip(self._conns, per_worker, strict=True)):
            try:
                conn.send((command, data))
            except (BrokenPipeError, ConnectionError, OSError):
                code = self._procs[w].exitcode
                self.close()
                raise RuntimeError(f"worker {w} of the vector env died (exit code {code}); "
                                   "make a new one with gymnasium.make_vec") from None

    def _gather(self, command: str) -> list[Any]:
        """Every worker's answer; a worker's error raised here (after all have answered, so
        the pipes stay in step)."""
        answers, error = [], None
        for w, conn in enumerate(self._conns):
            try:
                ok, data = conn.recv()
            except (EOFError, ConnectionError):
                ok, data = False, ("RuntimeError", f"worker {w} of the vector env died "
                                   f"(exit code {self._procs[w].exitcode})", "")
            if ok:
                answers.append(data)
            elif error is None:
                error = data
        if error is not None:
            name, message, trace = error
            if command == "init" or name not in _ERRORS:
                self.close()
                raise RuntimeError(f"{name} in a worker of the vector env: {message}\n{trace}")
            raise _ERRORS[name](message)
        return answers

    def _per_worker(self, values: Sequence[Any]) -> list[Sequence[Any]]:
        s = self._slices
        return [values[s[w]:s[w + 1]] for w in range(len(self._conns))]

    # ------------------------------------------------------------------ gymnasium API
    def reset(self, *, seed: int | Sequence[int | None] | None = None,
              options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        self._check_open()
        if seed is None:
            seeds: list[int | None] = [None] * self.num_envs
        elif isinstance(seed, int | np.integer) and not isinstance(seed, bool):
            seeds = [int(seed) + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)  # type: ignore[arg-type]
            if len(seeds) != self.num_envs:
                raise ValueError(f"reset(seed=…) needs one seed per env ({self.num_envs}), "
                                 f"got {len(seeds)}")
        self._autoreset[:] = False
        if self._local is not None:
            infos: list[dict[str, Any]] = []
            for i, (env, s) in enumerate(zip(self._local, seeds, strict=True)):
                obs, info = env.reset(seed=s, options=options)
                _write(self.single_observation_space, self._observations, i, obs)
                infos.append(info)
        else:
            self._send("reset", [(chunk, options) for chunk in self._per_worker(seeds)])
            infos = [info for answer in self._gather("reset") for info in answer]
        return _copy(self._observations), _merge_infos(infos)

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray,
                                          dict[str, Any]]:
        self._check_open()
        acts = np.asarray(actions)
        if acts.shape[:1] != (self.num_envs,):
            raise ValueError(f"actions must have shape {self.action_space.shape} (one action "
                             f"per env), got {acts.shape}")
        if self._local is not None:
            results = [_step_one(env, self.single_observation_space, self._observations, i,
                                 acts[i], bool(self._autoreset[i]))
                       for i, env in enumerate(self._local)]
        else:
            self._send("step", [(chunk, self._autoreset[s:e]) for chunk, s, e in zip(
                self._per_worker(acts), self._slices[:-1], self._slices[1:], strict=True)])
            results = [r for answer in self._gather("step") for r in answer]
        rewards = np.array([r[0] for r in results], dtype=np.float64)
        terminated = np.array([r[1] for r in results], dtype=np.bool_)
        truncated = np.array([r[2] for r in results], dtype=np.bool_)
        self._autoreset = terminated | truncated
        return (_copy(self._observations), rewards, terminated, truncated,
                _merge_infos([r[3] for r in results]))

    def call(self, name: str, *args: Any, **kwargs: Any) -> tuple[Any, ...]:
        """``getattr(env, name)(*args, **kwargs)`` on every env (or the attribute's value if
        it is not callable), in env order."""
        self._check_open()
        if self._local is not None:
            return tuple(_call(env, name, args, kwargs) for env in self._local)
        self._send("call", [(name, args, kwargs)] * len(self._conns))
        return tuple(r for answer in self._gather("call") for r in answer)

    def get_attr(self, name: str) -> tuple[Any, ...]:
        return self.call(name)

    def render(self) -> tuple[Any, ...] | None:
        return self.call("render")

    def close_extras(self, **kwargs: Any) -> None:
        if self._local is not None:
            for env in self._local:
                env.close()
            self._local = []
            return
        for conn in self._conns:
            with contextlib.suppress(OSError, BrokenPipeError):
                conn.send(("close", None))
        for proc in self._procs:
            proc.join(timeout=5.0)
            if proc.is_alive():
                proc.terminate()
                proc.join(timeout=5.0)
        for conn in self._conns:
            conn.close()
        self._conns, self._procs = [], []

    def close(self, **kwargs: Any) -> None:
        if self.closed:
            return
        self.close_extras(**kwargs)
        self.closed = True

    def _check_open(self) -> None:
        if self.closed:
            raise RuntimeError("the vector env is closed; make a new one with "
                               "gymnasium.make_vec")

    def __del__(self) -> None:
        with contextlib.suppress(Exception):
            if not getattr(self, "closed", True):
                self.close()


def make_vector_env(num_envs: int = 1, **kwargs: Any) -> TfaldaTrackVectorEnv:
    """The ``vector_entry_point`` of ``TfaldaTrack-v0`` (what ``gymnasium.make_vec`` calls
    when no ``vectorization_mode`` is given)."""
    return TfaldaTrackVectorEnv(num_envs, **kwargs)


# ---------------------------------------------------------------------- shared pieces
def _write(space: gym.Space, buffer: Any, index: int, obs: Any) -> None:
    """Env ``index``'s observation into the batch ``buffer`` (arrays or a dict of them)."""
    if isinstance(space, gym.spaces.Dict):
        for key, sub in space.spaces.items():
            _write(sub, buffer[key], index, obs[key])
    else:
        buffer[index] = obs


def _copy(batch: Any) -> Any:
    """A copy of the batch buffer (the next step overwrites it), as Gymnasium's vector
    envs return by default."""
    if isinstance(batch, dict):
        return {key: _copy(value) for key, value in batch.items()}
    return batch.copy()


def _step_one(env: gym.Env, space: gym.Space, buffer: Any, index: int, action: np.ndarray,
              autoreset: bool) -> tuple[float, bool, bool, dict[str, Any]]:
    """One env's step with NEXT_STEP autoreset, its observation written to ``buffer``."""
    if autoreset:
        obs, info = env.reset()
        reward, terminated, truncated = 0.0, False, False
    else:
        obs, reward, terminated, truncated, info = env.step(action)
    _write(space, buffer, index, obs)
    return float(reward), bool(terminated), bool(truncated), info


def _call(env: gym.Env, name: str, args: tuple, kwargs: dict[str, Any]) -> Any:
    attr = env.get_wrapper_attr(name)
    return attr(*args, **kwargs) if callable(attr) else attr


def _merge_infos(infos: list[dict[str, Any]]) -> dict[str, Any]:
    """``SyncVectorEnv``'s info layout (``key``: an array over envs, ``_key``: which envs
    have it), built column by column: every env of ours reports the same keys."""
    n = len(infos)
    merged: dict[str, Any] = {}
    keys = list(infos[0]) if infos else []
    if any(list(info) != keys for info in infos[1:]):  # not ours (a wrapper's?): general path
        keys = list(dict.fromkeys(k for info in infos for k in info))
    all_present = np.ones(n, dtype=np.bool_)
    for key in keys:
        values = [info.get(key, _MISSING) for info in infos]
        kind = type(values[0])
        if kind in (int, float, bool) and all(type(v) is kind for v in values):
            # The common case in one call: every env has the key, a plain scalar.
            merged[key] = np.array(values, dtype=kind)
            merged[f"_{key}"] = all_present.copy()
            continue
        first = next(v for v in values if v is not _MISSING)
        mask = np.array([v is not _MISSING for v in values], dtype=np.bool_)
        if isinstance(first, dict):
            present = [v if v is not _MISSING else {} for v in values]
            merged[key], merged[f"_{key}"] = _merge_infos(present), mask
            continue
        if type(first) in (int, float, bool) or isinstance(first, np.number):
            column = np.zeros(n, dtype=type(first))
        elif isinstance(first, np.ndarray):
            column = np.zeros((n, *first.shape), dtype=first.dtype)
        else:
            column = np.full(n, fill_value=None, dtype=object)
        for i, v in enumerate(values):
            if v is not _MISSING:
                column[i] = v
        merged[key] = column
        merged[f"_{key}"] = mask
    return merged


_MISSING = object()


def _worker(conn: Connection, shm: Any, space: gym.Space,
            num_envs: int, kwargs: dict[str, Any], start: int, stop: int,
            parent_pid: int) -> None:
    """A worker: envs ``start:stop`` of the vector env, commands from ``conn``."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    if os.getppid() != parent_pid:
        os._exit(1)
    # One OpenCV thread: the processes are the parallelism; OpenCV's pool of one thread per
    # core in every worker oversubscribed the cores (the 0.74× of two async envs).
    cv2.setNumThreads(1)
    buffer = read_from_shared_memory(space, shm, num_envs)  # the whole batch
    envs: list[gym.Env] = []
    try:
        envs = [gym.make(ENV_ID, **kwargs) for _ in range(start, stop)]
        conn.send((True, None))
        while True:
            command, data = conn.recv()
            try:
                if command == "step":
                    actions, autoreset = data
                    answer: Any = [_step_one(env, space, buffer, start + i, actions[i],
                                             bool(autoreset[i]))
                                   for i, env in enumerate(envs)]
                elif command == "reset":
                    seeds, options = data
                    answer = []
                    for i, (env, s) in enumerate(zip(envs, seeds, strict=True)):
                        obs, info = env.reset(seed=s, options=options)
                        _write(space, buffer, start + i, obs)
                        answer.append(info)
                elif command == "call":
                    name, args, kw = data
                    answer = [_call(env, name, args, kw) for env in envs]
                elif command == "close":
                    break
                else:
                    raise RuntimeError(f"unknown command {command!r}")
                conn.send((True, answer))
            except Exception as exc:  # reported to the parent, raised there
                conn.send((False, (type(exc).__name__, str(exc), traceback.format_exc())))
    except (EOFError, KeyboardInterrupt, BrokenPipeError):
        pass
    except Exception as exc:  # set-up failed
        with contextlib.suppress(Exception):
            conn.send((False, (type(exc).__name__, str(exc), traceback.format_exc())))
    finally:
        for env in envs:
            with contextlib.suppress(Exception):
                env.close()
        conn.close()
