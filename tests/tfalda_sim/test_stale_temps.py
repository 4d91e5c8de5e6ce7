"""A run killed outright (SIGKILL, the OOM killer) cannot remove its temporary files; the
next run that writes into the same folder does — only those whose process is gone, on
this host."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from tests.cli_helpers import SCRIPT, child_env, default_sigint, tfalda
from tfalda_sim.video import VideoWriter


def dead_pid() -> int:
    """The pid of a process that has ended."""
    proc = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)
    return int(proc.stdout)


def test_a_killed_drive_leaves_a_temporary_video_the_next_run_removes(tmp_path: Path) -> None:
    assert SCRIPT is not None
    proc = subprocess.Popen([SCRIPT, "drive", "--track", "oval", "--laps", "1000000000",
                             "--video", "d.mp4"], cwd=tmp_path, env=child_env(),
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            preexec_fn=default_sigint)
    try:
        deadline = time.monotonic() + 120
        while not [p for p in tmp_path.glob(".tfalda-sim-*.mp4") if p.stat().st_size]:
            assert proc.poll() is None and time.monotonic() < deadline
            time.sleep(0.2)
    finally:
        proc.kill()
        proc.wait()
    time.sleep(1.0)  # the encoder ends when its pipe closes
    left = list(tmp_path.glob(".tfalda-sim-*.mp4"))
    assert len(left) == 1, left
    tfalda("render", "--track", "oval", "--s", "1", "--out", "r.png", cwd=tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.png"]

    from tfalda_sim.fileio import temp_path

    mine = temp_path(tmp_path, ".png")  # a live process' (this one's): kept
    mine.write_bytes(b"x")
    other_host = tmp_path / f".tfalda-sim-{proc.pid}.zzzz.0123abcd.tmp.json"
    other_host.write_bytes(b"x")
    tfalda("render", "--track", "oval", "--s", "1", "--out", "r.png", "--force", cwd=tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        ["r.png", mine.name, other_host.name])


def test_each_writer_sweeps_its_folder(tmp_path: Path) -> None:
    """The video writer, staged outputs and atomic_write all clear a killed run's files
    (the cleaning itself: ``remove_stale_temps``)."""
    from tfalda_sim.fileio import atomic_write, remove_stale_temps, temp_path
    from tfalda_sim.outputs import Outputs

    pid = dead_pid()

    def plant() -> list[Path]:
        """Temporary files a killed process of this host left (a video, a PNG, a JSON)."""
        names = [temp_path(tmp_path, suffix).name.replace(f"-{os.getpid()}.", f"-{pid}.", 1)
                 for suffix in (".mp4", ".png", "")]
        for name in names:
            (tmp_path / name).write_bytes(b"x")
        return [tmp_path / name for name in names]

    keep = tmp_path / ".tfalda-sim-probe.x"  # not a temporary name of ours: kept
    keep.write_bytes(b"x")
    planted = plant()
    with VideoWriter(tmp_path / "v.mp4", 25.0) as w:
        w.write(np.zeros((48, 64), np.uint8))
    assert not any(p.exists() for p in planted) and keep.exists()
    planted = plant()
    with Outputs() as outs:
        outs.path(tmp_path / "a.json").write_text("{}")
        outs.commit()
    assert not any(p.exists() for p in planted)
    planted = plant()
    with atomic_write(tmp_path / "b.json") as fh:
        fh.write("{}")
    assert not any(p.exists() for p in planted)
    assert sorted(p.name for p in tmp_path.iterdir()) == [keep.name, "a.json", "b.json",
                                                         "v.mp4"]
    assert remove_stale_temps(tmp_path / "missing") == []
