"""Pieces every ``tfalda-sim`` subcommand shares: exit codes, the bad-input error,
argument types, the output check and the Ctrl-C message.

Exit codes: 0 success; 1 the command ran and the result is negative (an invalid track,
laps not completed); 2 bad input (unreadable file, bad option, refused overwrite);
130 stopped by Ctrl-C (143 SIGTERM, 129 SIGHUP; what was finished is kept and named).
An unexpected error (a bug) also exits 1, with one line naming it.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import shutil
import signal
import sys
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Generic, TypeVar

from .interrupts import INTERRUPTS, deferring_stops, holding_stops, is_interrupt, last_stop_signal
from .outputs import DIRECTORY, Output, OutputError, journal_of
from .outputs import check_outputs as _check_outputs
from .parallel import BACKENDS, Backend, RayUnavailable, WorkerDied, import_ray, resolve_workers

R = TypeVar("R")
J = TypeVar("J")

EXIT_OK: int = 0
EXIT_NEGATIVE: int = 1
EXIT_BAD_INPUT: int = 2
EXIT_INTERRUPTED: int = 130
"""128 + SIGINT, the shell's code for a Ctrl-C (SIGTERM: 143, SIGHUP: 129)."""

__all__ = [
    "DIRECTORY",
    "EXIT_BAD_INPUT",
    "EXIT_INTERRUPTED",
    "EXIT_NEGATIVE",
    "EXIT_OK",
    "MAX_SEED",
    "CliError",
    "add_force_option",
    "add_json_option",
    "add_sweep_options",
    "add_workers_option",
    "bounded_float_arg",
    "bounded_int_arg",
    "check_outputs",
    "finite_float_arg",
    "interrupted",
    "positive_float_arg",
    "positive_int_arg",
    "run_sweep",
    "seed_arg",
    "seed_range_arg",
    "speed_arg_for",
    "sweep_backend",
    "workers_arg_value",
]


class CliError(Exception):
    """Bad input: printed as ``error: …`` with exit code 2."""


MAX_SEED: int = 2**63 - 1
"""Largest seed: seeds reach numpy generators and numba kernels as int64."""


def _short(text: str) -> str:
    return repr(text if len(text) <= 40 else text[:37] + "...")


def seed_arg(text: str) -> int:
    """argparse type: a seed, an integer in [0, 2⁶³ − 1]."""
    try:
        value = int(text) if len(text) <= 30 else -1
    except ValueError:
        value = -1
    if not 0 <= value <= MAX_SEED:
        raise argparse.ArgumentTypeError(
            f"seed must be an integer from 0 to {MAX_SEED}, got {_short(text)}")
    return value


def seed_range_arg(text: str) -> range:
    """argparse type: ``A:B``, the seeds A, A+1, …, B−1 (Python's slice convention)."""
    parts = text.split(":")
    if len(parts) != 2:
        raise argparse.ArgumentTypeError(f"seeds must read A:B (e.g. 0:50), got {_short(text)}")
    a, b = (seed_arg(p) for p in parts)
    if b <= a:
        raise argparse.ArgumentTypeError(f"seeds A:B needs B > A, got {_short(text)}")
    return range(a, b)


def finite_float_arg(text: str) -> float:
    """argparse type: a finite number (NaN and infinities are refused)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {_short(text)}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {_short(text)}")
    return value


def bounded_float_arg(low: float, high: float, unit: str = "", *, low_open: bool = False,
                      why: str = "") -> Callable[[str], float]:
    """argparse type: a finite number in [low, high] (``low_open``: (low, high]); ``why``
    says where the bounds come from."""
    def parse(text: str) -> float:
        value = finite_float_arg(text)
        if value > high or value < low or (low_open and value == low):
            lo = "(" if low_open else "["
            raise argparse.ArgumentTypeError(
                f"expected a number in {lo}{low:g}, {high:g}]{' ' + unit if unit else ''}"
                f"{f' ({why})' if why else ''}, got {_short(text)}")
        return value
    parse.__name__ = "number"
    return parse


def bounded_int_arg(low: int, high: int) -> Callable[[str], int]:
    """argparse type: an integer in [low, high]."""
    def parse(text: str) -> int:
        try:
            value = int(text) if len(text) <= 30 else None
        except ValueError:
            value = None
        if value is None or not low <= value <= high:
            raise argparse.ArgumentTypeError(
                f"expected an integer from {low} to {high}, got {_short(text)}")
        return value
    parse.__name__ = "integer"
    return parse


def positive_float_arg(text: str) -> float:
    """argparse type: a finite number > 0."""
    value = finite_float_arg(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text!r}")
    return value


def positive_int_arg(text: str) -> int:
    """argparse type: an integer ≥ 1."""
    try:
        value = int(text) if len(text) <= 30 else None
    except ValueError:
        value = None
    if value is None:
        raise argparse.ArgumentTypeError(f"expected an integer, got {_short(text)}")
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected an integer ≥ 1, got {_short(text)}")
    return value


def speed_arg_for(min_speed_m_s: float,
                  top_speed_m_s: float) -> Callable[[str], float]:
    """argparse type of every ``--speed``: a cruise speed in [``min_speed_m_s``,
    ``top_speed_m_s``] [m/s] (``tfalda_sim.vehicle.MIN_CRUISE_SPEED_M_S`` and the car's
    top speed)."""
    return bounded_float_arg(min_speed_m_s, top_speed_m_s, "m/s",
                             why="from a crawl to the car's top speed")


def check_outputs(paths: Mapping[str, Path | None], suffixes: Mapping[str, str], force: bool,
                  *, inputs: Mapping[str, Path | None] | None = None,
                  files_in: Mapping[str, Iterable[str]] | None = None) -> None:
    """Check a command's outputs before any work (``tfalda_sim.outputs.check_outputs``):
    ``paths`` by option name (without ``--``), their ``suffixes`` (``DIRECTORY`` for a
    folder), ``inputs`` the command reads (never overwritten), ``files_in`` the file names
    a folder output gets. Raises ``CliError``."""
    outs = [Output(f"--{k}", p, suffixes[k]) for k, p in paths.items() if p is not None]
    ins = {f"--{k}" if not k.startswith("-") else k: p for k, p in (inputs or {}).items()
           if p is not None}
    try:
        _check_outputs(outs, force=force, inputs=ins,
                       files_in={f"--{k}": v for k, v in (files_in or {}).items()})
    except OutputError as exc:
        raise CliError(str(exc)) from None


def workers_arg_value(requested: int | None, jobs: int | None) -> int:
    """The workers to start for ``jobs`` jobs (``tfalda_sim.parallel.resolve_workers``);
    says on stderr when ``--workers`` was capped."""
    n, why = resolve_workers(requested, jobs)
    if why:
        print(f"note: {why}", file=sys.stderr)
    return n


def interrupted(kept: str) -> int:
    """After a Ctrl-C (or SIGTERM, SIGHUP): one line on stderr saying what was kept; the
    exit code 128 + the signal (130 for Ctrl-C)."""
    sig = last_stop_signal()
    name = "Ctrl-C" if sig == signal.SIGINT else signal.Signals(sig).name
    print(f"interrupted ({name}): {kept}", file=sys.stderr)
    return 128 + int(sig)


# Options every command spells the same way.
def add_json_option(parser: argparse.ArgumentParser) -> None:
    """``--json``: print one JSON object on stdout instead of the table."""
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def add_force_option(parser: argparse.ArgumentParser,
                     what: str = "existing output files") -> None:
    """``--force``: outputs that exist are replaced (refused without it)."""
    parser.add_argument("--force", action="store_true", help=f"overwrite {what}")


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


# Sweeps: one set of options and one driver for every command that runs jobs over a seed
# range (stress, evaluate --scenario random, compare, evaluate-agent, and any later one).

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
                        help="with --backend ray: a running Ray cluster (default: start a "
                             "local Ray with --workers CPUs for this sweep)")
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
