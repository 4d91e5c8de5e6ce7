"""The note a rendering command prints when it starts compiling on a cold numba cache (the
first run after an install is otherwise silent for about a minute), through the installed
console script. A cold cache: NUMBA_CACHE_DIR pointing to an empty folder."""

from __future__ import annotations

import os
import signal
import subprocess
import threading
from pathlib import Path

from tests.cli_helpers import SCRIPT, child_env, default_sigint, tfalda
from tfalda_sim.cli import COMPILING_NOTE

RENDER = ("render", "--track", "straight", "--s", "2", "--out", "f.png", "--force")


def test_a_cold_cache_is_announced_once_at_the_first_compile(tmp_path: Path) -> None:
    """Stopped once the note is out: the compile itself takes the minute the note names."""
    assert SCRIPT is not None
    env = child_env() | {"NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    proc = subprocess.Popen([SCRIPT, *RENDER], cwd=tmp_path, env=env, text=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            preexec_fn=default_sigint)
    assert proc.stderr is not None
    lines: list[str] = []
    seen = threading.Event()

    def read() -> None:
        for line in proc.stderr:  # type: ignore[union-attr]
            lines.append(line)
            if COMPILING_NOTE in line:
                seen.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        assert seen.wait(timeout=180), f"no note within 180 s; stderr: {''.join(lines)}"
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=120)
        reader.join(timeout=10)
        proc.stderr.close()
    assert lines[0] == COMPILING_NOTE + "\n", lines
    assert sum(COMPILING_NOTE in line for line in lines) == 1, lines
    assert "Traceback" not in "".join(lines)


def test_a_warm_cache_is_not_announced(tmp_path: Path) -> None:
    """Numba's own cache (the package's): warm after one run, whatever it was before."""
    env_cache = os.environ.get("NUMBA_CACHE_DIR")
    assert env_cache is None or Path(env_cache).is_dir()
    tfalda(*RENDER, cwd=tmp_path)
    run = tfalda(*RENDER, cwd=tmp_path)
    assert COMPILING_NOTE not in run.err, run


def test_a_command_refused_before_it_renders_says_nothing_of_compiling(tmp_path: Path
                                                                        ) -> None:
    """A bad --s is refused after the track's few kernels compiled, before the renderer's:
    no note, one error line."""
    env = {"NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    assert SCRIPT is not None
    proc = subprocess.run([SCRIPT, "render", "--track", "oval", "--s", "1e300", "--out",
                           "f.png"], cwd=tmp_path, env=child_env() | env, text=True,
                          capture_output=True, timeout=300, preexec_fn=default_sigint)
    assert proc.returncode == 2, proc.stderr
    assert COMPILING_NOTE not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr
