"""Sweeps over seed ranges in a process pool: jobs streamed, workers bounded.

``stream`` runs a function over an iterable of jobs and yields the results in job order.
It never materialises the job list: at most ``IN_FLIGHT_PER_WORKER`` jobs per worker are
submitted ahead, so ``--seeds 0:100000000`` costs as little memory as ``--seeds 0:10``
and the first results arrive as soon as the first jobs finish.

Workers ignore Ctrl-C (the parent handles it: it stops submitting, cancels what is
queued and terminates the workers), die with their parent (Linux ``PR_SET_PDEATHSIG``,
and a check of the parent's pid at start-up), and are capped by ``resolve_workers`` at
the number of jobs, the CPUs this process may use and the memory available.

``ray_stream`` is the same contract on Ray (the optional ``ray`` extra): the same job
function, the same bounded window of tasks in flight, results in job order. ``Backend``
picks one of the two; every sweep command goes through it (``--backend local|ray``).
"""

from __future__ import annotations

import contextlib
import ctypes
import itertools
import logging
import multiprocessing
import os
import signal
import socket
import sys
import threading
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from typing import Any, Generic, Literal, TypeVar

J = TypeVar("J")
R = TypeVar("R")
T = TypeVar("T")

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
    # A worker killed while it writes a result into the result pipe leaves half a message
    # there; the pool's manager thread then waits for the rest for ever — and so does the
    # interpreter's exit, which joins that thread. This process's own copy of the pipe's
    # writing end is all that keeps it open once the workers are dead: closed, the manager
    # reads the end of the pipe, counts the pool as broken and ends. Taken before
    # shutdown(), which drops the private handles.
    results = getattr(pool, "_result_queue", None)
    terminate = getattr(pool, "terminate_workers", None)  # Python ≥ 3.14
    if terminate is not None:
        procs = list((getattr(pool, "_processes", None) or {}).values())
        terminate()
    else:
        # The private process table is the only handle before 3.14.
        procs = list((getattr(pool, "_processes", None) or {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        for proc in procs:
            with contextlib.suppress(Exception):
                proc.terminate()
    for proc in procs:
        with contextlib.suppress(Exception):
            proc.join(timeout=WORKER_JOIN_TIMEOUT_S)
            if proc.is_alive():  # SIGTERM not acted on in time: no worker may outlive us
                proc.kill()
                proc.join(timeout=WORKER_JOIN_TIMEOUT_S)
    writer = getattr(results, "_writer", None)
    if writer is not None:
        with contextlib.suppress(Exception):
            writer.close()


def _in_job_order(submit: Callable[[J], T], collect: Callable[[T], R], jobs: Iterable[J],
                  limit: int, pending: deque[T]) -> Iterator[R]:
    """The window both backends keep: ``submit`` jobs (pulled lazily) until ``limit`` are in
    ``pending`` (the caller's, to cancel on an early close), then ``collect`` the oldest,
    submit the next job and yield the result: results in job order, never more than
    ``limit`` jobs ahead."""
    it = iter(jobs)
    for job in itertools.islice(it, limit):
        pending.append(submit(job))
    while pending:
        result = collect(pending[0])
        pending.popleft()
        for job in it:
            pending.append(submit(job))
            break
        yield result


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
    # be our children for PR_SET_PDEATHSIG to tie them to this process. But spawn (fork +
    # exec: our children too) in a process that has imported Ray: its threads keep running
    # after ray.shutdown(), and a fork copies whatever lock one of them holds (a test-suite
    # run hung so, both workers waiting on one semaphore).
    ray_here = "ray" in sys.modules
    context = (multiprocessing.get_context("spawn" if ray_here else "fork")
               if sys.platform.startswith("linux") else None)
    pool = ProcessPoolExecutor(max_workers=workers, initializer=_init_worker,
                               initargs=(os.getpid(),), mp_context=context)
    def collect(future: Future[R]) -> R:
        try:
            return future.result()
        except BrokenProcessPool:
            raise WorkerDied("a worker process died (killed, perhaps for lack of "
                             "memory: try fewer --workers)") from None

    finished = False
    try:
        yield from _in_job_order(lambda job: pool.submit(fn, job), collect, jobs,
                                 workers * IN_FLIGHT_PER_WORKER, deque())
        finished = True
    finally:
        if finished:
            pool.shutdown(wait=True)
        else:
            _terminate(pool)


BACKENDS: tuple[str, ...] = ("local", "ray")
"""Where a sweep's jobs run: this machine's process pool, or Ray (a local Ray started for
the sweep, or a running cluster at ``--ray-address``)."""

RAY_EXTRA_HINT = "pip install 'tfalda-sim[ray]'"
"""How to get Ray: the optional extra."""

RAY_POLL_S: float = 0.2
"""How long one ``ray.wait`` blocks: short, so that a Ctrl-C is seen at once."""


class RayUnavailable(RuntimeError):
    """``--backend ray`` without Ray installed, or a cluster that cannot be reached."""


def import_ray() -> Any:
    """The ``ray`` module, or ``RayUnavailable`` naming the extra to install."""
    try:
        import ray
    except ImportError:
        raise RayUnavailable(f"--backend ray needs Ray, the optional extra: "
                             f"{RAY_EXTRA_HINT}") from None
    return ray


RAY_CONNECT_TIMEOUT_S: float = 5.0
"""How long a Ray cluster's address may take to accept a connection [s] before it counts
as unreachable: ``ray.init`` itself retries an address nobody answers on without end,
logging a warning every few seconds (ray-project/ray#22413, #46863)."""

def _address_hint(client: bool) -> str:
    """What a ``--ray-address`` of the form given should be."""
    if client:
        return ("give ray://HOST:PORT of the head node's Ray Client server (port 10001 "
                "unless it was told otherwise)")
    return ("give the address `ray start --head` printed on the head node (HOST:PORT, port "
            "6379 unless it was told otherwise), or \"auto\" on a node of the cluster")


def _split_ray_address(address: str) -> tuple[str, str]:
    """``(host, port)`` of ``HOST:PORT`` or ``ray://HOST:PORT`` (an IPv6 host in brackets),
    or ``RayUnavailable`` naming what keeps ``address`` from being one. Checked here: Ray
    answers a malformed address with advice about its own command line (an ``--address``
    flag, ``RAY_ADDRESS``) or, for a web address, with a list cut at its first line."""
    client = address.startswith("ray://")

    def malformed(why: str) -> RayUnavailable:
        return RayUnavailable(f"--ray-address {address!r} is not a Ray cluster address: {why}; "
                              f"{_address_hint(client)}")

    scheme, sep, rest = address.partition("://")
    if sep and scheme != "ray":
        raise malformed(f"{scheme[:20]}:// is a web address (a dashboard's or the Jobs API's), "
                        "not the cluster's")
    rest = rest if sep else address
    if rest.startswith("["):
        host, closed, tail = rest[1:].partition("]")
        if not closed:
            raise malformed("the bracket of the IPv6 host is not closed")
        if tail and not tail.startswith(":"):
            raise malformed("after the IPv6 host's bracket comes :PORT")
        port = tail[1:]
    else:
        host, colon, port = rest.rpartition(":")
        if not colon:
            host, port = rest, ""
        if ":" in host:
            raise malformed(f"an IPv6 host goes in brackets: [{rest[:60]}]:PORT")
    if not host:
        raise malformed("no host")
    if not port:
        raise malformed("no port")
    return host, port


def check_ray_address(address: str) -> None:
    """Raise ``RayUnavailable`` if ``address`` cannot be connected to: not of the form
    ``HOST:PORT`` or ``ray://HOST:PORT`` (an IPv6 host in brackets) nor ``"auto"`` or
    ``"local"``, a host name that is not one or does not resolve, a port that is no number
    or out of range, a refused connection or none within ``RAY_CONNECT_TIMEOUT_S``.
    ``"auto"`` (the cluster this node belongs to) is ``ray.init``'s to find."""
    if address in ("auto", "local"):
        return
    client = address.startswith("ray://")
    host, port = _split_ray_address(address)

    def unreachable(reason: str) -> RayUnavailable:
        return RayUnavailable(f"could not connect to the Ray cluster at {address}: {reason}; "
                              f"{_address_hint(client)}")

    if not (port.isascii() and port.isdigit()):  # "²".isdigit() is True, int("²") fails
        raise unreachable(f"port {port!r} is not a number")
    if len(port) > 5 or not 0 < int(port) < 65536:
        raise unreachable(f"port {port} is out of range (1-65535)")
    try:
        with socket.create_connection((host, int(port)), timeout=RAY_CONNECT_TIMEOUT_S):
            pass
    except socket.gaierror:
        raise unreachable(f"host {host!r} is not known") from None
    except (UnicodeError, ValueError):  # the IDNA codec: an empty or a too long label
        raise unreachable(f"{host!r} is not a valid host name") from None
    except ConnectionRefusedError:
        raise unreachable(f"nothing listens on port {port} of {host}") from None
    except TimeoutError:
        raise unreachable(f"{host}:{port} did not answer within "
                          f"{RAY_CONNECT_TIMEOUT_S:g} s") from None
    except OSError as exc:
        raise unreachable(exc.strerror or str(exc) or type(exc).__name__) from None


def _call(fn: Callable[[J], R], job: J) -> R:
    """A Ray task: the job function, the very one the local pool runs."""
    return fn(job)


def ray_init_failure(address: str | None, exc: BaseException) -> str:
    """One line for a ``ray.init`` that failed: Ray's first sentence (the rest is advice
    for Ray's own command line: its ``--address`` flag, ``RAY_ADDRESS``), then ours."""
    text = str(exc).strip()
    first = text.splitlines()[0] if text else type(exc).__name__
    if address is None:
        return f"could not start a local Ray: {first}"
    if address == "auto" and isinstance(exc, ConnectionError):
        return ("could not connect to the Ray cluster at auto: no Ray runs on this machine "
                "(\"auto\" joins the cluster of this node); start one here with `ray start "
                "--head`, or give the head node's HOST:PORT")
    first = first.split(". ")[0].rstrip(".:")
    return (f"could not connect to the Ray cluster at {address}: {first}; "
            f"{_address_hint(address.startswith('ray://'))}")


def _start_ray(ray: Any, workers: int | None, address: str | None) -> bool:
    """Connect to ``address`` or start a local Ray with ``workers`` CPUs; True if this call
    started (and so must shut down) it. An already connected Ray is used as it is."""
    if ray.is_initialized():
        return False
    if address is not None:
        check_ray_address(address)  # before ray.init, which retries an unreachable one forever
    kwargs: dict[str, Any] = {"include_dashboard": False, "logging_level": logging.ERROR,
                              "log_to_driver": False}
    # ray.init installs its own SIGTERM handler; ours (tfalda_sim.interrupts) must stay, so
    # that SIGTERM keeps the finished results as Ctrl-C does.
    main = threading.current_thread() is threading.main_thread()
    saved = {sig: signal.getsignal(sig) for sig in (signal.SIGTERM, signal.SIGHUP)} if main else {}
    try:
        if address is None:
            # "local": a new Ray even if RAY_ADDRESS or `ray start` names a cluster (that is
            # --ray-address); connecting to one with num_cpus is an error in ray.init.
            ray.init(address="local", num_cpus=workers, **kwargs)
        else:
            ray.init(address=address, **kwargs)
    except (ConnectionError, RuntimeError, ValueError, TimeoutError) as exc:
        with contextlib.suppress(Exception):
            ray.shutdown()  # a half-made connection
        raise RayUnavailable(ray_init_failure(address, exc)) from None
    finally:
        for sig, handler in saved.items():
            if handler is not None:
                signal.signal(sig, handler)
    return True


def ray_stream(fn: Callable[[J], R], jobs: Iterable[J], *, workers: int | None = None,
               address: str | None = None) -> Iterator[R]:
    """``stream`` on Ray: ``fn(job)`` as Ray tasks (``fn`` must pickle: a top-level
    function or a ``functools.partial`` of one), results in job order, at most ``workers ×
    IN_FLIGHT_PER_WORKER`` tasks in flight (``workers`` None: the cluster's CPUs). Starts a
    local Ray with ``workers`` CPUs unless Ray is connected or ``address`` names a
    cluster, and shuts down a Ray it started. Closing the generator early ends the tasks
    in flight with a Ray it started, and lets them finish (results dropped) on a shared
    one. A task whose worker died raises ``WorkerDied``."""
    if workers is not None and workers < 1:
        raise ValueError(f"workers must be ≥ 1, got {workers}")
    ray = import_ray()
    from ray import exceptions as rex

    def collect(ref: Any) -> Any:
        # The oldest task only (results in job order), waited for in short steps so a
        # Ctrl-C is not stuck inside Ray.
        while not ray.wait([ref], timeout=RAY_POLL_S)[0]:
            pass
        try:
            return ray.get(ref)
        except (rex.WorkerCrashedError, rex.NodeDiedError, rex.OutOfMemoryError,
                rex.RaySystemError) as exc:
            raise WorkerDied(f"a Ray worker died ({type(exc).__name__}; killed, perhaps "
                             "for lack of memory: try fewer --workers)") from None
        except rex.RayTaskError as exc:  # the job's own error, as the local pool gives
            cause = exc.cause if isinstance(exc.cause, BaseException) else exc
            raise cause from None

    started = _start_ray(ray, workers, address)
    pending: deque[Any] = deque()
    try:
        if workers is None:
            workers = max(1, int(ray.cluster_resources().get("CPU", 1)))
        task = ray.remote(num_cpus=1, max_retries=0)(_call)
        fn_ref = ray.put(fn)  # shipped once, not with every task
        yield from _in_job_order(lambda job: task.remote(fn_ref, job), collect, jobs,
                                 workers * IN_FLIGHT_PER_WORKER, pending)
    finally:
        if started:
            # Shutting down the Ray we started ends its tasks with it. (Force-cancelling
            # them first raced the shutdown: Ray's core worker sometimes crashed, exit 1.)
            ray.shutdown()
        else:
            # An early close on a shared Ray: the few tasks in flight (the window) finish
            # and their results are dropped. Cancelling them raced their completion: Ray's
            # driver, this process, aborted ("Tried to complete task that was not pending",
            # task_manager.cc), once in a CI run of the test suite.
            pending.clear()


@dataclass(frozen=True)
class Backend(Generic[J, R]):
    """Where a sweep runs: ``local`` (``stream``, ``workers`` processes) or ``ray``
    (``ray_stream``; ``address`` a cluster, None a local Ray with ``workers`` CPUs;
    ``workers`` None on a cluster: its CPUs). The same job function either way, results
    in job order: a sweep's results do not depend on the backend."""

    kind: Literal["local", "ray"] = "local"
    workers: int | None = 1
    address: str | None = None

    def __post_init__(self) -> None:
        if self.kind not in BACKENDS:
            raise ValueError(f"backend must be one of {', '.join(BACKENDS)}, got {self.kind!r}")
        if self.address is not None and self.kind != "ray":
            raise ValueError("a Ray address needs the ray backend")
        if self.kind == "local" and self.workers is None:
            raise ValueError("the local backend needs a worker count")

    def stream(self, fn: Callable[[J], R], jobs: Iterable[J]) -> Iterator[R]:
        """``fn(job)`` for every job, results in job order, bounded jobs in flight."""
        if self.kind == "ray":
            return ray_stream(fn, jobs, workers=self.workers, address=self.address)
        return stream(fn, jobs, workers=self.workers or 1)
