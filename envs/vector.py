"""``gymnasium.make_vec("TfaldaTrack-v0", num_envs=N)``: N envs stepped in this process and
by worker processes, one per core.

Gymnasium's ``AsyncVectorEnv`` runs one process per env and talks to each through a pipe
per step; on a 2-core machine two such envs ran *slower* than one (0.74×): every worker
let OpenCV start a thread per core (4 busy threads on 2 cores), and the parent spent a
core's share on per-env pipe round trips and on merging 14 info entries per env.

Here the envs are cut into one slice per core: this process steps the first slice itself
while one worker process per further core steps each other slice (a batch: one message per
worker and step, not per env; a parent that only waited would leave its core idle, and a
2-env batch ran at 0.95–1.0× one env). OpenCV runs single-threaded in the workers (the
parallelism is the processes'), observations travel through shared memory, the waits
poll briefly before they block (``WAIT_SPIN_S``), and the parent merges the infos as
flat columns, its own envs' while it waits for the workers (``_MergeAhead``). On x86
the steps themselves go through shared memory too (``_Board``: actions, autoreset flags,
rewards, flags and the infos' numbers, handed over by a step number each side polls): a
pipe message cost ≈ 15 µs of system calls and wake-up here,
four per step and worker; the pipes carry everything else (resets, calls, errors, infos
the board cannot hold). Everything else is Gymnasium's semantics: ``AutoresetMode.NEXT_STEP`` (or
``SAME_STEP``, as SB3 needs), seeds ``seed + i`` for env ``i``, the infos of
``SyncVectorEnv`` (``key`` and ``_key`` arrays); a rollout equals ``SyncVectorEnv``'s bit
for bit. With one env, or one CPU, every env runs in this process.

Workers ignore Ctrl-C (the parent closes them) and die with the parent (Linux
``PR_SET_PDEATHSIG``), like the sweep workers of ``tfalda_sim.parallel``.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import multiprocessing
import os
import platform
import signal
import sys
import time
import traceback
from collections.abc import Callable, Sequence
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

WAIT_SPIN_S = 0.002
"""How long [s] a worker polls for its next command (and this process for the workers'
answers to other commands than steps: it spins for a step's, the workers are stepping)
before blocking. The wait between two steps is this process's own env step plus
its overhead (≈ 1.5–2.5 ms); a process that blocks instead lets its core sleep, and on this
VM a woken core then stepped ≈ 30 % slower (cold caches) — 740 vs 810 steps/s with 2 envs.
Past the spin it blocks, so a long pause (a PPO update) costs ≤ 2 ms of a core per step."""

BOARD_NAP_S = 0.05
"""A worker idle past ``WAIT_SPIN_S`` sleeps on its pipe for at most this long [s] before
it looks at the step board again (a wake-up message ends the nap at once; the rare one
missed costs at most this)."""

_WAKE = ("wake", None)
"""The message that wakes a worker sleeping on its pipe (a step is on the board)."""

BOARD_INFO_SLOTS = 32
"""Numbers per env's info the shared step board holds (floats and ints each): an info
with more goes through the pipe."""

FAST_STEPS = platform.machine().lower() in ("x86_64", "amd64", "x86", "i386", "i686")
"""Whether steps go through the shared step board (``_Board``) instead of the pipes: its
hand-over (write the data, then the sequence number; read the number, then the data)
needs stores seen by the other core in program order, which x86 guarantees (TSO) and
weaker memory models (ARM, POWER) do not without fences Python cannot issue; there the
pipes carry every step."""

_ERRORS: dict[str, type[Exception]] = {e.__name__: e for e in (
    ValueError, TypeError, RuntimeError, KeyError, AttributeError, NotImplementedError)}
"""Exceptions a worker's env may raise that the parent raises again as the same type."""


class TfaldaTrackVectorEnv(VectorEnv):
    """``num_envs`` copies of ``TfaldaTrack-v0`` (each with Gymnasium's ``TimeLimit`` of
    ``max_episode_steps``), stepped by ``workers`` processes, this one included (default:
    one per CPU this process may use, at most one per env; 1 runs them all in this
    process, 2 in this process and one worker process, …). Every other keyword is
    ``TfaldaTrackEnv``'s.

    ``reset(seed=s)`` seeds env ``i`` with ``s + i`` (a list gives one seed per env);
    ``options`` go to every env. ``autoreset_mode``: ``NEXT_STEP`` (the step after an
    episode ended resets that env and returns its first observation with reward 0) or
    ``SAME_STEP`` (an episode's last step resets it and returns the new episode's first
    observation; the last one is in ``info["final_obs"]``, its info in
    ``info["final_info"]``)."""

    metadata: ClassVar[dict[str, Any]] = {"autoreset_mode": AutoresetMode.NEXT_STEP,
                                          "render_modes": ["rgb_array"]}

    def __init__(self, num_envs: int = 1, *, workers: int | None = None,
                 max_episode_steps: int = MAX_EPISODE_STEPS,
                 autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
                 **env_kwargs: Any) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, int | np.integer) or (
                num_envs < 1):
            raise ValueError(f"num_envs must be an int ≥ 1, got {num_envs!r}")
        if workers is not None and (isinstance(workers, bool) or not isinstance(
                workers, int | np.integer) or workers < 1):
            raise ValueError(f"workers must be None or an int ≥ 1, got {workers!r}")
        try:
            mode = AutoresetMode(autoreset_mode)
        except ValueError:
            mode = None
        if mode not in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP):
            raise ValueError(f"autoreset_mode must be {AutoresetMode.NEXT_STEP.value!r} or "
                             f"{AutoresetMode.SAME_STEP.value!r}, got {autoreset_mode!r}")
        self.autoreset_mode = mode
        self.num_envs = int(num_envs)
        self._kwargs = {**env_kwargs, "max_episode_steps": max_episode_steps}
        probe = gym.make(ENV_ID, **self._kwargs)  # checks the arguments here, not in a worker
        self.single_observation_space = probe.observation_space
        self.single_action_space = probe.action_space
        self.render_mode = probe.render_mode
        self.metadata = {**self.metadata, "render_fps": probe.metadata["render_fps"],
                         "autoreset_mode": mode}
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        lanes = min(self.num_envs, workers if workers is not None else available_cpus())
        # Contiguous slices: lane w steps envs slices[w]:slices[w + 1]; lane 0 is this
        # process (it would otherwise sit idle while the workers step), lanes 1… are workers.
        self._slices = np.linspace(0, self.num_envs, lanes + 1).round().astype(int)
        self._conns: list[Connection] = []
        self._procs: list[multiprocessing.process.BaseProcess] = []
        self._autoreset = np.zeros(self.num_envs, dtype=np.bool_)
        self._board: _Board | None = None  # the shared step board (workers, x86 only)
        self._seq = 0  # the last step posted on it
        self._known: list[tuple | None] = [None] * self.num_envs  # info layouts (_layout)
        self._piped = 0  # posted steps whose results a worker sent through its pipe
        self._pending: set[int] = set()  # workers whose answer to step _seq is not read
        self._layouts = [0] * (self.num_envs + 1)  # per worker, layouts learnt from it
        self.closed = False
        self._local: list[gym.Env] = [probe] + [
            gym.make(ENV_ID, **self._kwargs) for _ in range(1, int(self._slices[1]))]
        if lanes == 1:
            self._observations = self.observation_space.sample()  # batch buffer, overwritten
            return
        # spawn, not fork: a fork copies OpenCV's thread pool mid-state (a worker then hung
        # in cv2.setNumThreads); spawned workers are still our children (PR_SET_PDEATHSIG).
        ctx = multiprocessing.get_context("spawn")
        self._shm = create_shared_memory(self.single_observation_space, self.num_envs, ctx)
        self._observations = read_from_shared_memory(self.single_observation_space,
                                                      self._shm, self.num_envs)
        if FAST_STEPS and isinstance(self.single_action_space, gym.spaces.Box):
            self._board = _Board(ctx, self.num_envs, self.single_action_space.shape, lanes)
            self._idle = _Idle(self._board, 0, self._local)
        for w in range(1, lanes):
            parent, child = ctx.Pipe()
            proc = ctx.Process(target=_worker, name=f"tfalda-vec-{w}", daemon=True, args=(
                child, self._shm, self.single_observation_space, self.num_envs,
                self._kwargs, int(self._slices[w]), int(self._slices[w + 1]), os.getpid(),
                self._board, w))
            proc.start()
            child.close()
            self._conns.append(parent)
            self._procs.append(proc)
        self._gather("init")

    # ------------------------------------------------------------------ protocol
    def _run(self, command: str, per_lane: Sequence[Any],
             local: Callable[[Any], list[Any]]) -> list[Any]:
        """``command`` on every lane, in env order: the workers get ``per_lane[1:]`` first,
        this process runs ``local(per_lane[0])`` meanwhile. Whatever happens here (an
        error, a Ctrl-C in this process's own envs, a value that does not pickle), every
        worker that got the command is heard before it is raised: the pipes stay in
        step."""
        sent = 0
        try:
            for w, (conn, data) in enumerate(zip(self._conns, per_lane[1:], strict=True)):
                try:
                    conn.send((command, data))
                except (BrokenPipeError, ConnectionError, OSError):
                    code = self._procs[w].exitcode
                    self.close()
                    raise RuntimeError(f"worker {w + 1} of the vector env died (exit code "
                                       f"{code}); make a new one with gymnasium.make_vec"
                                       ) from None
                sent += 1
            answers = local(per_lane[0])
        except BaseException:
            self._drain(sent)
            raise
        for answer in self._gather(command):
            answers.extend(answer)
        return answers

    def _drain(self, n: int) -> None:
        """Read and drop the answers of the first ``n`` workers (after an error here)."""
        for w in range(1, n + 1):
            with contextlib.suppress(EOFError, ConnectionError, OSError):
                self._answer(w)

    def _answer(self, lane: int) -> tuple[bool, Any]:
        """Worker ``lane``'s answer ``(ok, data)`` to a pipe command. Answers to posted
        steps this process gave up on (a Ctrl-C while it waited) may come first: skipped,
        their info layouts learnt (the worker learnt them as it sent them)."""
        message = _receive(self._conns[lane - 1], WAIT_SPIN_S)
        while len(message) == 3:
            self._learn(lane, message)
            message = _receive(self._conns[lane - 1], WAIT_SPIN_S)
        return message

    def _gather(self, command: str) -> list[Any]:
        """Every worker's answer; a worker's error raised here (after all have answered, so
        the pipes stay in step)."""
        answers, error = [], None
        for w in range(len(self._conns)):
            try:
                ok, data = self._answer(w + 1)
            except (EOFError, ConnectionError):
                ok, data = False, ("RuntimeError", f"worker {w + 1} of the vector env died "
                                   f"(exit code {self._procs[w].exitcode})", "")
            if ok:
                answers.append(data)
            elif error is None:
                error = data
        if error is not None:
            self._raise(command, error)
        return answers

    def _raise(self, command: str, error: tuple[str, str, str]) -> None:
        """Raise a worker's error here: as the same type if it is one an env may raise,
        else (or during set-up) as a RuntimeError after closing the vector env."""
        name, message, trace = error
        if command == "init" or name not in _ERRORS:
            self.close()
            raise RuntimeError(f"{name} in a worker of the vector env: {message}\n{trace}")
        raise _ERRORS[name](message)

    def _step_posted(self, acts: np.ndarray, same_step: bool, merge: bool
                     ) -> tuple[list[tuple[float, bool, bool, dict[str, Any]]],
                                dict[str, Any] | None]:
        """A step through the board: the workers' actions and autoreset flags are
        written, then the step's number (the workers poll it), this process steps its own
        envs meanwhile and reads the workers' results from the board (or, for an info the
        board cannot hold, from the pipe). With ``merge``, this process's envs' infos are
        merged before it waits for the workers (``_MergeAhead``): the merged infos, or
        None where the workers' infos have another layout."""
        board = self._board
        assert board is not None
        n0 = int(self._slices[1])
        if self._pending:  # a step given up on (a Ctrl-C while waiting): its answers
            with contextlib.suppress(Exception):  # first, or a worker could miss it
                self._collect()
        self._pending = set(range(1, len(self._conns) + 1))
        board.actions[:] = acts
        board.autoreset[:] = self._autoreset
        board.ctrl[1] = same_step
        self._seq += 1
        board.ctrl[0] = self._seq  # last: it posts the step
        for w, conn in enumerate(self._conns, start=1):
            if board.ctrl[board.asleep + w]:  # past its spin: blocked on its pipe
                with contextlib.suppress(OSError):
                    conn.send(_WAKE)
        try:
            try:
                answers = _step_envs(self._local, self.single_observation_space,
                                     self._observations, 0, acts[:n0], self._autoreset[:n0],
                                     same_step, self._idle.mark)
            finally:  # also after an error: a worker preparing meanwhile stops
                board.ctrl[board.finished] = self._seq
            ahead = _MergeAhead.of(answers[0][3], self.num_envs) if merge else None
            if ahead is not None and not all(ahead.fill(i, a[3]) for i, a in enumerate(answers)):
                ahead = None
        except BaseException:
            with contextlib.suppress(Exception):
                self._collect()  # the workers' answers, dropped: the board stays in step
            raise
        for part in self._collect(self._idle):
            answers.extend(part)
        if ahead is not None and not all(ahead.fill(i, answers[i][3])
                                         for i in range(n0, self.num_envs)):
            ahead = None
        return answers, None if ahead is None else ahead.merged

    def _collect(self, idle: _Idle | None = None
                 ) -> list[list[tuple[float, bool, bool, dict[str, Any]]]]:
        """The results of the step last posted of every worker not heard yet (all of
        them, but after a Ctrl-C), in worker order; a worker's error raised after all
        have answered. ``idle``: what this process does while it waits (``_Idle``)."""
        board = self._board
        assert board is not None
        parts, error = [], None
        for w in sorted(self._pending):
            conn = self._conns[w - 1]
            start, stop = int(self._slices[w]), int(self._slices[w + 1])
            try:
                message = _await_answer(conn, board, w, self._seq, idle)
                # Pipe messages to other commands or steps than this one are answers this
                # process gave up on (a Ctrl-C while it waited): dropped, but the layouts
                # a worker sent are learnt (it learnt them as it sent them).
                while message is not None and (len(message) != 3 or message[2] != self._seq):
                    self._learn(w, message)
                    message = _await_answer(conn, board, w, self._seq)
            except (EOFError, ConnectionError):
                message = (False, ("RuntimeError", f"worker {w} of the vector env died (exit "
                                   f"code {self._procs[w - 1].exitcode})", ""), self._seq)
            self._pending.discard(w)
            if message is None:
                if board.ctrl[board.layouts + w] != self._layouts[w]:
                    # A layout sent through the pipe was lost (a Ctrl-C inside its
                    # reading): the board's numbers cannot be decoded.
                    self.close()
                    raise RuntimeError(
                        f"the vector env lost worker {w}'s info layout (a Ctrl-C while it "
                        "read one); make a new one with gymnasium.make_vec")
                parts.append(_read_results(board, start, stop, self._known))
                continue
            ok, data, _ = message
            if ok:
                self._piped += 1
                self._learn(w, message)
                parts.append(data)
            elif error is None:
                error = data
        if error is not None:
            self._raise("step", error)
        return parts

    def _learn(self, lane: int, message: tuple) -> None:
        """The info layouts of worker ``lane``'s envs from its pipe answer to a posted
        step (the worker learnt them as it sent it, and counts them: ``_layouts``);
        other messages teach nothing."""
        if len(message) == 3 and message[2] == self._seq:
            self._pending.discard(lane)  # the answer to the step last posted: heard
        if len(message) == 3 and message[0]:
            start, stop = int(self._slices[lane]), int(self._slices[lane + 1])
            self._known[start:stop] = [_layout(answer[3]) for answer in message[1]]
            self._layouts[lane] += 1

    def _indices(self, indices: Sequence[int]) -> list[int]:
        """``indices`` as a list of env numbers, each checked to be one of ours."""
        chosen = [int(i) for i in indices]
        if any(not 0 <= i < self.num_envs for i in chosen):
            raise ValueError(f"indices must lie in [0, {self.num_envs}), got {indices!r}")
        return chosen

    def _per_lane(self, values: Sequence[Any]) -> list[Sequence[Any]]:
        s = self._slices
        return [values[s[w]:s[w + 1]] for w in range(len(s) - 1)]

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
        space, buffer = self.single_observation_space, self._observations

        def local(chunk: Sequence[int | None]) -> list[dict[str, Any]]:
            return _reset_envs(self._local, space, buffer, 0, chunk, options)

        infos = self._run("reset", [(chunk, options) for chunk in self._per_lane(seeds)],
                          lambda data: local(data[0]))
        return _copy(self._observations), _merge_infos(infos)

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray,
                                          dict[str, Any]]:
        obs, rewards, terminated, truncated, infos, merged = self._step(actions, merge=True)
        return (obs, rewards, terminated, truncated,
                merged if merged is not None else _merge_infos(infos))

    def step_per_env(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray,
                                                  list[dict[str, Any]]]:
        """``step``, with each env's info as its own dict (a list in env order) instead of
        Gymnasium's merged columns: what stable-baselines3's ``VecEnv`` API wants, without
        merging the infos only to split them again (≈ 85 µs a step here, in the process
        that steps the first env and so sets the pace). The same dicts ``step`` merges;
        those of this process's envs are the envs' own: copy one before changing it."""
        return self._step(actions, merge=False)[:5]

    def _step(self, actions: Any, merge: bool
              ) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]],
                         dict[str, Any] | None]:
        """``step_per_env``, and with ``merge`` the merged infos where they could be
        merged while the workers stepped (``_MergeAhead``; else None)."""
        self._check_open()
        acts = np.asarray(actions)
        if acts.shape[:1] != (self.num_envs,):
            raise ValueError(f"actions must have shape {self.action_space.shape} (one action "
                             f"per env), got {acts.shape}")
        space, buffer = self.single_observation_space, self._observations
        same_step = self.autoreset_mode is AutoresetMode.SAME_STEP
        if self._board is not None and acts.dtype.kind == "f" and (
                acts.shape == self.action_space.shape):
            results, merged = self._step_posted(acts, same_step, merge)
        else:  # no board, or actions the envs will refuse (with their own message)
            results = self._run(
                "step", [(a, r, same_step) for a, r in zip(
                    self._per_lane(acts), self._per_lane(self._autoreset), strict=True)],
                lambda data: _step_envs(self._local, space, buffer, 0, *data))
            merged = None
        rewards = np.array([r[0] for r in results], dtype=np.float64)
        terminated = np.array([r[1] for r in results], dtype=np.bool_)
        truncated = np.array([r[2] for r in results], dtype=np.bool_)
        if not same_step:
            self._autoreset = terminated | truncated
        return (_copy(self._observations), rewards, terminated, truncated,
                [r[3] for r in results], merged)

    def call(self, name: str, *args: Any, **kwargs: Any) -> tuple[Any, ...]:
        """``getattr(env, name)(*args, **kwargs)`` on every env (or the attribute's value if
        it is not callable), in env order."""
        return self.call_on(range(self.num_envs), name, *args, **kwargs)

    def call_on(self, indices: Sequence[int], name: str, *args: Any, **kwargs: Any
                ) -> tuple[Any, ...]:
        """``call`` on the envs ``indices`` only, their answers in that order."""
        return self._call_on(indices, name, args, kwargs, invoke=True)

    def get_attr_on(self, indices: Sequence[int], name: str) -> tuple[Any, ...]:
        """The attribute ``name`` of the envs ``indices`` as it is (a method is not
        called, unlike ``get_attr``, which is ``SyncVectorEnv``'s)."""
        return self._call_on(indices, name, (), {}, invoke=False)

    def _call_on(self, indices: Sequence[int], name: str, args: tuple, kwargs: dict[str, Any],
                 *, invoke: bool) -> tuple[Any, ...]:
        self._check_open()
        chosen = self._indices(indices)
        mask = np.zeros(self.num_envs, np.bool_)
        mask[chosen] = True
        answers = self._run("call", [(name, args, kwargs, m, invoke)
                                     for m in self._per_lane(mask)],
                            lambda data: _call_envs(self._local, *data))
        return tuple(answers[i] for i in chosen)

    def get_attr(self, name: str) -> tuple[Any, ...]:
        return self.call(name)

    def set_attr(self, name: str, values: Any, *,
                 indices: Sequence[int] | None = None) -> None:
        """``env.set_wrapper_attr(name, value)`` on every env (``SyncVectorEnv.set_attr``),
        or on the envs ``indices``: one value for all of them, or a list or tuple of one
        each."""
        self._check_open()
        chosen = self._indices(range(self.num_envs) if indices is None else indices)
        if not isinstance(values, list | tuple):
            values = [values] * len(chosen)
        if len(values) != len(chosen):
            raise ValueError(f"set_attr needs one value per env ({len(chosen)}), got "
                             f"{len(values)}")
        per_env: list[Any] = [None] * self.num_envs
        mask = np.zeros(self.num_envs, np.bool_)
        for i, value in zip(chosen, values, strict=True):
            per_env[i], mask[i] = value, True
        self._run("set", [(name, v, m) for v, m in zip(
            self._per_lane(per_env), self._per_lane(mask), strict=True)],
                  lambda data: _set(self._local, *data))

    def is_wrapped(self, wrapper: type[gym.Wrapper]) -> tuple[bool, ...]:
        """Whether each env is wrapped in ``wrapper`` (anywhere in its wrapper chain)."""
        self._check_open()
        return tuple(self._run("wrapped", [wrapper] * (len(self._slices) - 1),
                               lambda cls: [_wrapped(env, cls) for env in self._local]))

    def render(self) -> tuple[Any, ...] | None:
        return self.call("render")

    def close_extras(self, **kwargs: Any) -> None:
        for env in self._local:
            env.close()
        self._local = []
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


def _step_envs(envs: list[gym.Env], space: gym.Space, buffer: Any, start: int,
               actions: np.ndarray, autoreset: np.ndarray, same_step: bool,
               on_reset: Callable[[], None] | None = None
               ) -> list[tuple[float, bool, bool, dict[str, Any]]]:
    """``envs`` (envs ``start``… of the batch) stepped, their observations in ``buffer``;
    ``on_reset()`` before any of them resets."""
    return [_step_one(env, space, buffer, start + i, actions[i], bool(autoreset[i]), same_step,
                      on_reset) for i, env in enumerate(envs)]


def _reset_envs(envs: list[gym.Env], space: gym.Space, buffer: Any, start: int,
                seeds: Sequence[int | None], options: dict[str, Any] | None
                ) -> list[dict[str, Any]]:
    """``envs`` (envs ``start``… of the batch) reset, their observations in ``buffer``."""
    infos = []
    for i, (env, seed) in enumerate(zip(envs, seeds, strict=True)):
        obs, info = env.reset(seed=seed, options=options)
        _write(space, buffer, start + i, obs)
        infos.append(info)
    return infos


def _step_one(env: gym.Env, space: gym.Space, buffer: Any, index: int, action: np.ndarray,
              autoreset: bool, same_step: bool = False,
              on_reset: Callable[[], None] | None = None
              ) -> tuple[float, bool, bool, dict[str, Any]]:
    """One env's step, its observation written to ``buffer``. NEXT_STEP autoreset: a
    step with ``autoreset`` resets instead; SAME_STEP (``same_step``): an episode's last
    step resets at once, the info being ``SyncVectorEnv``'s (``final_obs``,
    ``final_info``, then the reset's info). ``on_reset()`` just before a reset."""
    if autoreset:
        if on_reset is not None:
            on_reset()
        obs, info = env.reset()
        reward, terminated, truncated = 0.0, False, False
    else:
        obs, reward, terminated, truncated, info = env.step(action)
        if same_step and (terminated or truncated):
            final_obs, final_info = obs, info
            if on_reset is not None:
                on_reset()
            obs, info = env.reset()
            info = {"final_obs": final_obs, "final_info": final_info, **info}
    _write(space, buffer, index, obs)
    return float(reward), bool(terminated), bool(truncated), info


def _call(env: gym.Env, name: str, args: tuple, kwargs: dict[str, Any]) -> Any:
    attr = env.get_wrapper_attr(name)
    return attr(*args, **kwargs) if callable(attr) else attr


def _call_envs(envs: list[gym.Env], name: str, args: tuple, kwargs: dict[str, Any],
               mask: np.ndarray, invoke: bool) -> list[Any]:
    """``_call`` on the envs marked in ``mask`` (None for the others); without
    ``invoke`` the attribute itself."""
    return [(_call(env, name, args, kwargs) if invoke else env.get_wrapper_attr(name))
            if chosen else None for env, chosen in zip(envs, mask, strict=True)]


def _set(envs: list[gym.Env], name: str, values: Sequence[Any], mask: np.ndarray
         ) -> list[None]:
    for env, value, chosen in zip(envs, values, mask, strict=True):
        if chosen:
            env.set_wrapper_attr(name, value)
    return [None] * len(envs)


def _wrapped(env: gym.Env, wrapper: type[gym.Wrapper]) -> bool:
    while isinstance(env, gym.Wrapper):
        if isinstance(env, wrapper):
            return True
        env = env.env
    return False


_SCALARS = (float, int, bool)

_plans: dict[tuple, Any] = {}
"""``_MergeAhead``'s plans by (keys, their types): the merged dict's names in order
(``key``, ``_key``, …), the numeric types' columns, per key its row among the numeric
blocks' rows (their concatenation; −1: a string) and the string keys' positions; False
where the fast path does not apply."""


def _merge_scalars(infos: list[dict[str, Any]]) -> dict[str, Any] | None:
    """``_merge_infos`` of infos with the same keys, each a plain float, int, bool or str
    of the same type in every info (every step of ours; ``_MergeAhead``), None for any
    other infos."""
    ahead = _MergeAhead.of(infos[0], len(infos))
    if ahead is None:
        return None
    for i, info in enumerate(infos):
        if not ahead.fill(i, info):
            return None
    return ahead.merged


class _MergeAhead:
    """``_merge_infos``' result for infos of one layout, made before the infos are all
    known: ``of`` makes the merged dict with its arrays, ``fill`` writes env ``i``'s values
    into them. So the vector env merges this process's envs' infos while it waits for the
    workers, and only theirs after (≈ 45 µs a step off the path both lanes wait on).

    The layout (a plan per keys and their types): one array per numeric type, a row per
    key (each row as ``np.array(values, dtype=type)`` makes it; the rows are views of that
    array), an object array per string key; the dict is made in one call from the rows in
    key order (per key two stores cost µs a step)."""

    __slots__ = ("blocks", "keys", "kinds", "merged", "plan", "strings")

    def __init__(self, keys: tuple, kinds: tuple, plan: tuple, n: int) -> None:
        names, columns, row_of, strings = plan
        self.keys, self.kinds, self.plan = keys, kinds, plan
        self.blocks = [np.empty((len(cols), n), dtype=kind)
                       for kind, cols in zip(_SCALARS, columns, strict=True)]
        block_rows: list[Any] = [row for block in self.blocks for row in block]  # views
        values: list[Any] = [None] * len(names)
        values[0::2] = [block_rows[i] for i in row_of]  # a string's row −1: replaced below
        values[1::2] = np.ones((len(keys), n), np.bool_)
        self.strings = []
        for j in strings:  # as the general path: an object column
            column = np.full(n, fill_value=None, dtype=object)
            values[2 * j] = column
            self.strings.append((j, column))
        self.merged = dict(zip(names, values, strict=True))

    @classmethod
    def of(cls, first: dict[str, Any], n: int) -> _MergeAhead | None:
        """The merge of ``n`` infos of ``first``'s layout, None if it has other values
        than plain scalars and strings."""
        kinds = tuple(map(type, first.values()))
        keys = tuple(first)
        plan = _plans.get(key := (keys, kinds))
        if plan is None:
            plan = False
            if all(k in _SCALARS or k is str for k in kinds):
                columns = tuple([j for j, k in enumerate(kinds) if k is kind]
                                for kind in _SCALARS)
                numeric = [j for cols in columns for j in cols]  # the blocks' rows, in order
                row_of = [numeric.index(j) if k is not str else -1
                          for j, k in enumerate(kinds)]
                names = tuple(name for k in keys for name in (k, f"_{k}"))
                strings = tuple(j for j, k in enumerate(kinds) if k is str)
                plan = (names, columns, row_of, strings)
            if len(_plans) > 16:
                _plans.clear()
            _plans[key] = plan
        return None if plan is False else cls(keys, kinds, plan, n)

    def fill(self, i: int, info: dict[str, Any]) -> bool:
        """Env ``i``'s ``info`` into the arrays; False (the merge is void) if its layout
        is not the merge's or an int does not fit int64."""
        if tuple(info) != self.keys or tuple(map(type, info.values())) != self.kinds:
            return False
        row = list(info.values())
        for block, cols in zip(self.blocks, self.plan[1], strict=True):
            if cols:
                try:
                    block[:, i] = [row[j] for j in cols]
                except OverflowError:  # an int beyond int64: the general path says so
                    return False
        for j, column in self.strings:
            column[i] = row[j]
        return True


def _merge_infos(infos: list[dict[str, Any]]) -> dict[str, Any]:
    """``SyncVectorEnv``'s info layout (``key``: an array over envs, ``_key``: which envs
    have it), built column by column: every env of ours reports the same keys."""
    n = len(infos)
    if n and (fast := _merge_scalars(infos)) is not None:
        return fast
    merged: dict[str, Any] = {}
    keys = list(infos[0]) if infos else []
    if any(list(info) != keys for info in infos[1:]):  # not ours (a wrapper's?): general path
        keys = list(dict.fromkeys(k for info in infos for k in info))
    all_present = np.ones(n, dtype=np.bool_)
    for key in keys:
        values = [info.get(key, _MISSING) for info in infos]
        if key == "final_obs":  # SyncVectorEnv keeps the final observations as objects
            merged[key] = np.full(n, fill_value=None, dtype=object)
            for i, v in enumerate(values):
                if v is not _MISSING:
                    merged[key][i] = v
            merged[f"_{key}"] = np.array([v is not _MISSING for v in values], np.bool_)
            continue
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


class _Board:
    """Shared memory through which this process posts steps to the workers and they post
    their results back: a pipe message costs ≈ 15 µs of system calls and wake-up on this
    VM, and a step through the pipes took four (≈ 0.12 ms of a 1.4 ms step of two envs).
    ``ctrl``: the number of the step posted, its SAME_STEP flag, then per worker the
    number of the last step whose results it wrote, whether it sleeps on its pipe (past
    its spin: the parent wakes it with a message) and how many info layouts it sent
    through the pipe (the parent checks it learnt as many); per lane (this process's
    first) the number of the last step in which one of its envs reset (it says so as
    the reset begins: the other lanes, done with their step, prepare their next resets
    meanwhile, ``_Idle``) and the number of the last step it took (results on the board
    or in the pipe: the others' preparation ends). Per env: its action, its autoreset
    flag, reward, terminated and truncated, and its info's floats and ints (in the order
    of its keys; the keys, types and strings are its layout, ``_layout``, which both sides
    learn from the infos that went through the pipe)."""

    def __init__(self, ctx: Any, num_envs: int, action_shape: tuple[int, ...],
                 lanes: int) -> None:
        size = int(np.prod(action_shape, dtype=np.int64))
        self.asleep = lanes  # ctrl[asleep + w]: worker w blocks on its pipe (wake it)
        self.layouts = 2 * lanes  # ctrl[layouts + w]: layouts worker w sent by pipe
        self.lanes = lanes
        self.resetting = 3 * lanes  # ctrl[resetting + l]: the last step lane l reset in
        self.finished = 4 * lanes  # ctrl[finished + l]: the last step lane l took
        self._raw = (ctx.RawArray(ctypes.c_int64, 5 * lanes),
                     ctx.RawArray(ctypes.c_double, num_envs * size),
                     ctx.RawArray(ctypes.c_uint8, num_envs),
                     ctx.RawArray(ctypes.c_double, num_envs),
                     ctx.RawArray(ctypes.c_uint8, 2 * num_envs),
                     ctx.RawArray(ctypes.c_double, num_envs * BOARD_INFO_SLOTS),
                     ctx.RawArray(ctypes.c_int64, num_envs * BOARD_INFO_SLOTS))
        self._shape = (num_envs, *action_shape)
        self._views()

    def _views(self) -> None:
        ctrl, actions, autoreset, rewards, flags, floats, ints = self._raw
        n = self._shape[0]
        self.ctrl = np.frombuffer(ctrl, np.int64)
        self.actions = np.frombuffer(actions, np.float64).reshape(self._shape)
        self.autoreset = np.frombuffer(autoreset, np.uint8)
        self.rewards = np.frombuffer(rewards, np.float64)
        self.flags = np.frombuffer(flags, np.uint8).reshape(n, 2)
        self.floats = np.frombuffer(floats, np.float64).reshape(n, BOARD_INFO_SLOTS)
        self.ints = np.frombuffer(ints, np.int64).reshape(n, BOARD_INFO_SLOTS)

    def __getstate__(self) -> dict[str, Any]:  # to a spawned worker: the shared memory
        return {"_raw": self._raw, "_shape": self._shape, "asleep": self.asleep,
                "layouts": self.layouts, "resetting": self.resetting,
                "finished": self.finished, "lanes": self.lanes}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._views()


def _layout(info: dict[str, Any]) -> tuple | None:
    """What the board needs to know of an info to carry it as numbers: its keys, their
    types and its strings (None: it cannot, e.g. an array in it or too many numbers)."""
    kinds = tuple(map(type, info.values()))
    n_float = kinds.count(float)
    if n_float > BOARD_INFO_SLOTS or len(kinds) - n_float - kinds.count(str) > (
            BOARD_INFO_SLOTS) or not all(k in _SCALARS or k is str for k in kinds):
        return None
    return tuple(info), kinds, tuple(v for v in info.values() if type(v) is str)


def _post_results(board: _Board, start: int,
                  answers: list[tuple[float, bool, bool, dict[str, Any]]],
                  known: list[tuple | None]) -> bool:
    """Write a worker's step results (envs ``start``…) to the board if every info has
    the layout its env had last (``known``); False (nothing meant) otherwise."""
    for answer, layout in zip(answers, known, strict=True):
        if layout is None or _layout(answer[3]) != layout:
            return False
    for i, (reward, terminated, truncated, info) in enumerate(answers):
        k = start + i
        board.rewards[k] = reward
        board.flags[k] = terminated, truncated
        values = info.values()
        floats = [v for v in values if type(v) is float]
        ints = [v for v in values if type(v) is int or type(v) is bool]
        board.floats[k, :len(floats)] = floats
        try:
            board.ints[k, :len(ints)] = ints
        except OverflowError:  # an int beyond int64: the pipe carries it
            return False
    return True


def _read_results(board: _Board, start: int, stop: int, known: list[tuple | None]
                  ) -> list[tuple[float, bool, bool, dict[str, Any]]]:
    """The step results of envs ``start:stop`` from the board, as the worker made them."""
    out = []
    rewards = board.rewards[start:stop].tolist()
    flags = board.flags[start:stop].tolist()
    for i, k in enumerate(range(start, stop)):
        keys, kinds, strings = known[k]  # type: ignore[misc]
        floats = iter(board.floats[k].tolist())
        ints = iter(board.ints[k].tolist())
        texts = iter(strings)
        info = {key: (next(floats) if kind is float else next(texts) if kind is str
                      else bool(next(ints)) if kind is bool else next(ints))
                for key, kind in zip(keys, kinds, strict=True)}
        out.append((rewards[i], bool(flags[i][0]), bool(flags[i][1]), info))
    return out


def _prepare_resets(envs: list[gym.Env], stop: Callable[[], bool] | None = None) -> None:
    """``prepare_reset`` on each env (a lane with time to spare: while another lane
    resets, it generates its envs' next tracks, builds their scenes and paints their
    first frames, ≈ 1.5 ms of each of their resets, so that the others wait less on them)
    until ``stop()`` says the spare time is over (the other lanes are done: going on would
    make them wait); never fails the lane (a reset that would fail still fails, then, as
    it would have)."""
    for env in envs:
        if stop is not None and stop():
            return
        with contextlib.suppress(Exception):
            env.unwrapped.prepare_reset(stop)  # type: ignore[attr-defined]


class _Idle:
    """What a lane does with its time to spare in a step (this process while it waits for
    the workers, a worker while it waits for the next step): if another lane resets an
    env in that step (its flag on the board, set as the reset begins: ``mark``), it
    prepares its own envs' next resets (``_prepare_resets``) until every other lane has
    taken the step, at most once a step. A reset costs 3–8 steps' time; the lanes step
    in lockstep, so without this the others would only wait."""

    __slots__ = ("_busy", "_ctrl", "_envs", "_last", "_others", "mark")

    def __init__(self, board: _Board, lane: int, envs: list[gym.Env]) -> None:
        ctrl = self._ctrl = board.ctrl
        lanes = board.lanes
        self._envs = envs
        self._others = [board.resetting + other for other in range(lanes) if other != lane]
        self._busy = [board.finished + other for other in range(lanes) if other != lane]
        self._last = -1
        self.mark = functools.partial(_mark_reset, ctrl, board.resetting + lane)

    def __call__(self, seq: int) -> bool:
        """Prepare if another lane resets in step ``seq``; whether it did (then not
        again this step)."""
        if self._last == seq:
            return False
        ctrl = self._ctrl
        for slot in self._others:
            if ctrl[slot] == seq:
                self._last = seq
                _prepare_resets(self._envs, lambda: self.done(seq))
                return True
        return False

    def done(self, seq: int) -> bool:
        """Whether every other lane has taken step ``seq`` (this process: its own envs;
        a worker: its results are on the board or in its pipe), or a later one (step
        numbers only grow: a lane may be on to the next step before this one looks)."""
        ctrl = self._ctrl
        return all(ctrl[slot] >= seq for slot in self._busy)


def _mark_reset(ctrl: np.ndarray, slot: int) -> None:
    """Say on the board that a lane resets an env in the step posted (``_Idle.mark``)."""
    ctrl[slot] = ctrl[0]


def _await_answer(conn: Connection, board: _Board, lane: int, seq: int,
                  idle: _Idle | None = None) -> Any:
    """Wait for worker ``lane``'s results of step ``seq``: None when they are on the
    board, else the next message on its pipe (its answer ``(ok, data, seq)``: an error,
    or infos the board cannot hold; or an older answer). Spins: the worker is stepping on
    another core; meanwhile ``idle(seq)`` (``_Idle``), until it did something. A dead
    worker's pipe raises EOFError here."""
    done = board.ctrl
    while True:
        if done[1 + lane] == seq:
            return None
        if conn.poll(0):
            return conn.recv()
        if idle is not None and idle(seq):
            idle = None
        else:
            os.sched_yield()


def _await_command(conn: Connection, board: _Board | None, seen: int, spin_s: float,
                   lane: int = 1, idle: _Idle | None = None) -> Any:
    """Worker ``lane``'s next command: ``("post", n)`` when step ``n`` is on the board,
    else the pipe's next message; polled for up to ``spin_s`` (meanwhile ``idle(seen)``,
    ``_Idle``, until it did something; the spin starts again after it), then slept for
    on the pipe: the worker says so on the board and the parent, posting a step, sends a
    wake-up. (x86 may order the parent's read of that flag before its write of the step
    number: a missed wake-up costs one nap, ``BOARD_NAP_S``.)"""
    if board is None:
        return _receive(conn, spin_s)
    ctrl = board.ctrl
    deadline = time.perf_counter() + spin_s
    asleep = board.asleep + lane
    try:
        while True:
            if ctrl[0] != seen:
                return "post", int(ctrl[0])
            if conn.poll(0):
                message = conn.recv()
                if message[0] != "wake":
                    return message
            elif idle is not None and idle(seen):
                idle = None
                ctrl[asleep] = 0  # spinning again (a wake-up sent meanwhile is skipped)
                deadline = time.perf_counter() + spin_s
            elif ctrl[asleep]:
                conn.poll(BOARD_NAP_S)  # until a message (a wake-up) or the nap's end
            elif time.perf_counter() < deadline:
                os.sched_yield()
            else:
                ctrl[asleep] = 1  # then the board is looked at once more before a nap
    finally:
        ctrl[asleep] = 0


def _receive(conn: Connection, spin_s: float) -> Any:
    """The next message on ``conn``, polled for up to ``spin_s`` before blocking."""
    deadline = time.perf_counter() + spin_s
    while not conn.poll(0) and time.perf_counter() < deadline:
        os.sched_yield()  # a runnable thread on this core goes first
    return conn.recv()


def _worker(conn: Connection, shm: Any, space: gym.Space,
            num_envs: int, kwargs: dict[str, Any], start: int, stop: int,
            parent_pid: int, board: _Board | None = None, lane: int = 1) -> None:
    """A worker (lane ``lane``): envs ``start:stop`` of the vector env, commands from
    ``conn``, steps from the ``board`` if there is one."""
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
        seen = 0  # the last step taken from the board
        known: list[tuple | None] = [None] * (stop - start)  # as the parent's _known
        idle = _Idle(board, lane, envs) if board is not None else None
        while True:
            command, data = _await_command(conn, board, seen, WAIT_SPIN_S, lane, idle)
            if command == "post":
                assert board is not None
                seen = data
                try:
                    answer = _step_envs(envs, space, buffer, start,
                                        board.actions[start:stop].copy(),
                                        board.autoreset[start:stop].astype(np.bool_),
                                        bool(board.ctrl[1]), idle.mark)  # type: ignore[union-attr]
                    if _post_results(board, start, answer, known):
                        board.ctrl[board.finished + lane] = seen  # before the hand-over
                        board.ctrl[1 + lane] = seen  # last: it hands the results over
                    else:
                        layouts = [_layout(a[3]) for a in answer]
                        board.ctrl[board.finished + lane] = seen
                        conn.send((True, answer, seen))
                        known = layouts
                        board.ctrl[board.layouts + lane] += 1
                except Exception as exc:  # reported to the parent, raised there
                    board.ctrl[board.finished + lane] = seen
                    conn.send((False, (type(exc).__name__, str(exc), traceback.format_exc()),
                               seen))
                continue
            try:
                if command == "step":
                    answer: Any = _step_envs(envs, space, buffer, start, *data)
                elif command == "reset":
                    answer = _reset_envs(envs, space, buffer, start, *data)
                elif command == "call":
                    answer = _call_envs(envs, *data)
                elif command == "set":
                    answer = _set(envs, *data)
                elif command == "wrapped":
                    answer = [_wrapped(env, data) for env in envs]
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
