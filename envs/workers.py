"""The vector env's multiprocess runtime: worker processes, each stepping one slot of the
batch (a contiguous range of envs), this process stepping the first slot itself; a
shared step board; the waits; what a process does with its spare time in a step.

Words: a **slot** is the envs one process steps (slot 0: this process, slots 1…: the
workers); the **board** (``Board``) is the shared memory through which steps are posted
and their results handed back (x86 only: ``FAST_STEPS``); the pipes carry every other
command, errors and the infos the board cannot hold.

Workers start from an entry point of our own (``start_worker``): Python's spawn method
with the user's ``__main__`` hidden while the process starts, so that a worker never
re-runs the user's main module. A script without an ``if __name__ == "__main__":``
guard, ``python -c``, a script read from standard input and an interactive session or
notebook kernel all work. Fork is not an option: it copies OpenCV's thread pool mid-state
(a worker then hung in ``cv2.setNumThreads``); a forkserver imports the main module too
(in the server and again in each child's preparation). A worker's standard error goes
through a pipe that this process forwards to its own (``_StderrTail``), keeping the last
line: a worker that dies is reported with its exit code or signal and that line
(``WorkerProcess.death``).

Workers ignore Ctrl-C (the parent closes them) and die with the parent (Linux
``PR_SET_PDEATHSIG``), like the sweep workers of ``tfalda_sim.parallel``.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import os
import pickle
import platform
import signal
import sys
import threading
import time
import traceback
import types
from collections.abc import Callable, Iterator, Sequence
from multiprocessing.connection import Connection
from typing import Any

import cv2
import gymnasium as gym
import numpy as np
from gymnasium.vector.utils import read_from_shared_memory

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

WAKE = ("wake", None)
"""The message that wakes a worker sleeping on its pipe (a step is on the board)."""

BOARD_INFO_CELLS = 32
"""Numbers per env's info the shared step board holds (floats and ints each): an info
with more goes through the pipe."""

FAST_STEPS = platform.machine().lower() in ("x86_64", "amd64", "x86", "i386", "i686")
"""Whether steps go through the shared step board (``Board``) instead of the pipes: its
hand-over (write the data, then the sequence number; read the number, then the data)
needs stores seen by the other core in program order, which x86 guarantees (TSO) and
weaker memory models (ARM, POWER) do not without fences Python cannot issue; there the
pipes carry every step."""

RAISED_AS_IS: dict[str, type[Exception]] = {e.__name__: e for e in (
    ValueError, TypeError, RuntimeError, KeyError, AttributeError, NotImplementedError)}
"""Exceptions a worker's env may raise that the parent raises again as the same type."""


# ---------------------------------------------------------------------- a slot's envs
def write_obs(space: gym.Space, buffer: Any, index: int, obs: Any) -> None:
    """Env ``index``'s observation into the batch ``buffer`` (arrays or a dict of them)."""
    if isinstance(space, gym.spaces.Dict):
        for key, sub in space.spaces.items():
            write_obs(sub, buffer[key], index, obs[key])
    else:
        buffer[index] = obs


def step_envs(envs: list[gym.Env], space: gym.Space, buffer: Any, start: int,
               actions: np.ndarray, autoreset: np.ndarray, same_step: bool,
               on_reset: Callable[[], None] | None = None
               ) -> list[tuple[float, bool, bool, dict[str, Any]]]:
    """``envs`` (envs ``start``… of the batch) stepped, their observations in ``buffer``;
    ``on_reset()`` before any of them resets."""
    return [step_one(env, space, buffer, start + i, actions[i], bool(autoreset[i]), same_step,
                      on_reset) for i, env in enumerate(envs)]


def reset_envs(envs: list[gym.Env], space: gym.Space, buffer: Any, start: int,
                seeds: Sequence[int | None], options: dict[str, Any] | None
                ) -> list[dict[str, Any]]:
    """``envs`` (envs ``start``… of the batch) reset, their observations in ``buffer``."""
    infos = []
    for i, (env, seed) in enumerate(zip(envs, seeds, strict=True)):
        obs, info = env.reset(seed=seed, options=options)
        write_obs(space, buffer, start + i, obs)
        infos.append(info)
    return infos


def step_one(env: gym.Env, space: gym.Space, buffer: Any, index: int, action: np.ndarray,
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
    write_obs(space, buffer, index, obs)
    return float(reward), bool(terminated), bool(truncated), info


def call_attr(env: gym.Env, name: str, args: tuple, kwargs: dict[str, Any]) -> Any:
    attr = env.get_wrapper_attr(name)
    return attr(*args, **kwargs) if callable(attr) else attr


def call_envs(envs: list[gym.Env], name: str, args: tuple, kwargs: dict[str, Any],
               mask: np.ndarray, invoke: bool) -> list[Any]:
    """``call_attr`` on the envs marked in ``mask`` (None for the others); without
    ``invoke`` the attribute itself."""
    return [(call_attr(env, name, args, kwargs) if invoke else env.get_wrapper_attr(name))
            if chosen else None for env, chosen in zip(envs, mask, strict=True)]


def set_attrs(envs: list[gym.Env], name: str, values: Sequence[Any], mask: np.ndarray
         ) -> list[None]:
    for env, value, chosen in zip(envs, values, mask, strict=True):
        if chosen:
            env.set_wrapper_attr(name, value)
    return [None] * len(envs)


def wrapped_in(env: gym.Env, wrapper: type[gym.Wrapper]) -> bool:
    while isinstance(env, gym.Wrapper):
        if isinstance(env, wrapper):
            return True
        env = env.env
    return False


SCALAR_TYPES = (float, int, bool)
"""The info values the board carries as numbers (strings travel with the layout)."""


# ---------------------------------------------------------------------- the step board


class Board:
    """Shared memory through which this process posts steps to the workers and they post
    their results back: a pipe message costs ≈ 15 µs of system calls and wake-up on this
    VM, and a step through the pipes took four (≈ 0.12 ms of a 1.4 ms step of two envs).
    ``ctrl``: the number of the step posted, its SAME_STEP flag, then per worker the
    number of the last step whose results it wrote, whether it sleeps on its pipe (past
    its spin: the parent wakes it with a message) and how many info layouts it sent
    through the pipe (the parent checks it learnt as many); per slot (this process's
    first) the number of the last step in which one of its envs reset (it says so as
    the reset begins: the other slots, done with their step, prepare their next resets
    meanwhile, ``SpareTime``) and the number of the last step it took (results on the board
    or in the pipe: the others' preparation ends). Per env: its action, its autoreset
    flag, reward, terminated and truncated, and its info's floats and ints (in the order
    of its keys; the keys, types and strings are its layout, ``info_layout``, which both sides
    learn from the infos that went through the pipe)."""

    def __init__(self, ctx: Any, num_envs: int, action_shape: tuple[int, ...],
                 slots: int) -> None:
        size = int(np.prod(action_shape, dtype=np.int64))
        self.asleep = slots  # ctrl[asleep + w]: worker w blocks on its pipe (wake it)
        self.layouts = 2 * slots  # ctrl[layouts + w]: layouts worker w sent by pipe
        self.slots = slots
        self.resetting = 3 * slots  # ctrl[resetting + l]: the last step slot l reset in
        self.finished = 4 * slots  # ctrl[finished + l]: the last step slot l took
        self._raw = (ctx.RawArray(ctypes.c_int64, 5 * slots),
                     ctx.RawArray(ctypes.c_double, num_envs * size),
                     ctx.RawArray(ctypes.c_uint8, num_envs),
                     ctx.RawArray(ctypes.c_double, num_envs),
                     ctx.RawArray(ctypes.c_uint8, 2 * num_envs),
                     ctx.RawArray(ctypes.c_double, num_envs * BOARD_INFO_CELLS),
                     ctx.RawArray(ctypes.c_int64, num_envs * BOARD_INFO_CELLS))
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
        self.floats = np.frombuffer(floats, np.float64).reshape(n, BOARD_INFO_CELLS)
        self.ints = np.frombuffer(ints, np.int64).reshape(n, BOARD_INFO_CELLS)

    def __getstate__(self) -> dict[str, Any]:  # to a spawned worker: the shared memory
        return {"_raw": self._raw, "_shape": self._shape, "asleep": self.asleep,
                "layouts": self.layouts, "resetting": self.resetting,
                "finished": self.finished, "slots": self.slots}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._views()


def info_layout(info: dict[str, Any]) -> tuple | None:
    """What the board needs to know of an info to carry it as numbers: its keys, their
    types and its strings (None: it cannot, e.g. an array in it or too many numbers)."""
    kinds = tuple(map(type, info.values()))
    n_float = kinds.count(float)
    if n_float > BOARD_INFO_CELLS or len(kinds) - n_float - kinds.count(str) > (
            BOARD_INFO_CELLS) or not all(k in SCALAR_TYPES or k is str for k in kinds):
        return None
    return tuple(info), kinds, tuple(v for v in info.values() if type(v) is str)


def post_results(board: Board, start: int,
                  answers: list[tuple[float, bool, bool, dict[str, Any]]],
                  known: list[tuple | None]) -> bool:
    """Write a worker's step results (envs ``start``…) to the board if every info has
    the layout its env had last (``known``); False (nothing meant) otherwise."""
    for answer, layout in zip(answers, known, strict=True):
        if layout is None or info_layout(answer[3]) != layout:
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


def read_results(board: Board, start: int, stop: int, known: list[tuple | None]
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


# ---------------------------------------------------------------------- spare time and waits
def prepare_resets(envs: list[gym.Env], stop: Callable[[], bool] | None = None) -> None:
    """``prepare_reset`` on each env (a slot with time to spare: while another slot
    resets, it generates its envs' next tracks, builds their scenes and paints their
    first frames, ≈ 1.5 ms of each of their resets, so that the others wait less on them)
    until ``stop()`` says the spare time is over (the other slots are done: going on would
    make them wait); never fails the slot (a reset that would fail still fails, then, as
    it would have)."""
    for env in envs:
        if stop is not None and stop():
            return
        with contextlib.suppress(Exception):
            env.unwrapped.prepare_reset(stop)  # type: ignore[attr-defined]


class SpareTime:
    """What a slot does with its time to spare in a step (this process while it waits for
    the workers, a worker while it waits for the next step): if another slot resets an
    env in that step (its flag on the board, set as the reset begins: ``mark``), it
    prepares its own envs' next resets (``prepare_resets``) until every other slot has
    taken the step, at most once a step. A reset costs 3–8 steps' time; the slots step
    in lockstep, so without this the others would only wait."""

    __slots__ = ("_busy", "_ctrl", "_envs", "_last", "_others", "mark")

    def __init__(self, board: Board, slot: int, envs: list[gym.Env]) -> None:
        ctrl = self._ctrl = board.ctrl
        slots = board.slots
        self._envs = envs
        self._others = [board.resetting + other for other in range(slots) if other != slot]
        self._busy = [board.finished + other for other in range(slots) if other != slot]
        self._last = -1
        self.mark = functools.partial(mark_reset, ctrl, board.resetting + slot)

    def __call__(self, seq: int) -> bool:
        """Prepare if another slot resets in step ``seq``; whether it did (then not
        again this step)."""
        if self._last == seq:
            return False
        ctrl = self._ctrl
        for cell in self._others:
            if ctrl[cell] == seq:
                self._last = seq
                prepare_resets(self._envs, lambda: self.done(seq))
                return True
        return False

    def done(self, seq: int) -> bool:
        """Whether every other slot has taken step ``seq`` (this process: its own envs;
        a worker: its results are on the board or in its pipe), or a later one (step
        numbers only grow: a slot may be on to the next step before this one looks)."""
        ctrl = self._ctrl
        return all(ctrl[cell] >= seq for cell in self._busy)


def mark_reset(ctrl: np.ndarray, cell: int) -> None:
    """Say on the board that a slot resets an env in the step posted (``SpareTime.mark``)."""
    ctrl[cell] = ctrl[0]


def await_results(conn: Connection, board: Board, slot: int, seq: int,
                  idle: SpareTime | None = None) -> Any:
    """Wait for worker ``slot``'s results of step ``seq``: None when they are on the
    board, else the next message on its pipe (its answer ``(ok, data, seq)``: an error,
    or infos the board cannot hold; or an older answer). Spins: the worker is stepping on
    another core; meanwhile ``idle(seq)`` (``SpareTime``), until it did something. A dead
    worker's pipe raises EOFError here."""
    done = board.ctrl
    while True:
        if done[1 + slot] == seq:
            return None
        if conn.poll(0):
            return conn.recv()
        if idle is not None and idle(seq):
            idle = None
        else:
            os.sched_yield()


def await_command(conn: Connection, board: Board | None, seen: int, spin_s: float,
                   slot: int = 1, idle: SpareTime | None = None) -> Any:
    """Worker ``slot``'s next command: ``("post", n)`` when step ``n`` is on the board,
    else the pipe's next message; polled for up to ``spin_s`` (meanwhile ``idle(seen)``,
    ``SpareTime``, until it did something; the spin starts again after it), then slept for
    on the pipe: the worker says so on the board and the parent, posting a step, sends a
    wake-up. (x86 may order the parent's read of that flag before its write of the step
    number: a missed wake-up costs one nap, ``BOARD_NAP_S``.)"""
    if board is None:
        return receive(conn, spin_s)
    ctrl = board.ctrl
    deadline = time.perf_counter() + spin_s
    asleep = board.asleep + slot
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


def receive(conn: Connection, spin_s: float) -> Any:
    """The next message on ``conn``, polled for up to ``spin_s`` before blocking."""
    deadline = time.perf_counter() + spin_s
    while not conn.poll(0) and time.perf_counter() < deadline:
        os.sched_yield()  # a runnable thread on this core goes first
    return conn.recv()


# ---------------------------------------------------------------------- the worker loop
def worker_main(conn: Connection, shm: Any, space: gym.Space, num_envs: int, env_id: str,
                kwargs: dict[str, Any], start: int, stop: int, parent_pid: int,
                board: Board | None = None, slot: int = 1,
                stderr: Connection | None = None) -> None:
    """A worker (slot ``slot``): envs ``start:stop`` of the vector env, each
    ``gym.make(env_id, **kwargs)``, commands from ``conn``, steps from the ``board`` if
    there is one; its standard error into ``stderr`` (``start_worker`` forwards it)."""
    if stderr is not None:
        os.dup2(stderr.fileno(), 2)
        stderr.close()
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
        envs = [gym.make(env_id, **kwargs) for _ in range(start, stop)]
        conn.send((True, None))
        seen = 0  # the last step taken from the board
        known: list[tuple | None] = [None] * (stop - start)  # as the parent's _known
        idle = SpareTime(board, slot, envs) if board is not None else None
        while True:
            command, data = await_command(conn, board, seen, WAIT_SPIN_S, slot, idle)
            if command == "post":
                assert board is not None
                seen = data
                try:
                    answer = step_envs(envs, space, buffer, start,
                                        board.actions[start:stop].copy(),
                                        board.autoreset[start:stop].astype(np.bool_),
                                        bool(board.ctrl[1]), idle.mark)  # type: ignore[union-attr]
                    if post_results(board, start, answer, known):
                        board.ctrl[board.finished + slot] = seen  # before the hand-over
                        board.ctrl[1 + slot] = seen  # last: it hands the results over
                    else:
                        layouts = [info_layout(a[3]) for a in answer]
                        board.ctrl[board.finished + slot] = seen
                        conn.send((True, answer, seen))
                        known = layouts
                        board.ctrl[board.layouts + slot] += 1
                except Exception as exc:  # reported to the parent, raised there
                    board.ctrl[board.finished + slot] = seen
                    conn.send((False, (type(exc).__name__, str(exc), traceback.format_exc()),
                               seen))
                continue
            try:
                if command == "step":
                    answer: Any = step_envs(envs, space, buffer, start, *data)
                elif command == "reset":
                    answer = reset_envs(envs, space, buffer, start, *data)
                elif command == "call":
                    answer = call_envs(envs, *data)
                elif command == "set":
                    answer = set_attrs(envs, *data)
                elif command == "wrapped":
                    answer = [wrapped_in(env, data) for env in envs]
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

# ---------------------------------------------------------------------- starting workers
class WorkerStartError(ValueError):
    """A worker could not be started: what it needs does not reach a process that does
    not run the user's script."""


@contextlib.contextmanager
def _main_module_hidden() -> Iterator[None]:
    """``sys.modules["__main__"]`` replaced by an empty module while a process starts:
    spawn's preparation then names no main module for the child to re-run (it would run
    a script without a main guard again, or fail on ``<stdin>``)."""
    main = sys.modules.get("__main__")
    sys.modules["__main__"] = types.ModuleType("__main__")
    try:
        yield
    finally:
        if main is not None:
            sys.modules["__main__"] = main


class _StderrTail(threading.Thread):
    """Forwards a worker's standard error to this process's and keeps its last
    non-empty line (for ``WorkerProcess.death``)."""

    def __init__(self, conn: Connection, name: str) -> None:
        super().__init__(name=f"{name}-stderr", daemon=True)
        self._conn = conn
        self._partial = b""
        self.last_line = ""

    def run(self) -> None:
        fd = self._conn.fileno()
        try:
            while data := os.read(fd, 65536):
                with contextlib.suppress(OSError):
                    os.write(2, data)
                self._keep(data)
        except OSError:
            pass
        finally:
            self._keep(b"\n")
            with contextlib.suppress(OSError):
                self._conn.close()

    def _keep(self, data: bytes) -> None:
        lines = (self._partial + data).split(b"\n")
        self._partial = lines.pop()[-4096:]  # a line not ended yet, bounded
        for line in reversed(lines):
            if line.strip():
                self.last_line = line.decode(errors="replace").strip()[-500:]
                break


class WorkerProcess:
    """A worker process of the vector env, started by ``start_worker``."""

    def __init__(self, process: Any, tail: _StderrTail) -> None:
        self.process = process
        self._tail = tail

    def death(self) -> str:
        """Why the worker is gone: its exit code or the signal that killed it, and the
        last line it wrote to standard error."""
        self.process.join(timeout=2.0)
        code = self.process.exitcode
        if code is None:
            how = "it closed its pipe but still runs"
        elif code < 0:
            try:
                how = f"killed by signal {signal.Signals(-code).name}"
            except ValueError:
                how = f"killed by signal {-code}"
        else:
            how = f"exit code {code}"
        self._tail.join(timeout=2.0)
        last = self._tail.last_line
        return how + (f"; its last line on stderr: {last}" if last else "")


def start_worker(ctx: Any, name: str, args: tuple) -> WorkerProcess:
    """A daemon process running ``worker_main(*args, stderr)`` from spawn's entry point,
    the user's main module not re-run (``_main_module_hidden``), its standard error
    forwarded here (``_StderrTail``). ``WorkerStartError`` if the arguments reach the
    worker only through the user's script (a class or function defined there)."""
    stderr_r, stderr_w = ctx.Pipe(duplex=False)
    process = ctx.Process(target=worker_main, name=name, daemon=True, args=(*args, stderr_w))
    try:
        with _main_module_hidden():
            process.start()
    except (pickle.PicklingError, AttributeError, TypeError) as exc:
        stderr_r.close()
        stderr_w.close()
        raise WorkerStartError(
            f"the vector env's arguments cannot reach its worker processes: {exc}. Workers "
            "start without running your script, so pass only what an importable module "
            "defines (not a class, function or lambda of your script or notebook), or "
            "step every env in this process with workers=1") from None
    stderr_w.close()
    tail = _StderrTail(stderr_r, name)
    tail.start()
    return WorkerProcess(process, tail)
