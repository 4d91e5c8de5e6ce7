"""Sweeps: one set of options and one driver for every command that runs jobs over a seed
range (stress, evaluate --scenario random, compare, evaluate-agent, and any later one).

The options (``add_sweep_options``: ``--workers``, ``--backend``, ``--ray-address``,
``--results``, ``--resume``; ``check_sweep_options``, ``sweep_backend``), the driver
(``SweepSpec`` run by ``run_sweep`` on a ``tfalda_sim.parallel`` backend), the results
journal a stopped sweep is continued from (``read_results``), and how a sweep ended
(``consume``, ``SweepEnd``, ``sweep_exit``).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import shutil
import sys
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Generic, TypeVar

from .cli_common import EXIT_NEGATIVE, EXIT_OK, CliError, interrupted, positive_int_arg
from .interrupts import INTERRUPTS, deferring_stops, holding_stops, is_interrupt
from .outputs import journal_of
from .parallel import BACKENDS, Backend, RayUnavailable, WorkerDied, import_ray, resolve_workers

R = TypeVar("R")
J = TypeVar("J")

__all__ = [
    "SWEEP_FORMAT",
    "SWEEP_HEADER_KEY",
    "ResumedResults",
    "SweepEnd",
    "SweepSpec",
    "add_sweep_options",
    "add_workers_option",
    "check_sweep_options",
    "consume",
    "read_results",
    "resume_hint",
    "run_sweep",
    "sweep_backend",
    "sweep_exit",
    "workers_arg_value",
]


def workers_arg_value(requested: int | None, jobs: int | None) -> int:
    """The workers to start for ``jobs`` jobs (``tfalda_sim.parallel.resolve_workers``);
    says on stderr when ``--workers`` was capped."""
    n, why = resolve_workers(requested, jobs)
    if why:
        print(f"note: {why}", file=sys.stderr)
    return n


def add_workers_option(parser: argparse.ArgumentParser, what: str = "jobs") -> None:
    """``--workers N``: processes of a sweep, capped by ``workers_arg_value``."""
    parser.add_argument("--workers", type=positive_int_arg,
                        help=f"processes (default: the CPUs available; capped at the {what}, "
                             "the CPUs and the memory)")


@dataclass
class SweepEnd:
    """How a sweep's stream of results ended: completely, by Ctrl-C (or SIGTERM, SIGHUP),
    or because a worker process died (``worker_died``: the message)."""

    interrupted: bool = False
    worker_died: str | None = None

    @property
    def early(self) -> bool:
        return self.interrupted or self.worker_died is not None


def consume(results: Iterator[R], handle: Callable[[R], None]) -> SweepEnd:
    """Pass every result of a sweep to ``handle`` until the stream ends, is interrupted or
    loses a worker; the pool is shut down either way (shielded from a second Ctrl-C)."""
    end = SweepEnd()
    try:
        for result in results:
            handle(result)
    except INTERRUPTS as exc:
        if not is_interrupt(exc):
            raise
        end.interrupted = True
    except WorkerDied as exc:
        end.worker_died = str(exc)
    finally:
        with holding_stops():
            close = getattr(results, "close", None)
            if close is not None:
                close()
    return end


def sweep_exit(end: SweepEnd, kept: str) -> int:
    """The exit code of a sweep that ended as ``end``, saying what was ``kept`` if it
    ended early (a dead worker: an error, exit 1; an interrupt: ``interrupted``)."""
    if end.worker_died is not None:
        print(f"error: {end.worker_died}; {kept}", file=sys.stderr)
        return EXIT_NEGATIVE
    if end.interrupted:
        return interrupted(kept)
    return EXIT_OK


SWEEP_HEADER_KEY = "tfalda_sim_sweep"
"""The key of a results file's first line: the command that wrote it."""

SWEEP_FORMAT = 1
"""The results file's format version (a different one is refused by --resume)."""


def add_sweep_options(parser: argparse.ArgumentParser, what: str = "jobs") -> None:
    """``--workers``, ``--backend local|ray``, ``--ray-address``, ``--results F.jsonl`` and
    ``--resume``: the options of every sweep (checked by ``check_sweep_options``)."""
    add_workers_option(parser, what)
    parser.add_argument("--backend", choices=BACKENDS, default="local",
                        help="where the jobs run: local processes (default) or Ray (the "
                             "optional extra: pip install 'tfalda-sim[ray]')")
    parser.add_argument("--ray-address", metavar="ADDR",
                        help="with --backend ray: a running Ray cluster, HOST:PORT of its head "
                             "node, ray://HOST:PORT or auto (default: start a local Ray with "
                             "--workers CPUs for this sweep)")
    parser.add_argument("--results", type=Path, metavar="F.jsonl",
                        help="stream each finished job's result to this JSON Lines file (first "
                             "line: the sweep's configuration), so --resume can continue it; "
                             "it grows as F.jsonl.partial until the sweep ends")
    parser.add_argument("--resume", action="store_true",
                        help="continue the interrupted sweep in --results: its finished jobs "
                             "are kept, not redone (same options needed; the report files "
                             "are replaced)")
    parser.set_defaults(sweep_parser=parser)


def check_sweep_options(args: argparse.Namespace) -> None:
    """Contradictory sweep options refused at the parser (usage and exit 2); a missing
    ``--results`` file of a ``--resume`` is ``read_results``' to refuse."""
    error = args.sweep_parser.error
    if args.ray_address is not None and args.backend != "ray":
        error("--ray-address names a Ray cluster: it needs --backend ray")
    if args.resume and args.results is None:
        error("--resume continues the sweep saved in --results F.jsonl: give that file")
    if args.resume and getattr(args, "force", False):
        error("--resume continues --results and replaces the report it had; --force starts "
              "afresh over it: give one of them")
    journal = None if args.results is None else journal_of(args.results)
    if (journal is not None and not args.resume and not getattr(args, "force", False)
            and (journal.exists() or journal.is_symlink())):
        error(f"{journal} holds the finished jobs of a sweep that was stopped before it "
              "ended (killed?): --resume continues it, --force starts afresh over it")


def sweep_backend(args: argparse.Namespace, jobs: int) -> Backend[Any, Any]:
    """The backend of ``--backend``/``--ray-address``/``--workers`` for ``jobs`` jobs.
    Local and a local Ray: ``--workers`` capped (``workers_arg_value``); a Ray cluster:
    ``--workers`` as given (default its CPUs). Raises ``CliError`` without Ray."""
    if args.backend == "ray":
        try:
            import_ray()
        except RayUnavailable as exc:
            raise CliError(str(exc)) from None
        if args.ray_address is not None:
            return Backend("ray", args.workers, args.ray_address)
        return Backend("ray", workers_arg_value(args.workers, max(jobs, 1)))
    return Backend("local", workers_arg_value(args.workers, max(jobs, 1)))


def resume_hint(args: argparse.Namespace) -> str:
    """What to tell an interrupted sweep's user about continuing it."""
    if args.results is None:
        return ""
    return f"; --resume with the same options continues it from {args.results}"


@dataclass(frozen=True)
class SweepSpec(Generic[J]):
    """A sweep as ``run_sweep`` runs it: ``fn`` (a picklable top-level function, the same
    for every backend) over ``jobs`` (pulled lazily, ``total`` of them); ``record`` turns a
    job's result into its JSON record (a line of ``--results``), ``check`` raises
    ValueError when a stored record is not that job's. ``command`` and ``config`` (JSON
    values by option name) make the results file's header: ``--resume`` refuses a file
    of another command or configuration."""

    command: str
    config: Mapping[str, Any]
    jobs: Iterable[J]
    total: int
    fn: Callable[[J], Any]
    record: Callable[[J, Any], dict[str, Any]]
    check: Callable[[J, dict[str, Any]], None]

    def header(self) -> dict[str, Any]:
        return {SWEEP_HEADER_KEY: self.command, "format": SWEEP_FORMAT,
                "config": dict(self.config), "jobs": self.total}


def _show(value: Any) -> str:
    return "(not given)" if value is None else json.dumps(value)


class ResumedResults:
    """The records of a results journal as ``(line number, record)`` (``read_results``);
    ``valid_end`` is the byte length of the header and the records read so far, where
    ``run_sweep`` appends the next one (cutting off an incomplete last line)."""

    def __init__(self, path: Path, fh: Any, spec_path: Path, header_bytes: int) -> None:
        self.path = path
        self._fh = fh
        self._shown = spec_path
        self.valid_end = header_bytes
        self.header_newline = True  # False: the header line lost its newline (cut off)

    def __iter__(self) -> Iterator[tuple[int, dict[str, Any]]]:
        with self._fh as fh:
            for n, raw in enumerate(fh, start=2):
                if not raw.endswith(b"\n"):  # the last line, cut off mid-write
                    print(f"note: --resume: dropped the incomplete last line {n} of "
                          f"{self._shown}; its job runs again", file=sys.stderr)
                    return
                try:
                    rec = json.loads(raw.decode("utf-8"))
                except (ValueError, UnicodeDecodeError):
                    raise CliError(f"--resume: {self._shown} line {n} is not JSON: the file "
                                   "is damaged; start afresh without --resume") from None
                if not isinstance(rec, dict):
                    raise CliError(f"--resume: {self._shown} line {n} is not a result "
                                   "record; start afresh without --resume")
                self.valid_end += len(raw)
                yield n, rec


def read_results(path: Path, spec: SweepSpec[Any]) -> ResumedResults:
    """The records of the results of an interrupted sweep, after checking its header
    against ``spec`` now (``CliError`` naming the mismatch). They are read from the
    journal ``journal_of(path)`` if a killed sweep left one (it holds every finished
    job), else from ``path``, copied to the journal first: the resumed sweep appends its
    jobs to the journal, so a kill never loses what was there. An incomplete last line (a
    write cut off) is dropped with a note: its job runs again; any other bad line is an
    error naming it."""
    journal = journal_of(path)
    source = journal if journal.is_file() else path
    if not source.is_file():
        raise CliError(f"--resume: {path} is not a file (nothing to resume); run without "
                       "--resume to start the sweep")
    try:
        fh = open(source, "rb")  # closed by ResumedResults (or on an error here)
    except OSError as exc:
        raise CliError(f"--resume: cannot read {source}: {exc.strerror or exc}") from None
    first = fh.readline()
    try:
        head = json.loads(first.decode("utf-8"))
    except (ValueError, UnicodeDecodeError):
        head = None
    if not isinstance(head, dict) or not isinstance(head.get(SWEEP_HEADER_KEY), str):
        fh.close()
        raise CliError(f"--resume: {source} does not start with a sweep header: it is not a "
                       "--results file of tfalda-sim; start afresh without --resume")
    problems = []
    if head[SWEEP_HEADER_KEY] != spec.command:
        problems.append(f"it holds `tfalda-sim {head[SWEEP_HEADER_KEY]}` results, this is "
                        f"`tfalda-sim {spec.command}`")
    elif head.get("format") != SWEEP_FORMAT:
        problems.append(f"its format is {_show(head.get('format'))}, this version reads "
                        f"{SWEEP_FORMAT}")
    else:
        theirs = head.get("config") if isinstance(head.get("config"), dict) else {}
        ours = json.loads(json.dumps(dict(spec.config)))
        for key in sorted(set(theirs) | set(ours)):
            if theirs.get(key) != ours.get(key):
                problems.append(f"--{key.replace('_', '-')} was {_show(theirs.get(key))}, "
                                f"now {_show(ours.get(key))}")
    if problems:
        fh.close()
        raise CliError(f"--resume: {source} is from another sweep: {'; '.join(problems)}. "
                       "Give the options it was started with, or start afresh without "
                       "--resume")
    if source == journal:
        print(f"note: --resume: continuing from {journal}, which a sweep stopped before "
              "its end left", file=sys.stderr)
    else:
        fh.close()
        # Copied under a temporary name and renamed: a copy cut short (Ctrl-C, a kill)
        # never stands as the journal, and a link at the journal's name is replaced, not
        # written through.
        tmp = journal.with_name(f".{journal.name}.{os.getpid()}.tmp")
        try:
            shutil.copyfile(path, tmp)
            os.replace(tmp, journal)
            fh = open(journal, "rb")
            fh.readline()
        except OSError as exc:
            raise CliError(f"--resume: cannot copy {path} to {journal}: "
                           f"{exc.strerror or exc}") from None
        finally:
            Path(tmp).unlink(missing_ok=True)
    resumed = ResumedResults(journal, fh, source, len(first))
    resumed.header_newline = first.endswith(b"\n")
    return resumed


_END = object()


def run_sweep(spec: SweepSpec[J], backend: Backend[Any, Any],
              handle: Callable[[dict[str, Any]], None], *, results: Path | None = None,
              resume: ResumedResults | None = None,
              progress: bool = True, desc: str = "jobs", unit: str = "job",
              on_result: Callable[[J, Any], None] | None = None) -> SweepEnd:
    """Run a sweep: the records of ``resume`` (``read_results``) first, in place of the
    jobs they finished, then the remaining jobs on ``backend``. Every record (JSON
    round-tripped, so a resumed sweep sees exactly what an uninterrupted one does) goes
    to ``handle``; ``results`` (the journal, ``Outputs.journal``) gets the header and
    every fresh record, flushed at once — with ``resume`` it is ``resume.path`` and the
    fresh records go after the resumed ones. A fresh result also goes to ``on_result``
    (side outputs that need more than the record). A tqdm bar counts finished jobs.
    Returns how the sweep ended (``consume``)."""
    if resume is not None and results is not None and resume.path != results:
        raise ValueError(f"a resumed sweep appends to its journal {resume.path}, not to "
                         f"{results}")
    jobs = iter(spec.jobs)
    in_flight: deque[J] = deque()  # the jobs handed to the backend, oldest first

    def items() -> Iterator[tuple[J, str, dict[str, Any], Any, int]]:
        for n, rec in resume or ():
            job = next(jobs, _END)
            if job is _END:
                raise CliError(f"--resume: line {n} is past the sweep's {spec.total} jobs: "
                               "the file is not this sweep's results")
            try:
                spec.check(job, rec)  # type: ignore[arg-type]
            except (ValueError, TypeError, KeyError) as exc:
                raise CliError(f"--resume: line {n}: {exc}; the file is not this sweep's "
                               "results") from None
            yield job, json.dumps(rec), rec, None, n  # type: ignore[misc]
        first = next(jobs, _END)
        if first is _END:  # all done: no backend to start
            return
        jobs_left = _prepend(first, jobs)
        for result in backend.stream(spec.fn, _pulled_from(jobs_left, in_flight)):
            job = in_flight.popleft()
            line = json.dumps(spec.record(job, result))
            yield job, line, json.loads(line), result, 0

    with contextlib.ExitStack() as stack:
        fh = None

        def journal() -> Any:
            """The results journal, opened where the next record goes."""
            nonlocal fh
            if fh is None and results is not None:
                if resume is None:
                    # A new file: a link left at the journal's name is not written through.
                    results.unlink(missing_ok=True)
                    fh = stack.enter_context(open(results, "xb"))
                    fh.write((json.dumps(spec.header()) + "\n").encode("utf-8"))
                    fh.flush()
                else:  # after the resumed records (an incomplete last line cut off)
                    fh = stack.enter_context(open(results, "r+b"))
                    fh.seek(resume.valid_end)
                    fh.truncate()
                    if not resume.header_newline:  # the file ended in the header line
                        fh.write(b"\n")
            return fh

        if resume is None:
            journal()
        bar = stack.enter_context(_tqdm(total=spec.total, desc=desc, unit=unit,
                                        disable=not progress))

        def keep(item: tuple[J, str, dict[str, Any], Any, int]) -> None:
            with deferring_stops():  # a Ctrl-C keeps this result whole in every output
                _keep(item)

        def _keep(item: tuple[J, str, dict[str, Any], Any, int]) -> None:
            job, line, rec, result, n = item
            try:
                handle(rec)
            except (ValueError, TypeError, KeyError) as exc:
                if n == 0:
                    raise
                raise CliError(f"--resume: line {n} is not a valid result ({exc}); the file "
                               "is not this sweep's results") from None
            if n == 0 and journal() is not None:  # a fresh result (resumed: there already)
                fh.write((line + "\n").encode("utf-8"))
                fh.flush()  # a finished job is on disk at once
            if result is not None and on_result is not None:
                on_result(job, result)
            bar.update()

        try:
            end = consume(items(), keep)
            if not end.early:
                journal()  # all resumed: still cut off an incomplete last line
            return end
        except RayUnavailable as exc:  # Ray starts with the first job: bad input, not a bug
            raise CliError(str(exc)) from None


def _prepend(first: J, rest: Iterator[J]) -> Iterator[J]:
    yield first
    yield from rest


def _pulled_from(jobs: Iterator[J], in_flight: deque[J]) -> Iterator[J]:
    for job in jobs:
        in_flight.append(job)
        yield job


def _tqdm(**kwargs: Any) -> Any:
    from tqdm import tqdm

    return tqdm(**kwargs)
