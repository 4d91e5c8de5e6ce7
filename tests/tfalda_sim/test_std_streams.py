"""The console script with its standard streams closed (``>&-``, ``2>&-``) or read by a
reader that has gone (``| head -0``): it stops cleanly, never with a traceback or an
internal error, and never writes its output into a file it opened on a freed descriptor."""

from __future__ import annotations

import os
import subprocess
from collections.abc import Sequence
from pathlib import Path

import pytest

from tests.cli_helpers import SCRIPT, TIMEOUT_S, child_env, default_sigint


def run_with(argv: Sequence[str], cwd: Path, *, close: Sequence[int] = (),
             broken: Sequence[int] = ()) -> tuple[int, bytes, bytes]:
    """Run the console script with the descriptors ``close`` closed and ``broken`` a pipe
    whose reader has already gone; the others are captured."""
    assert SCRIPT is not None
    pipes = {fd: os.pipe() for fd in broken}
    for r, _ in pipes.values():
        os.close(r)  # the reader is gone before the first write: EPIPE

    def setup() -> None:
        default_sigint()
        for fd, (_, w) in pipes.items():
            os.dup2(w, fd)
        for fd in close:
            os.close(fd)

    try:
        proc = subprocess.run([SCRIPT, *argv], cwd=cwd, env=child_env(), capture_output=True,
                              timeout=TIMEOUT_S, check=False, preexec_fn=setup,
                              pass_fds=[w for _, w in pipes.values()])
    finally:
        for _, w in pipes.values():
            os.close(w)
    for stream in (proc.stdout, proc.stderr):
        assert b"Traceback" not in stream and b"internal error" not in stream, proc
        assert b"Exception ignored" not in stream, proc
    return proc.returncode, proc.stdout, proc.stderr


@pytest.mark.parametrize("argv", [["track", "list"], ["track", "list", "--json"],
                                  ["track", "validate", "figure-eight"]])
def test_closed_stdout_stops_quietly_and_non_zero(argv: list[str], tmp_path: Path) -> None:
    code, _, err = run_with(argv, tmp_path, close=[1])
    assert code == 1, err
    assert len(err.decode().strip().splitlines()) <= 1, err


def test_closed_stdout_and_stderr(tmp_path: Path) -> None:
    code, _, _ = run_with(["track", "list"], tmp_path, close=[1, 2])
    assert code == 1


def test_closed_stderr_keeps_the_output_and_the_exit_code(tmp_path: Path) -> None:
    code, out, _ = run_with(["track", "list"], tmp_path, close=[2])
    assert code == 0 and b"figure-eight" in out
    # A bad argument: its message has nowhere to go, its exit code still says it.
    code, out, _ = run_with(["track", "validate", "no-such.json"], tmp_path, close=[2])
    assert code == 2 and out == b""


def test_a_file_written_with_stdout_closed_gets_no_stray_output(tmp_path: Path) -> None:
    """With fd 1 closed, the first file the command opens would get descriptor 1; what the
    command prints must not land in it."""
    code, _, _ = run_with(["track", "generate", "--seed", "3", "--out", "t.json"], tmp_path,
                          close=[1])
    assert code == 1
    text = (tmp_path / "t.json").read_text()
    assert text.lstrip().startswith("{") and text.rstrip().endswith("}")


@pytest.mark.parametrize("fd", [1, 2])
def test_broken_pipe(fd: int, tmp_path: Path) -> None:
    """``| head -0`` on stdout; on stderr, a bad argument whose message cannot be written."""
    argv = ["track", "list"] if fd == 1 else ["track", "validate", "no-such.json"]
    code, _, _ = run_with(argv, tmp_path, broken=[fd])
    assert code == (1 if fd == 1 else 2)
