"""Argument checks of the envs: the right type or a ``TypeError``, an impossible value a
``ValueError``; each message names the argument, shows what was given and what is accepted.

Conventions: a boolean is a ``bool`` or ``numpy.bool_`` (not ``0``/``1``, not ``"yes"``); a
number is an ``int``, ``float`` or numpy integer/floating scalar, never a boolean.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import fields
from typing import Any, TypeVar

import numpy as np

from tfalda_sim.faults import FAULT_TYPES, Fault, check_schedule

T = TypeVar("T")

_REPR_LIMIT = 80


def show(value: object) -> str:
    """``repr(value)`` on one line, shortened: a huge list or string must not flood the
    message."""
    try:
        text = repr(value)
    except Exception:  # e.g. an int beyond sys.get_int_max_str_digits(): the message must go on
        text = f"<{type(value).__name__} without a printable repr>"
    text = re.sub(r"\s*\n\s*", " ", text)  # numpy prints arrays on many lines
    return text if len(text) <= _REPR_LIMIT else text[:_REPR_LIMIT - 3] + "..."


def is_bool(value: object) -> bool:
    return isinstance(value, bool | np.bool_)


def is_int(value: object) -> bool:
    return isinstance(value, int | np.integer) and not isinstance(value, bool)


def is_real(value: object) -> bool:
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)


def check_bool(name: str, value: object) -> bool:
    if not is_bool(value):
        raise TypeError(f"{name} must be a bool (True or False), got {show(value)}")
    return bool(value)


def check_real(name: str, value: object, low: float = -math.inf, high: float = math.inf, *,
               low_open: bool = False, unit: str = "") -> float:
    """``value`` as a finite float in ``[low, high]`` (``(low, high]`` if ``low_open``)."""
    if not is_real(value):
        raise TypeError(f"{name} must be a real number (int or float), got {show(value)}")
    try:
        x = float(value)  # type: ignore[arg-type]
    except OverflowError:  # an int beyond the float range
        x = math.inf if value > 0 else -math.inf  # type: ignore[operator]
    inside = (low < x if low_open else low <= x) and x <= high
    if not (math.isfinite(x) and inside):
        bracket = "(" if low_open else "["
        raise ValueError(f"{name} must be finite and in {bracket}{low:g}, {high:g}]{unit}, got "
                         f"{show(value)}")
    return x


def check_int(name: str, value: object, low: int = 0) -> int:
    """``value`` as an int ≥ ``low``; floats are refused, even integral ones (no silent
    truncation of 1.5, no NaN)."""
    if not is_int(value):
        raise TypeError(f"{name} must be an int ≥ {low}, got {show(value)}")
    n = int(value)  # type: ignore[call-overload]
    if n < low:
        raise ValueError(f"{name} must be an int ≥ {low}, got {show(value)}")
    return n


def check_optional(name: str, value: T | None, kind: type[T], accepted: str) -> T | None:
    """``value`` if it is a ``kind`` or None."""
    if value is not None and not isinstance(value, kind):
        raise TypeError(f"{name} must be {accepted} or None, got {show(value)}")
    return value


def check_choice(name: str, value: object, choices: Sequence[str], *,
                 optional: bool = False) -> str:
    """``value``, one of the strings ``choices`` (the caller lets None through if
    ``optional``; the message then lists it)."""
    accepted = ("None or " if optional else "") + "one of " + ", ".join(map(repr, choices))
    if not isinstance(value, str):
        raise TypeError(f"{name} must be {accepted}; got {show(value)}")
    if value not in choices:
        raise ValueError(f"unknown {name} {show(value)}; use {accepted}")
    return value


def check_options(value: object) -> Mapping[Any, Any]:
    """``reset``'s ``options``: None or a mapping."""
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise TypeError(f"options must be None or a mapping (dict) of reset options, got "
                        f"{show(value)}")
    return value


def check_seed_range(name: str, value: object, high_limit: int) -> tuple[int, int]:
    """A pair ``(low, high)`` of ints with ``0 ≤ low < high ≤ high_limit``."""
    power = high_limit.bit_length() - 1
    limit = f"2**{power}" if high_limit == 2**power else str(high_limit)
    accepted = f"a pair (low, high) of ints with 0 ≤ low < high ≤ {limit}"
    if isinstance(value, str | bytes) or not isinstance(value, Sequence | np.ndarray):
        raise TypeError(f"{name} must be {accepted}, got {show(value)}")
    if (isinstance(value, np.ndarray) and value.ndim != 1) or len(value) != 2:
        raise ValueError(f"{name} must be {accepted}, got {show(value)}")
    lo, hi = value
    if not (is_int(lo) and is_int(hi)):
        raise TypeError(f"{name} must be {accepted}, got {show(value)}")
    if not 0 <= lo < hi <= high_limit:
        raise ValueError(f"{name} must be {accepted}, got {show(value)}")
    return int(lo), int(hi)


def check_triple(name: str, value: object, what: str) -> tuple[float, float, float]:
    """Three finite real numbers (a tuple, list or 1-D array), e.g. a start pose."""
    accepted = f"{what}: three finite real numbers"
    if isinstance(value, str | bytes) or not isinstance(value, Sequence | np.ndarray):
        raise TypeError(f"{name} must be {accepted}, got {show(value)}")
    if (isinstance(value, np.ndarray) and value.ndim != 1) or len(value) != 3:
        raise ValueError(f"{name} must be {accepted}, got {show(value)}")
    if not all(is_real(v) for v in value):
        raise TypeError(f"{name} must be {accepted}, got {show(value)}")
    try:
        out = tuple(check_real(name, v) for v in value)
    except ValueError:  # show the whole triple, not the bad entry alone
        raise ValueError(f"{name} must be {accepted}, got {show(value)}") from None
    return out  # type: ignore[return-value]


def _check_fault_fields(where: str, fault: object) -> None:
    # A fault checks its fields when it is made; one made past that (object.__new__, a
    # field set afterwards) is checked again here, named by its place in the schedule.
    # Annotations are strings (postponed evaluation).
    for f in fields(fault):  # type: ignore[arg-type]
        if f.type in ("float", float):
            check_real(f"{where}: {type(fault).__name__}.{f.name}", getattr(fault, f.name))
    try:
        fault.__post_init__()  # type: ignore[attr-defined]
    except (TypeError, ValueError) as exc:
        raise type(exc)(f"{where}: {exc}") from None


def check_fault_schedule(name: str, value: object) -> tuple[Fault, ...]:
    """A fault schedule: a sequence (list, tuple) of ``tfalda_sim.faults`` faults."""
    kinds = ", ".join(t.__name__ for t in FAULT_TYPES)
    if isinstance(value, str | bytes) or not isinstance(value, Sequence):
        raise TypeError(f"{name} must be a sequence (list or tuple) of faults ({kinds} from "
                        f"tfalda_sim.faults), got {show(value)}")
    for i, fault in enumerate(value):
        if not isinstance(fault, FAULT_TYPES):
            raise TypeError(f"{name}[{i}]: unknown fault {show(fault)}; use {kinds} from "
                            "tfalda_sim.faults")
        _check_fault_fields(f"{name}[{i}]", fault)
    return check_schedule(value)
