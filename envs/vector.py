"""``gymnasium.make_vec("TfaldaTrack-v0", num_envs=N)``: N envs stepped in this process and
by worker processes, one per core.

Gymnasium's ``AsyncVectorEnv`` runs one process per env and talks to each through a pipe
per step; on a 2-core machine two such envs ran *slower* than one (0.74×): every worker
let OpenCV start a thread per core (4 busy threads on 2 cores), and the parent spent a
core's share on per-env pipe round trips and on merging 14 info entries per env.

Here the envs are cut into one slot per core: this process steps the first slot itself
while one worker process per further core steps each other slot (a batch: one message per
worker and step, not per env; a parent that only waited would leave its core idle). The
runtime (worker processes, the shared step board, the waits) is ``envs.workers``; this
module keeps Gymnasium's semantics: ``AutoresetMode.NEXT_STEP`` (or ``SAME_STEP``, as SB3
needs), seeds ``seed + i`` for env ``i``, the infos of ``SyncVectorEnv`` (``key`` and
``_key`` arrays, merged as flat columns, this process's envs' while it waits for the
workers: ``_MergeAhead``); a rollout equals ``SyncVectorEnv``'s bit for bit. With one
env, or one CPU, every env runs in this process.

It works from any script: a worker never re-runs the user's main module (no
``if __name__ == "__main__":`` guard needed; ``envs.workers.start_worker``).
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
from collections.abc import Callable, Sequence
from multiprocessing.connection import Connection
from typing import Any, ClassVar

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

from .workers import (
    FAST_STEPS,
    RAISED_AS_IS,
    SCALAR_TYPES,
    WAIT_SPIN_S,
    WAKE,
    Board,
    SpareTime,
    WorkerProcess,
    await_results,
    call_envs,
    info_layout,
    read_results,
    receive,
    reset_envs,
    set_attrs,
    start_worker,
    step_envs,
    wrapped_in,
)


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
        slots = min(self.num_envs, workers if workers is not None else available_cpus())
        # Contiguous slices: slot w steps envs slices[w]:slices[w + 1]; slot 0 is this
        # process (it would otherwise sit idle while the workers step), slots 1… are workers.
        self._slices = np.linspace(0, self.num_envs, slots + 1).round().astype(int)
        self._conns: list[Connection] = []
        self._workers: list[WorkerProcess] = []
        self._autoreset = np.zeros(self.num_envs, dtype=np.bool_)
        self._board: Board | None = None  # the shared step board (workers, x86 only)
        self._seq = 0  # the last step posted on it
        self._known: list[tuple | None] = [None] * self.num_envs  # info layouts (info_layout)
        self._piped = 0  # posted steps whose results a worker sent through its pipe
        self._pending: set[int] = set()  # workers whose answer to step _seq is not read
        self._layouts = [0] * (self.num_envs + 1)  # per worker, layouts learnt from it
        self.closed = False
        self._local: list[gym.Env] = [probe] + [
            gym.make(ENV_ID, **self._kwargs) for _ in range(1, int(self._slices[1]))]
        if slots == 1:
            self._observations = self.observation_space.sample()  # batch buffer, overwritten
            return
        # spawn, not fork: a fork copies OpenCV's thread pool mid-state (a worker then hung
        # in cv2.setNumThreads); spawned workers are still our children (PR_SET_PDEATHSIG).
        ctx = multiprocessing.get_context("spawn")
        self._shm = create_shared_memory(self.single_observation_space, self.num_envs, ctx)
        self._observations = read_from_shared_memory(self.single_observation_space,
                                                      self._shm, self.num_envs)
        if FAST_STEPS and isinstance(self.single_action_space, gym.spaces.Box):
            self._board = Board(ctx, self.num_envs, self.single_action_space.shape, slots)
            self._idle = SpareTime(self._board, 0, self._local)
        for w in range(1, slots):
            parent, child = ctx.Pipe()
            try:
                worker = start_worker(ctx, f"tfalda-vec-{w}", (
                    child, self._shm, self.single_observation_space, self.num_envs, ENV_ID,
                    self._kwargs, int(self._slices[w]), int(self._slices[w + 1]),
                    os.getpid(), self._board, w))
            except BaseException:
                parent.close()
                child.close()
                self.close()
                raise
            child.close()
            self._conns.append(parent)
            self._workers.append(worker)
        self._gather("init")

    # ------------------------------------------------------------------ protocol
    def _run(self, command: str, per_slot: Sequence[Any],
             local: Callable[[Any], list[Any]]) -> list[Any]:
        """``command`` on every slot, in env order: the workers get ``per_slot[1:]`` first,
        this process runs ``local(per_slot[0])`` meanwhile. Whatever happens here (an
        error, a Ctrl-C in this process's own envs, a value that does not pickle), every
        worker that got the command is heard before it is raised: the pipes stay in
        step."""
        sent = 0
        try:
            for w, (conn, data) in enumerate(zip(self._conns, per_slot[1:], strict=True)):
                try:
                    conn.send((command, data))
                except (BrokenPipeError, ConnectionError, OSError):
                    death = self._workers[w].death()
                    self.close()
                    raise RuntimeError(f"worker {w + 1} of the vector env died ({death}); "
                                       "make a new one with gymnasium.make_vec") from None
                sent += 1
            answers = local(per_slot[0])
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

    def _answer(self, slot: int) -> tuple[bool, Any]:
        """Worker ``slot``'s answer ``(ok, data)`` to a pipe command. Answers to posted
        steps this process gave up on (a Ctrl-C while it waited) may come first: skipped,
        their info layouts learnt (the worker learnt them as it sent them)."""
        message = receive(self._conns[slot - 1], WAIT_SPIN_S)
        while len(message) == 3:
            self._learn(slot, message)
            message = receive(self._conns[slot - 1], WAIT_SPIN_S)
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
                                   f"({self._workers[w].death()})", "")
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
        if command == "init" or name not in RAISED_AS_IS:
            self.close()
            raise RuntimeError(f"{name} in a worker of the vector env: {message}\n{trace}")
        raise RAISED_AS_IS[name](message)

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
                    conn.send(WAKE)
        try:
            try:
                answers = step_envs(self._local, self.single_observation_space,
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

    def _collect(self, idle: SpareTime | None = None
                 ) -> list[list[tuple[float, bool, bool, dict[str, Any]]]]:
        """The results of the step last posted of every worker not heard yet (all of
        them, but after a Ctrl-C), in worker order; a worker's error raised after all
        have answered. ``idle``: what this process does while it waits (``SpareTime``)."""
        board = self._board
        assert board is not None
        parts, error = [], None
        for w in sorted(self._pending):
            conn = self._conns[w - 1]
            start, stop = int(self._slices[w]), int(self._slices[w + 1])
            try:
                message = await_results(conn, board, w, self._seq, idle)
                # Pipe messages to other commands or steps than this one are answers this
                # process gave up on (a Ctrl-C while it waited): dropped, but the layouts
                # a worker sent are learnt (it learnt them as it sent them).
                while message is not None and (len(message) != 3 or message[2] != self._seq):
                    self._learn(w, message)
                    message = await_results(conn, board, w, self._seq)
            except (EOFError, ConnectionError):
                message = (False, ("RuntimeError", f"worker {w} of the vector env died "
                                   f"({self._workers[w - 1].death()})", ""), self._seq)
            self._pending.discard(w)
            if message is None:
                if board.ctrl[board.layouts + w] != self._layouts[w]:
                    # A layout sent through the pipe was lost (a Ctrl-C inside its
                    # reading): the board's numbers cannot be decoded.
                    self.close()
                    raise RuntimeError(
                        f"the vector env lost worker {w}'s info layout (a Ctrl-C while it "
                        "read one); make a new one with gymnasium.make_vec")
                parts.append(read_results(board, start, stop, self._known))
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

    def _learn(self, slot: int, message: tuple) -> None:
        """The info layouts of worker ``slot``'s envs from its pipe answer to a posted
        step (the worker learnt them as it sent it, and counts them: ``_layouts``);
        other messages teach nothing."""
        if len(message) == 3 and message[2] == self._seq:
            self._pending.discard(slot)  # the answer to the step last posted: heard
        if len(message) == 3 and message[0]:
            start, stop = int(self._slices[slot]), int(self._slices[slot + 1])
            self._known[start:stop] = [info_layout(answer[3]) for answer in message[1]]
            self._layouts[slot] += 1

    def _indices(self, indices: Sequence[int]) -> list[int]:
        """``indices`` as a list of env numbers, each checked to be one of ours."""
        chosen = [int(i) for i in indices]
        if any(not 0 <= i < self.num_envs for i in chosen):
            raise ValueError(f"indices must lie in [0, {self.num_envs}), got {indices!r}")
        return chosen

    def _per_slot(self, values: Sequence[Any]) -> list[Sequence[Any]]:
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
            return reset_envs(self._local, space, buffer, 0, chunk, options)

        infos = self._run("reset", [(chunk, options) for chunk in self._per_slot(seeds)],
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
                    self._per_slot(acts), self._per_slot(self._autoreset), strict=True)],
                lambda data: step_envs(self._local, space, buffer, 0, *data))
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
                                     for m in self._per_slot(mask)],
                            lambda data: call_envs(self._local, *data))
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
            self._per_slot(per_env), self._per_slot(mask), strict=True)],
                  lambda data: set_attrs(self._local, *data))

    def is_wrapped(self, wrapper: type[gym.Wrapper]) -> tuple[bool, ...]:
        """Whether each env is wrapped in ``wrapper`` (anywhere in its wrapper chain)."""
        self._check_open()
        return tuple(self._run("wrapped", [wrapper] * (len(self._slices) - 1),
                               lambda cls: [wrapped_in(env, cls) for env in self._local]))

    def render(self) -> tuple[Any, ...] | None:
        return self.call("render")

    def close_extras(self, **kwargs: Any) -> None:
        for env in self._local:
            env.close()
        self._local = []
        for conn in self._conns:
            with contextlib.suppress(OSError, BrokenPipeError):
                conn.send(("close", None))
        for worker in self._workers:
            proc = worker.process
            proc.join(timeout=5.0)
            if proc.is_alive():
                proc.terminate()
                proc.join(timeout=5.0)
        for conn in self._conns:
            conn.close()
        self._conns, self._workers = [], []

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


def _copy(batch: Any) -> Any:
    """A copy of the batch buffer (the next step overwrites it), as Gymnasium's vector
    envs return by default."""
    if isinstance(batch, dict):
        return {key: _copy(value) for key, value in batch.items()}
    return batch.copy()


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
    workers, and only theirs after (≈ 45 µs a step off the path both slots wait on).

    The layout (a plan per keys and their types): one array per numeric type, a row per
    key (each row as ``np.array(values, dtype=type)`` makes it; the rows are views of that
    array), an object array per string key; the dict is made in one call from the rows in
    key order (per key two stores cost µs a step)."""

    __slots__ = ("blocks", "keys", "kinds", "merged", "plan", "strings")

    def __init__(self, keys: tuple, kinds: tuple, plan: tuple, n: int) -> None:
        names, columns, row_of, strings = plan
        self.keys, self.kinds, self.plan = keys, kinds, plan
        self.blocks = [np.empty((len(cols), n), dtype=kind)
                       for kind, cols in zip(SCALAR_TYPES, columns, strict=True)]
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
            if all(k in SCALAR_TYPES or k is str for k in kinds):
                columns = tuple([j for j, k in enumerate(kinds) if k is kind]
                                for kind in SCALAR_TYPES)
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
