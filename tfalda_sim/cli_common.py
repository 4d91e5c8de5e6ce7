"""Pieces every ``tfalda-sim`` subcommand shares: exit codes, the bad-input error,
argument types, the output check, the shared options and the Ctrl-C message (the options
and driver of the commands that sweep a seed range: ``tfalda_sim.sweep_runner``).

Exit codes: 0 success; 1 the command ran and the result is negative (an invalid track,
laps not completed); 2 bad input (unreadable file, bad option, refused overwrite);
130 stopped by Ctrl-C (143 SIGTERM, 129 SIGHUP; what was finished is kept and named).
An unexpected error (a bug) also exits 1, with one line naming it.
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import sys
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path

from .interrupts import last_stop_signal
from .outputs import DIRECTORY, Output, OutputError
from .outputs import check_outputs as _check_outputs

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


def add_recording_options(parser: argparse.ArgumentParser, what: str = "the run") -> None:
    """``--mcap FILE`` / ``--rosbag DIR``: ``what`` as a recording Foxglove shows and
    ``tfalda-sim replay`` reads (docs/recordings.md)."""
    rec = parser.add_mutually_exclusive_group()
    rec.add_argument("--mcap", type=Path, metavar="FILE.mcap",
                     help=f"record {what} as an MCAP file: camera frames, lanes, ROIs, LIS "
                          "state and more, each on its own channel (Foxglove shows them)")
    rec.add_argument("--rosbag", type=Path, metavar="DIR",
                     help=f"record {what} as a ROS 2 bag folder (MCAP storage), the same "
                          "channels as --mcap")


RECORDING_SUFFIXES: dict[str, str] = {"mcap": ".mcap", "rosbag": DIRECTORY}
"""``check_outputs``' suffixes of the recording options."""


def recording_outputs(args: argparse.Namespace) -> dict[str, Path | None]:
    """``check_outputs``' paths of the recording options."""
    return {"mcap": args.mcap, "rosbag": args.rosbag}


def add_force_option(parser: argparse.ArgumentParser,
                     what: str = "existing output files") -> None:
    """``--force``: outputs that exist are replaced (refused without it)."""
    parser.add_argument("--force", action="store_true", help=f"overwrite {what}")


def strict_json(value: object) -> object:
    """``value`` with every non-finite float (NaN, ±inf; numpy's too) as None: JSON has no
    NaN or Infinity (RFC 8259), and a strict parser refuses Python's ``NaN``. numpy scalars
    and arrays become plain numbers and lists."""
    if isinstance(value, Mapping):
        return {key: strict_json(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [strict_json(item) for item in value]
    if hasattr(value, "tolist") and not isinstance(value, str | bytes):  # numpy
        return strict_json(value.tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def json_text(value: object, **dumps_kwargs: object) -> str:
    """A command's ``--json`` output: strict JSON (``strict_json``; ``json.dumps`` refuses
    anything else rather than print it)."""
    return json.dumps(strict_json(value), allow_nan=False, **dumps_kwargs)  # type: ignore[arg-type]
