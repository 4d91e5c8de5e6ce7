"""Sweeps over seed ranges in a process pool: jobs streamed, workers bounded.

``stream`` runs a function over an iterable of jobs and yields the results in job order.
It never materialises the job list: at most ``IN_FLIGHT_PER_WORKER`` jobs per worker are
submitted ahead, so ``--seeds 0:100000000`` costs as little memory as ``--seeds 0:10``
and the first results arrive as soon as the first jobs finish.

Workers ignore Ctrl-C (the parent handles it: it stops submitting, cancels what is
queued and terminates the workers), die with their parent (Linux ``PR_SET_PDEATHSIG``,
and a check of the parent's pid at start-up), and are capped by ``resolve_workers`` at
the number of jobs, the CPUs this process may use and the memory available.
"""

from __future__ import annotations

import contextlib
import ctypes
import multiprocessing
import os
import signal
import sys
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import TypeVar

J = TypeVar("J")
R = TypeVar("R")

IN_FLIGHT_PER_WORKER: int = 2
"""Jobs submitted ahead per worker: enough to keep every worker busy while the parent
collects a result, few enough that the queue stays a handful of small tuples."""

WORKER_MEMORY_BYTES: int = 600 * 2**20
"""Memory one sweep worker may need (renderer pixel geometry, scene raster, numba):
≈ 350–450 MB measured for an ``evaluate``/``stress`` worker, with margin [bytes]."""

WORKER_JOIN_TIMEOUT_S: float = 5.0
"""How long an interrupted sweep waits for a terminated worker to exit [s]."""

_PR_SET_PDEATHSIG = 1  # linux/prctl.h


class WorkerDied(RuntimeError):
    """A worker process of a sweep ended abruptly (killed, e.g. by the kernel when memory
    ran out): the jobs in flight are lost, the results before them are not."""


def available_cpus() -> int:
    """The CPUs this process may run on."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return max(1, os.cpu_count() or 1)


def available_memory_bytes() -> int | None:
    """``MemAvailable`` of /proc/meminfo, or None where there is none."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError):
        pass
    return None


def resolve_workers(requested: int | None, jobs: int | None) -> tuple[int, str | None]:
    """The worker count to use and, if ``requested`` was lowered, why (to tell the user).
    Default: the CPUs available. Capped at the number of ``jobs`` (None: unknown, e.g. an
    endless range), the CPUs (the jobs are CPU-bound: more processes only share them) and
    the memory available for ``WORKER_MEMORY_BYTES`` per worker."""
    cpus = available_cpus()
    want = cpus if requested is None else requested
    if want < 1:
        raise ValueError(f"workers must be ≥ 1, got {want}")
    limits: list[tuple[int, str]] = [(cpus, f"{cpus} CPU(s) available")]
    if jobs is not None:
        limits.append((max(1, jobs), f"{jobs} job(s)"))
    mem = available_memory_bytes()
    if mem is not None:
        limits.append((max(1, mem // WORKER_MEMORY_BYTES),
                       f"{mem / 2**30:.1f} GiB of memory available for "
                       f"{WORKER_MEMORY_BYTES / 2**20:.0f} MiB per worker"))
    n, why = want, None
    for cap, reason in limits:
        if cap < n:
            n, why = cap, reason
    if requested is not None and n < requested:
        return n, f"--workers {requested} capped to {n}: {why}"
    return n, None


def _init_worker(parent_pid: int) -> None:
    # Ctrl-C reaches the whole process group; only the parent decides what to do. The
    # parent's SIGTERM/SIGHUP handlers (tfalda_sim.interrupts) are not the worker's: the
    # parent terminates its workers with SIGTERM.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGHUP, signal.SIG_DFL)
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    if os.getppid() != parent_pid:  # the parent died before prctl took effect
        os._exit(1)


def _terminate(pool: ProcessPoolExecutor) -> None:
    """Stop the workers now: an interrupted sweep does not wait for running jobs."""
    terminate = getattr(pool, "terminate_workers", None)  # Python ≥ 3.14
    if terminate is not None:
        terminate()
        return
    # The private process table is the only handle before 3.14; shutdown() drops it, so
    # take it first.
    procs = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in procs:
        with contextlib.suppress(Exception):
            proc.terminate()
    for proc in procs:
        with contextlib.suppress(Exception):
            proc.join(timeout=WORKER_JOIN_TIMEOUT_S)


def stream(fn: Callable[[J], R], jobs: Iterable[J], *, workers: int = 1) -> Iterator[R]:
    """``fn(job)`` for every job, results in job order, at most
    ``workers × IN_FLIGHT_PER_WORKER`` jobs ahead. ``workers == 1`` runs in this process.
    Closing the generator early (``break``, an exception, Ctrl-C) terminates the pool."""
    if workers < 1:
        raise ValueError(f"workers must be ≥ 1, got {workers}")
    if workers == 1:
        for job in jobs:
            yield fn(job)
        return
    # fork on Linux, also where it is not the default (3.14+: forkserver): the workers must
    # be our children for PR_SET_PDEATHSIG to tie them to this process.
    context = (multiprocessing.get_context("fork") if sys.platform.startswith("linux")
               else None)
    pool = ProcessPoolExecutor(max_workers=workers, initializer=_init_worker,
                               initargs=(os.getpid(),), mp_context=context)
    finished = False
    try:
        pending: deque[Future[R]] = deque()
        it = iter(jobs)
        limit = workers * IN_FLIGHT_PER_WORKER
        for job in it:
            pending.append(pool.submit(fn, job))
            if len(pending) >= limit:
                break
        while pending:
            try:
                result = pending.popleft().result()
            except BrokenProcessPool:
                raise WorkerDied("a worker process died (killed, perhaps for lack of "
                                 "memory: try fewer --workers)") from None
            for job in it:
                pending.append(pool.submit(fn, job))
                break
            yield result
        finished = True
    finally:
        if finished:
            pool.shutdown(wait=True)
        else:
            _terminate(pool)
