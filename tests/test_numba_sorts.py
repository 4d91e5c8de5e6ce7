"""Sorting inside cached numba kernels.

numba names the helpers of its quicksort by the process's own count of compiled functions.
Two cached kernels compiled in different processes can therefore carry helpers with one
name but different code (an argsort's and an in-place sort's, on the same dtype); the
process that loads both links every call to whichever came first. It happened: once
the scene kernels (``scene._propagate``'s in-place sort) were recompiled, the Hough
baseline's cached ``_lines`` (an argsort) returned indices from uninitialised memory,
different segments on every call. The rule that keeps every name to one piece of code:
in a kernel, an argsort is a merge sort (``kind="mergesort"``), every other sort is a
quicksort (no ``kind``), and no sort or search takes the options that make other
variants of the same helpers (a list's ``reverse=``/``key=``, ``sorted()``,
``searchsorted``'s ``side=``)."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("tfalda_sim", "tracks", "envs", "agents", "benchmarks")


def _kernels() -> list[tuple[str, ast.FunctionDef]]:
    """Every function decorated with ``njit`` / ``jit`` (bare or called) in our code."""
    out = []
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"))
            for node in ast.walk(tree):
                if not isinstance(node, ast.FunctionDef):
                    continue
                for dec in node.decorator_list:
                    target = dec.func if isinstance(dec, ast.Call) else dec
                    name = target.attr if isinstance(target, ast.Attribute) else getattr(
                        target, "id", "")
                    if name in ("njit", "jit"):
                        out.append((f"{path.relative_to(ROOT)}:{node.name}", node))
    return out


def _sort_calls(fn: ast.FunctionDef) -> list[tuple[str, str | None, int, int]]:
    """``(kind of call, its kind= argument, its number of other arguments, line)`` of every
    sort or search that numba builds from helpers in ``fn``."""
    calls = []
    for node in ast.walk(fn):
        if not isinstance(node, ast.Call):
            continue
        if isinstance(node.func, ast.Attribute):
            name = node.func.attr
        elif isinstance(node.func, ast.Name):
            name = node.func.id
        else:
            continue
        if name in ("argsort", "sort", "unique", "sorted", "searchsorted"):
            kind = next((kw.value.value for kw in node.keywords if kw.arg == "kind"
                         and isinstance(kw.value, ast.Constant)), None)
            others = len([kw for kw in node.keywords if kw.arg != "kind"])
            calls.append((name, kind, others, node.lineno))
    return calls


def test_kernels_are_found() -> None:
    names = {name for name, _ in _kernels()}
    assert any(n.endswith(":_lines") for n in names)
    assert any(n.endswith(":_propagate") for n in names)
    assert len(names) > 50


@pytest.mark.parametrize(("name", "fn"), _kernels(), ids=lambda v: v if isinstance(v, str)
                         else "")
def test_sorts_in_kernels_follow_the_rule(name: str, fn: ast.FunctionDef) -> None:
    for call, kind, others, line in _sort_calls(fn):
        # Variants that numba builds from the same helpers under the same names: a list's
        # sort with reverse= or key=, sorted(), a searchsorted with another side=.
        assert call != "sorted" and others == 0, (
            f"{name} line {line}: {call} with {others} keyword argument(s) in a cached "
            "kernel: its helpers could share names with another variant's (see this "
            "module's docstring); sort an array with its plain sort instead")
        if call == "argsort":
            assert kind == "mergesort", (
                f"{name} line {line}: an argsort in a cached kernel must be "
                "np.argsort(…, kind=\"mergesort\") (see this module's docstring)")
        else:
            assert kind in (None, "quicksort"), (
                f"{name} line {line}: {call} in a cached kernel must be a quicksort (no "
                "kind=): a merge sort's helpers would share names with the argsorts'")


def test_the_hough_lines_kernel_equals_its_python() -> None:
    """``_lines`` (its argsort) gives what its plain Python gives, call after call."""
    from tfalda_sim.perception.hough import _lines

    rng = np.random.default_rng(0)
    xs, ys = [], []
    for x in (20, 50, 90):  # three vertical lines with gaps, pixels shuffled
        for y in rng.permutation(np.r_[0:60, 70:150, 160:199]):
            xs.append(x)
            ys.append(y)
    perm = rng.permutation(len(xs))
    x_px = np.array(xs, np.int32)[perm]
    y_px = np.array(ys, np.int32)[perm]
    theta = np.deg2rad(np.arange(-80.0, 80.0, 1.0))
    peaks = np.array([[320, 80], [350, 80], [390, 80]], np.int64)  # θ = 0, ρ = x + 300
    args = (x_px, y_px, np.cos(theta), np.sin(theta), -300.0, 1.0, peaks, 9.0, 4.0, 200, 200)
    want_segs, want_owner = _lines.py_func(*args)
    assert len(want_segs) == 9  # three segments per line
    for _ in range(3):
        segs, owner = _lines(*args)
        np.testing.assert_array_equal(segs, want_segs)
        np.testing.assert_array_equal(owner, want_owner)
