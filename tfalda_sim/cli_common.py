"""Pieces every ``tfalda-sim`` subcommand shares: the bad-input error and argument types."""

from __future__ import annotations

import argparse
import math
from pathlib import Path


class CliError(Exception):
    """Bad input: printed as ``error: …`` with exit code 2."""


def seed_arg(text: str) -> int:
    """argparse type: a non-negative integer seed."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"seed must be a non-negative integer, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"seed must be a non-negative integer, got {text!r}")
    return value


def seed_range_arg(text: str) -> range:
    """argparse type: ``A:B``, the seeds A, A+1, …, B−1 (Python's slice convention)."""
    parts = text.split(":")
    if len(parts) != 2:
        raise argparse.ArgumentTypeError(f"seeds must read A:B (e.g. 0:50), got {text!r}")
    a, b = (seed_arg(p) for p in parts)
    if b <= a:
        raise argparse.ArgumentTypeError(f"seeds A:B needs B > A, got {text!r}")
    return range(a, b)


def finite_float_arg(text: str) -> float:
    """argparse type: a finite number (NaN and infinities are refused)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def positive_float_arg(text: str) -> float:
    """argparse type: a finite number > 0."""
    value = finite_float_arg(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text!r}")
    return value


def positive_int_arg(text: str) -> int:
    """argparse type: an integer ≥ 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected an integer ≥ 1, got {text!r}")
    return value


def check_outputs(paths: dict[str, Path | None], suffixes: dict[str, str], force: bool) -> None:
    """Refuse wrong suffixes, two outputs on one path, and existing files without --force."""
    given = {k: p for k, p in paths.items() if p is not None}
    for key, p in given.items():
        if p.suffix.lower() != suffixes[key]:
            raise CliError(f"--{key} {p} must end in {suffixes[key]}")
    resolved = [p.resolve() for p in given.values()]
    if len(set(resolved)) != len(resolved):
        raise CliError("two outputs name the same file; give each its own path")
    existing = [str(p) for p in given.values() if p.exists()]
    if existing and not force:
        raise CliError(f"{', '.join(existing)} exists; add --force to overwrite")
