"""Benchmark of TfaldaTrack-v0: env steps per second against CarRacing-v3, one run.

    python benchmarks/bench_env.py [--steps 3000] [--warmup-steps 6000] [--json]

In one run, with uniformly random actions and resets included (random steering leaves the
road every ≈ 50 steps, so a reset's cost counts), each of our envs timed after
``WARMUP_STEPS`` steps (the steady state of a training run; ``--warmup-steps 20``: a fresh
process's first seconds), the reference after ``REFERENCE_WARMUP_STEPS``:

- Gymnasium's CarRacing-v3, the reference every other figure is divided by (this VM's
  speed drifts by 2× within a day; the ratio does not), stepped in turns with the single
  envs (below), so that their ratios to it hold no drift between measurements either;
- ``gymnasium.make("TfaldaTrack-v0")`` in "lanes" mode (ROIs rendered on demand + TFALDA +
  LIS) and "image" mode (full frame + TFALDA + LIS), on one fixed track (the oval: a reset
  re-uses its scene) and with the default, a new generated track every reset; their
  resets are clocked apart too (mean ms per reset, and generated / fixed with the resets
  off the clock: how much of the gap free resets would close);
- ``gymnasium.make_vec("TfaldaTrack-v0", num_envs=N)`` for N = 1 and 2 (the env's default
  vectorisation mode) and, for comparison, Gymnasium's ``AsyncVectorEnv`` with 2 envs, in
  "lanes" mode on default generated tracks; steps are env steps (N per vector step).
  All of them step the same two streams (``STREAMS``: env i reset with seed i, its
  actions drawn for it before each turn, not timed), "1 env" each stream in a 1-env
  vector env of its own: the same episodes and tracks, so the ratio of 2 envs to 1 is
  the scaling alone, not the luck of different seeds;
- the machine's ceiling for them: the same two streams stepped by single envs in one
  process alone, then in 2 processes at once (pinned one per core, talking to nobody
  while they step). Two busy
  processes share caches, memory bandwidth and, on a VM, the host with its other guests.
  Two figures: their turns' wall clock (a turn lasts until the slower of the two is done:
  two envs on different tracks step at different paces over a turn, so this ceiling
  still holds a synchronisation every ``CHUNK_STEPS`` steps), and the sum of each
  process's own rate over its own stepping time ("each at its own pace": no
  synchronisation at all, the machine alone). A 2-env vector env synchronises every
  step: the own-pace ratio is what the machine gives, the difference is what
  synchronising costs.

Single envs run pinned to one core with OpenCV on one thread (figures per core); the vector
envs get every core of the machine. The single envs (both modes, fixed and generated
tracks) and the reference run interleaved, in rounds of one turn each (``CHUNK_STEPS``
steps; the reference's ≈ 10× slower steps are fewer per turn, ``REFERENCE_STEPS`` in
all), so that the host's drift (± 10 % between runs a minute apart here) does not enter
their ratios; so do the vector envs
(``make_vec`` with 1 and 2 envs, ``AsyncVectorEnv`` and the ceiling), in turns of
``CHUNK_STEPS`` env steps. Needs Box2D for the reference
(``pip install "gymnasium[box2d]"``, in the ``dev`` extra).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import multiprocessing
import os
import sys
import time
from collections.abc import Callable
from multiprocessing.connection import Connection
from typing import Any

import cv2
import gymnasium as gym
import numpy as np
from _machine import machine
from tqdm import tqdm

import tfalda_sim  # noqa: F401  (registers TfaldaTrack-v0)
from tfalda_sim.rendering import scene as scene_module
from tfalda_sim.tracks import generator as generator_module

REFERENCE = "CarRacing-v3 (reference)"
MAKE_VEC_1 = "make_vec, 1 env, lanes, generated"
MAKE_VEC_2 = "make_vec, 2 envs, lanes, generated"
CEILING_1 = "1 process alone, lanes, generated"
CEILING_2 = "2 processes at once, lanes, generated"
CEILING_2_OWN_PACE = "2 processes at once, each at its own pace"
SCALING_CEILING = "2 processes at once / 1 (the machine's ceiling)"
OWN_PACE_CEILING = "2 processes, each at its own pace / 1"
GENERATED_FIXED = "generated / fixed track (lanes)"
DYNAMIC_REAL_CAR = "lanes, fixed track (oval), dynamic car, real-car timing"
DYNAMIC_COST = "step cost: dynamic car + real-car timing / kinematic car (lanes, fixed)"
GENERATED_FIXED_NO_RESETS = "generated / fixed track (lanes), resets off the clock"
WARMUP_STEPS = 6000
"""Steps each of our envs (a single env, or a stream of a vector configuration or of the
ceiling) makes before it is timed (``--warmup-steps``): a training run steps for minutes,
and the figures are its steady state, not a fresh process's first seconds. A new env's
scenes page their atlas memory in as tracks are painted into it (a page fault per 4 KiB
page written first), one memory per env, two per env of a 2-env vector env (one for the
scene it prepares): a fresh 2-env vector env's own process faulted 6980–7660 pages in
its first 3000 env steps, ≈ 600 in the next 3000; and the vector envs' and the ceiling's worker
processes are fresh. ``--warmup-steps 20`` measures the cold start."""

REFERENCE_WARMUP_STEPS = 20
"""CarRacing-v3's warm-up: its rate is flat from the first hundred steps on (ten turns of
200 steps after these 20: 243–279 steps/s, no trend), and its steps are ≈ 15× ours."""


def steps_per_second(env: gym.Env, steps: int, desc: str, quiet: bool) -> dict[str, float]:
    """Random-policy steps/s of one env over ``steps`` steps (resets included; warmed up
    first, then stepped from ``reset(seed=1)``)."""
    return interleaved_steps_per_second({desc: lambda: env}, steps, quiet)[desc]


CHUNK_STEPS = 300
"""Steps per turn when single envs run interleaved (``interleaved_steps_per_second``)."""

REFERENCE_STEPS = 2000
"""CarRacing-v3's steps at most (≈ 10 ms each here), spread over the rounds of the
single envs' turns."""


def interleaved_steps_per_second(makes: dict[str, Callable[[], gym.Env]], steps: int,
                                 quiet: bool, totals: dict[str, int] | None = None,
                                 warmups: dict[str, int] | None = None
                                 ) -> dict[str, dict[str, float | None]]:
    """Random-policy steps/s of several envs at once (resets included): each warmed up by
    ``warmups[name]`` steps (``WARMUP_STEPS`` if not given; an episode's end resets it),
    reset with seed 1, then all stepped in rounds, one turn each, until each has made its
    steps (``steps``, or ``totals[name]``); an env's time is the sum of its turns, of which
    its resets' share is clocked too (``ms_per_reset``, a reset's mean, None without one;
    ``steps_per_s_without_resets``, the rate of its steps alone: what free resets would
    give). There are as many rounds as ``steps`` has turns of ``CHUNK_STEPS``, and an env
    with other ``totals`` spreads its steps over the same rounds (a slower reference makes
    fewer steps, in the same minutes as the others: the host's drift stays out of their
    ratios). What envs of this process share between resets (``forget_shared_tracks``) is
    dropped before every turn: envs of the same seeds draw the same tracks (the "lanes"
    and "image" envs on generated tracks), and the second would find the first's."""
    totals = {name: (totals or {}).get(name, steps) for name in makes}
    warmups = {name: (warmups or {}).get(name, WARMUP_STEPS) for name in makes}
    if any(n < 1 for n in totals.values()):
        raise ValueError(f"every env needs at least one step, got {totals}")
    rounds = -(-steps // CHUNK_STEPS)
    turn = {name: -(-n // rounds) for name, n in totals.items()}
    envs: dict[str, gym.Env] = {}
    clock = dict.fromkeys(makes, 0.0)
    reset_clock = dict.fromkeys(makes, 0.0)  # the part of ``clock`` spent in resets
    resets = dict.fromkeys(makes, 0)
    done = dict.fromkeys(makes, 0)
    try:
        for name, make in makes.items():
            envs[name] = env = make()
            env.action_space.seed(0)
            env.reset(seed=0)
            for _ in range(warmups[name]):
                _, _, terminated, truncated, _ = env.step(env.action_space.sample())
                if terminated or truncated:
                    env.reset()
            env.reset(seed=1)
        with tqdm(total=sum(totals.values()), desc=" + ".join(envs), disable=quiet,
                  file=sys.stderr) as bar:
            while any(done[name] < totals[name] for name in envs):
                for name, env in envs.items():
                    n = min(turn[name], totals[name] - done[name])
                    forget_shared_tracks()  # the same seeds draw the same tracks
                    t0 = time.perf_counter()
                    for _ in range(n):
                        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
                        if terminated or truncated:
                            r0 = time.perf_counter()
                            env.reset()
                            reset_clock[name] += time.perf_counter() - r0
                            resets[name] += 1
                    clock[name] += time.perf_counter() - t0
                    done[name] += n
                    bar.update(n)
    finally:
        for env in envs.values():
            env.close()
    return {name: {"steps_per_s": totals[name] / clock[name],
                   "ms_per_step": 1000 * clock[name] / totals[name],
                   "episodes": resets[name] + 1,
                   "ms_per_reset": (1000 * reset_clock[name] / resets[name] if resets[name]
                                    else None),
                   "steps_per_s_without_resets": totals[name] / (clock[name]
                                                                 - reset_clock[name])}
            for name in envs}


STREAMS = 2
"""Env streams every vector configuration and the ceiling step: stream i is an env reset
with seed i (autoreset then draws its tracks) and driven by the actions of its own
generator (``stream_rng(i)``, ``stream_actions``); the ceiling's single envs reset the
step after an episode's end, spending its action, as a vector env's autoreset does. A
vector env of 2 envs steps both at once; "1 env" steps each in its own 1-env vector env
(one process alone: each in turn): the same episodes, the same tracks, the same
actions, so a ratio compares the same work. (Two different seeds drew 47 and 57 episodes
in 3000 steps here: ±2 % on a ratio from the seeds alone.)"""


ACTION_SEED = 7
"""Entropy the streams' action generators add to the stream number."""


def stream_rng(stream: int) -> np.random.Generator:
    """The action generator of ``stream`` (apart from the env's own, seeded with
    ``stream``)."""
    return np.random.default_rng([ACTION_SEED, stream])


def stream_actions(rng: np.random.Generator, space: gym.spaces.Box, count: int
                   ) -> np.ndarray:
    """A stream's next ``count`` actions from its generator ``rng`` (``stream_rng``):
    ``(count, *space.shape)``, uniform in the Box. Drawn before a turn, not timed:
    Gymnasium's ``Box.sample`` costs 20 µs alone and ≈ 55 µs between env steps here, more
    than a tenth of a step, and a vector env's one sample for all its envs would count
    for it less of that than one env's."""
    return rng.uniform(space.low, space.high, (count, *space.shape)).astype(space.dtype)


def forget_shared_tracks() -> None:
    """Drop what envs of this process share between resets: the generated tracks
    (``GENERATE_CACHE_SIZE`` of them) and the last scene's painted marking map. The
    configurations measured together step the same streams, so they draw the same tracks:
    one that found another's track painted would paint less and read faster than it is.
    Called before every turn."""
    generator_module._generate_cached.cache_clear()  # looked up now: never a stale binding
    scene_module._last_marking.clear()


def _make_all(makes: list[Callable[[], gym.vector.VectorEnv]]) -> list[gym.vector.VectorEnv]:
    """The vector envs ``makes`` give, or none: those made are closed if one fails."""
    made: list[gym.vector.VectorEnv] = []
    try:
        for make in makes:
            made.append(make())
    except BaseException:
        for venv in made:
            with contextlib.suppress(Exception):
                venv.close()
        raise
    return made


class _VectorTurns:
    """Vector envs that together step the ``STREAMS`` streams (env i of the
    concatenation: stream i), in turns (``interleaved_vector_steps_per_second``)."""

    def __init__(self, venvs: list[gym.vector.VectorEnv], warmup: int) -> None:
        self.venvs = venvs
        try:
            first = 0
            self.streams: list[range] = []
            for venv in venvs:
                self.streams.append(range(first, first + venv.num_envs))
                first += venv.num_envs
            if first != STREAMS:
                raise ValueError(f"the vector envs hold {first} envs, not {STREAMS}")
            self.num_envs = STREAMS
            self.space = venvs[0].single_action_space
            self.rngs = [stream_rng(i) for i in range(STREAMS)]
            forget_shared_tracks()
            for venv, streams in zip(venvs, self.streams, strict=True):
                venv.reset(seed=streams.start)
            self._step(warmup)
        except BaseException:
            self.close()
            raise

    def _step(self, calls: int) -> tuple[float, int]:
        """``calls`` steps of every stream, untimed turn set-up aside: time [s], episodes."""
        actions = [stream_actions(rng, self.space, calls) for rng in self.rngs]
        elapsed, episodes = 0.0, 0
        for venv, streams in zip(self.venvs, self.streams, strict=True):
            batch = np.stack([actions[i] for i in streams], axis=1)
            t0 = time.perf_counter()
            for k in range(calls):
                _, _, terminated, truncated, _ = venv.step(batch[k])
                episodes += int(np.count_nonzero(terminated | truncated))
            elapsed += time.perf_counter() - t0
        return elapsed, episodes

    def turn(self, calls: int) -> tuple[float, int]:
        """``calls`` steps of every stream: their time [s] and the episodes they ended."""
        forget_shared_tracks()
        return self._step(calls)

    def close(self) -> None:
        for venv in self.venvs:  # every one, whatever one of them raises
            with contextlib.suppress(Exception):
                venv.close()


def _solo_process(conn: Connection, cpu: int | None, streams: list[int], warmup: int
                  ) -> None:
    """Single envs stepping ``streams`` in one process, pinned to ``cpu``, one after
    another: ``warmup`` steps of each (answered with None), then ``n`` steps of each
    stream per message ``n`` (0 ends it), answered with (time [s], episodes)."""
    if cpu is not None:
        os.sched_setaffinity(0, {cpu})
    cv2.setNumThreads(1)
    # Gymnasium's NEXT_STEP autoreset, as the vector envs have it: the step after an
    # episode's last resets instead, spending its action (the same episodes as theirs).
    envs = [gym.wrappers.Autoreset(gym.make("TfaldaTrack-v0")) for _ in streams]
    rngs = [stream_rng(i) for i in streams]

    def step(n: int) -> tuple[float, int]:
        elapsed, episodes = 0.0, 0
        for env, rng in zip(envs, rngs, strict=True):
            actions = stream_actions(rng, env.action_space, n)
            t0 = time.perf_counter()
            for k in range(n):
                _, _, terminated, truncated, _ = env.step(actions[k])
                episodes += int(terminated or truncated)
            elapsed += time.perf_counter() - t0
        return elapsed, episodes

    for env, i in zip(envs, streams, strict=True):
        env.reset(seed=i)
    step(warmup)
    conn.send(None)
    while n := conn.recv():
        forget_shared_tracks()
        conn.send(step(n))
    for env in envs:
        env.close()


class _SoloProcessTurns:
    """The ``STREAMS`` streams stepped by single envs in ``n`` processes, one per core
    (stream i in process ``i % n``), at the same time and talking to nobody while they
    step: with ``n`` = 2, what the machine gives 2 busy processes of this workload at once
    (its cache, memory bandwidth, and the host's other guests share), the ceiling of any
    vector env; with 1, the same streams one after another. A turn lasts until the slower
    process is done."""

    def __init__(self, n: int, cpus: list[int] | None, warmup: int) -> None:
        ctx = multiprocessing.get_context("spawn")
        self.warmup = warmup  # steps each stream made before its first turn
        self.num_envs = STREAMS
        self.own_s = [0.0] * n  # each process's own stepping time [s]
        self.steps_each = [0] * n  # env steps each process made
        self.per_process = [list(range(i, STREAMS, n)) for i in range(n)]
        self.conns: list[Connection] = []
        self.procs: list[multiprocessing.process.BaseProcess] = []
        try:
            for i in range(n):
                parent, child = ctx.Pipe()
                cpu = cpus[i % len(cpus)] if cpus else None
                proc = ctx.Process(target=_solo_process,
                                   args=(child, cpu, self.per_process[i], warmup),
                                   daemon=True)
                proc.start()
                child.close()  # the child's end is the child's: its death reads as EOF here
                self.conns.append(parent)
                self.procs.append(proc)
            for w in range(n):
                self._answer(w)  # warmed up
        except BaseException:
            self.close()
            raise

    def _answer(self, w: int) -> Any:
        try:
            return self.conns[w].recv()
        except EOFError:
            self.procs[w].join(timeout=5)
            raise RuntimeError(f"the single-env process {w} of the ceiling died (exit code "
                               f"{self.procs[w].exitcode})") from None

    def turn(self, calls: int) -> tuple[float, int]:
        """``calls`` steps of every stream: the turn's wall clock [s] and episodes."""
        t0 = time.perf_counter()
        for conn in self.conns:
            conn.send(calls)
        answers = [self._answer(w) for w in range(len(self.conns))]
        for w, (own_s, _) in enumerate(answers):
            self.own_s[w] += own_s
            self.steps_each[w] += calls * len(self.per_process[w])
        return time.perf_counter() - t0, sum(episodes for _, episodes in answers)

    def own_pace_steps_per_s(self) -> float:
        """The sum of each process's steps/s over its own stepping time (not waiting for
        the slower one at the end of a turn, nor for the messages)."""
        return sum(n / s for n, s in zip(self.steps_each, self.own_s, strict=True) if s > 0)

    def close(self) -> None:
        for conn in self.conns:
            with contextlib.suppress(OSError):
                conn.send(0)
        for proc in self.procs:
            proc.join(timeout=10)
            if proc.is_alive():
                proc.kill()


def interleaved_vector_steps_per_second(makes: dict[str, Callable[[], Any]], steps: int,
                                        quiet: bool, warmup: int = WARMUP_STEPS
                                        ) -> dict[str, dict[str, float]]:
    """Env steps/s of several configurations that each step the ``STREAMS`` streams (autoreset
    inside): each made, reset and warmed up (``warmup`` steps a stream; a
    ``_SoloProcessTurns`` is made warmed up), then all stepped in turns of about
    ``CHUNK_STEPS`` env steps (``CHUNK_STEPS // STREAMS`` steps a stream) until each has
    made about ``steps``; one's time is the sum of its turns. ``makes`` give a list of
    vector envs holding ``STREAMS`` envs together (``_VectorTurns``), or a
    ``_SoloProcessTurns``. Idle vector envs' workers sleep on their pipes (waking every
    ``BOARD_NAP_S``), so a turn has the machine to itself."""
    runners: dict[str, Any] = {}
    try:
        for name, make in makes.items():
            made = make()
            if isinstance(made, _SoloProcessTurns) and made.warmup != warmup:
                made.close()
                raise ValueError(f"{name}: its processes warmed up {made.warmup} steps a "
                                 f"stream, the others {warmup}: the streams would differ")
            runners[name] = (made if isinstance(made, _SoloProcessTurns)
                             else _VectorTurns(made, warmup))
        calls = max(1, steps // STREAMS)
        done = dict.fromkeys(runners, 0)
        clock = dict.fromkeys(runners, 0.0)
        episodes = dict.fromkeys(runners, 0)
        with tqdm(total=len(runners) * calls * STREAMS, desc=" + ".join(runners),
                  disable=quiet, file=sys.stderr) as bar:
            while any(done[k] < calls for k in runners):
                for name, runner in runners.items():
                    n = min(max(1, CHUNK_STEPS // STREAMS), calls - done[name])
                    if n <= 0:
                        continue
                    elapsed, ended = runner.turn(n)
                    clock[name] += elapsed
                    episodes[name] += ended
                    done[name] += n
                    bar.update(n * STREAMS)
    finally:
        for runner in runners.values():
            runner.close()
    results = {name: {"steps_per_s": calls * STREAMS / clock[name],
                      "ms_per_step": 1000 * clock[name] / (calls * STREAMS),
                      "episodes": episodes[name]} for name in runners}
    for name, r in runners.items():
        if isinstance(r, _SoloProcessTurns):
            results[name]["own_pace_steps_per_s"] = r.own_pace_steps_per_s()
    return results


def run(steps: int, quiet: bool, warmup: int = WARMUP_STEPS) -> dict[str, Any]:
    """Every configuration, each after ``warmup`` steps (an env, a stream; the reference
    ``REFERENCE_WARMUP_STEPS``), then ``steps``."""
    all_cpus = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else None
    results: dict[str, dict[str, float] | str] = {}

    def one_core() -> None:  # per-core figures
        if all_cpus is not None:
            os.sched_setaffinity(0, {min(all_cpus)})
        cv2.setNumThreads(1)

    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")  # CarRacing draws with pygame
    one_core()
    singles: dict[str, Callable[[], gym.Env]] = {REFERENCE: lambda: gym.make("CarRacing-v3")}
    for mode in ("lanes", "image"):
        singles[f"{mode}, fixed track (oval)"] = (
            lambda mode=mode: gym.make("TfaldaTrack-v0", observation=mode, track="oval"))
        singles[f"{mode}, new generated track per reset"] = (
            lambda mode=mode: gym.make("TfaldaTrack-v0", observation=mode))
    # The real car: the dynamic single-track model and the real-car timing (latency,
    # jitter, servo), on the same fixed track.
    singles[DYNAMIC_REAL_CAR] = lambda: gym.make("TfaldaTrack-v0", track="oval",
                                                 vehicle="dynamic", timing="real-car")
    # The reference steps in the same rounds as the envs divided by it (≈ 10× slower a
    # step: fewer steps, the same minutes).
    reference_steps = min(steps, REFERENCE_STEPS)
    try:
        gym.make("CarRacing-v3").close()
    except Exception as exc:  # the reference may be missing: say so in the table
        results[REFERENCE] = f"not available: {type(exc).__name__}: {exc}"
        del singles[REFERENCE]
    warmups = {name: warmup for name in singles} | {REFERENCE: REFERENCE_WARMUP_STEPS}
    results.update(interleaved_steps_per_second(singles, steps, quiet,
                                                {REFERENCE: reference_steps}, warmups))
    results = {REFERENCE: results[REFERENCE],
               **{k: v for k, v in results.items() if k != REFERENCE}}
    if all_cpus is not None:  # the vector envs get the whole machine
        os.sched_setaffinity(0, all_cpus)
    cpus = sorted(all_cpus) if all_cpus is not None else None
    results.update(interleaved_vector_steps_per_second({
        MAKE_VEC_1: lambda: _make_all(
            [lambda: gym.make_vec("TfaldaTrack-v0", num_envs=1)] * STREAMS),
        MAKE_VEC_2: lambda: [gym.make_vec("TfaldaTrack-v0", num_envs=STREAMS)],
        "AsyncVectorEnv, 2 envs, lanes, generated":
            lambda: [gym.make_vec("TfaldaTrack-v0", num_envs=STREAMS,
                                  vectorization_mode="async")],
        CEILING_1: lambda: _SoloProcessTurns(1, cpus, warmup),
        CEILING_2: lambda: _SoloProcessTurns(2, cpus, warmup),
    }, steps, quiet, warmup))
    pair = results.get(CEILING_2)
    if isinstance(pair, dict):
        own = pair["own_pace_steps_per_s"]
        results[CEILING_2_OWN_PACE] = {"steps_per_s": own, "ms_per_step": 1000 / own,
                                       "episodes": pair["episodes"]}
    reference = results[REFERENCE]
    ref_rate = reference["steps_per_s"] if isinstance(reference, dict) else None
    for r in results.values():
        if isinstance(r, dict) and ref_rate:
            r["ratio_to_car_racing"] = r["steps_per_s"] / ref_rate
    scaling = {}
    for label, (one, two) in {"make_vec 2 envs / 1 env": (MAKE_VEC_1, MAKE_VEC_2),
                              SCALING_CEILING: (CEILING_1, CEILING_2)}.items():
        a, b = results.get(one), results.get(two)
        if isinstance(a, dict) and isinstance(b, dict):
            scaling[label] = b["steps_per_s"] / a["steps_per_s"]
    alone = results.get(CEILING_1)
    if isinstance(alone, dict) and isinstance(pair, dict):  # both at their own pace
        scaling[OWN_PACE_CEILING] = (pair["own_pace_steps_per_s"]
                                     / alone["own_pace_steps_per_s"])
    fixed = results.get("lanes, fixed track (oval)")
    real_car = results.get(DYNAMIC_REAL_CAR)
    if isinstance(fixed, dict) and isinstance(real_car, dict):  # cost of a step, not rate
        scaling[DYNAMIC_COST] = fixed["steps_per_s"] / real_car["steps_per_s"]
    generated = results.get("lanes, new generated track per reset")
    if isinstance(fixed, dict) and isinstance(generated, dict):
        scaling[GENERATED_FIXED] = generated["steps_per_s"] / fixed["steps_per_s"]
        # What free resets would leave of the gap: the rest is the new ground a new
        # track's episode paints as it comes into view, and the tracks' own content.
        scaling[GENERATED_FIXED_NO_RESETS] = (generated["steps_per_s_without_resets"]
                                              / fixed["steps_per_s_without_resets"])
    m = machine()
    m["pinned_to_one_core"] = "single envs only"
    return {"machine": m, "steps": steps, "warmup_steps": warmup,
            "reference_warmup_steps": REFERENCE_WARMUP_STEPS, "envs": results,
            "ratios": scaling}


def table(result: dict[str, Any]) -> str:
    """``run``'s result as the printed table: the machine, then per configuration its
    steps/s, ms/step, episodes, ratio to CarRacing-v3 and mean reset [ms] (single envs:
    a vector env's resets are inside its steps), then the ratios."""
    m = result["machine"]
    lines = [f"machine: {m['cores']} cores of {m['cpu']} ({m['simd']}; single envs pinned "
             f"to one, OpenCV threads 1), Python {m['python']}; {result['steps']} steps "
             f"after {result['warmup_steps']} warm-up steps per env or stream "
             f"(CarRacing-v3: {result['reference_warmup_steps']})"]
    width = 1 + max(map(len, [*result["envs"], *result["ratios"]]))
    lines.append(f"{'configuration':<{width}}{'steps/s':>9}{'ms/step':>9}{'episodes':>9}"
                 f"{'× CarRacing':>13}{'ms/reset':>10}")
    for name, r in result["envs"].items():
        if isinstance(r, str):
            lines.append(f"{name:<{width}}{r}")
        else:
            reset = r.get("ms_per_reset")
            lines.append(f"{name:<{width}}{r['steps_per_s']:>9.0f}{r['ms_per_step']:>9.3f}"
                         f"{r['episodes']:>9.0f}"
                         f"{r.get('ratio_to_car_racing', float('nan')):>12.2f}×"
                         f"{'–' if reset is None else f'{reset:.3f}':>10}")
    for name, ratio in result["ratios"].items():
        lines.append(f"{name:<{width}}{ratio:>9.2f}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=3000, help="env steps per configuration")
    parser.add_argument("--warmup-steps", type=int, default=WARMUP_STEPS,
                        help="steps each of our envs (a vector configuration: each stream) "
                             "makes before it is timed; 20 measures the cold start "
                             f"(CarRacing-v3: always {REFERENCE_WARMUP_STEPS})")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    if args.steps < 1:
        parser.error("--steps must be ≥ 1")
    if args.warmup_steps < 0:
        parser.error("--warmup-steps must be ≥ 0")
    result = run(args.steps, quiet=args.json, warmup=args.warmup_steps)
    if args.json:
        print(json.dumps(result))
        return 0
    print(table(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
