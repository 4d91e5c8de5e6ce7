"""Pieces every ``tfalda-sim`` subcommand shares: exit codes, the bad-input error,
argument types, the output check and the Ctrl-C message.

Exit codes: 0 success; 1 the command ran and the result is negative (an invalid track,
laps not completed); 2 bad input (unreadable file, bad option, refused overwrite);
130 stopped by Ctrl-C (143 SIGTERM, 129 SIGHUP; what was finished is kept and named).
An unexpected error (a bug) also exits 1, with one line naming it.
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

from .interrupts import INTERRUPTS, ignoring_stops, is_interrupt, last_stop_signal
from .outputs import DIRECTORY, Output, OutputError
from .outputs import check_outputs as _check_outputs
from .parallel import WorkerDied, resolve_workers

R = TypeVar("R")

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
    "add_workers_option",
    "bounded_float_arg",
    "bounded_int_arg",
    "check_outputs",
    "finite_float_arg",
    "interrupted",
    "positive_float_arg",
    "positive_int_arg",
    "seed_arg",
    "seed_range_arg",
    "speed_arg_for",
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
        with ignoring_stops():
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
