"""What the command-line tests share: the parser's commands, walked from ``build_parser``
(so a new subcommand or option is picked up by the tests without editing them), and
``tfalda``, which runs the installed console script as a user does."""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from tfalda_sim.cli import build_parser


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """The subcommands of ``parser`` by name (empty for a leaf command)."""
    out: dict[str, argparse.ArgumentParser] = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            out.update(action.choices)
    return out


def command_tree() -> dict[tuple[str, ...], argparse.ArgumentParser]:
    """Every command of ``tfalda-sim`` by its path, groups included: ``()`` is the top
    level, ``("track",)`` the group, ``("track", "list")`` a leaf."""
    tree: dict[tuple[str, ...], argparse.ArgumentParser] = {}
    stack: list[tuple[tuple[str, ...], argparse.ArgumentParser]] = [((), build_parser())]
    while stack:
        path, parser = stack.pop()
        tree[path] = parser
        stack.extend(((*path, name), sub) for name, sub in _subcommands(parser).items())
    return dict(sorted(tree.items()))


def leaf_commands() -> dict[tuple[str, ...], argparse.ArgumentParser]:
    """The commands that do something (``track list``, ``render``, …) by path."""
    return {path: p for path, p in command_tree().items() if path and not _subcommands(p)}


SCRIPT: str | None = shutil.which("tfalda-sim", path=str(Path(sys.executable).parent))
"""The console script of the interpreter running the tests (None: not installed)."""

TIMEOUT_S = 300.0
"""Hard limit per command (each takes seconds; a hang must not stall CI)."""


def _not_json(name: str) -> Any:
    """``json.loads``' hook for NaN, Infinity and -Infinity: not JSON (RFC 8259)."""
    raise ValueError(f"{name} is not JSON (a strict parser refuses it; write null)")


@dataclass(frozen=True)
class Run:
    argv: tuple[str, ...]
    code: int
    out: str
    err: str

    def __str__(self) -> str:
        return (f"tfalda-sim {' '.join(self.argv)} → exit {self.code}\n"
                f"--- stdout\n{self.out[-3000:]}\n--- stderr\n{self.err[-3000:]}")

    def json(self) -> dict[str, Any]:
        try:
            doc = json.loads(self.out, parse_constant=_not_json)
        except (json.JSONDecodeError, ValueError) as exc:
            pytest.fail(f"stdout is not one JSON object ({exc})\n{self}")
        assert isinstance(doc, dict), str(self)
        return doc


def child_env() -> dict[str, str]:
    env = dict(os.environ)
    env.pop("TFALDA_SIM_DEBUG", None)  # the one-line "internal error" users see
    return env


def default_sigint() -> None:
    # CI may start the tests with SIGINT ignored, which a child inherits.
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def tfalda(*argv: str | Path, cwd: Path, code: int = 0) -> Run:
    """Run the console script with ``argv`` in ``cwd``; assert it exits with ``code``
    and prints neither a traceback nor an internal error."""
    if SCRIPT is None:
        pytest.fail(f"no tfalda-sim console script next to {sys.executable}: the package's "
                    "[project.scripts] entry point is not installed")
    args = tuple(str(a) for a in argv)
    proc = subprocess.run([SCRIPT, *args], cwd=cwd, env=child_env(), capture_output=True,
                          text=True, timeout=TIMEOUT_S, check=False,
                          preexec_fn=default_sigint)
    run = Run(args, proc.returncode, proc.stdout, proc.stderr)
    assert "Traceback" not in run.err, str(run)
    assert "internal error" not in run.err, str(run)
    assert run.code == code, str(run)
    return run


