"""A recording that cannot be written (a full disk, a file size limit) fails with a
``WriteError`` naming the file or bag asked for, keeps an existing one as it was and
leaves no temporary file or folder behind.

The writes run in a child process: under a file size limit (``RLIMIT_FSIZE``; Python
ignores SIGXFSZ, so a write fails with EFBIG instead of killing it; works anywhere) and on
a small tmpfs filled up (ENOSPC, as a real full disk; skipped where tmpfs cannot be
mounted). A failure in the last step, the index written by ``close``, is made in-process.
"""

from __future__ import annotations

import errno
import os
import resource
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.small_disk import tmpfs
from tests.tfalda_sim.recording.readback import read_bag, read_mcap, steps
from tfalda_sim.fileio import WriteError
from tfalda_sim.recording import CAMERA_TOPIC, Recorder, RecordingFormat

ROOM = 2 << 20
"""Bytes a child may still write: a few noise frames (≈ 360 kB each as PNG)."""

PRECIOUS = b"an existing recording the failed one must not touch"

CHILD = """
import sys
from pathlib import Path

import numpy as np

from tfalda_sim.fileio import WriteError
from tfalda_sim.recording import RecordedStep, Recorder, RecordingFormat

path, fmt = Path(sys.argv[1]), RecordingFormat(sys.argv[2])
rng = np.random.default_rng(0)
try:
    with Recorder(path, fmt, source="noise") as rec:
        for k in range(200):  # ≈ 70 MB of noise frames
            rec.write(RecordedStep(t_s=k * 0.02,
                                   frame=rng.integers(0, 256, (480, 752), dtype=np.uint8)))
except WriteError as exc:
    print(exc)
    print(exc.path)
    sys.exit(3)
"""


@pytest.fixture(params=["limit", "tmpfs"])
def disk(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[tuple[str, Path]]:
    """(kind, folder): a folder where only ``ROOM`` bytes more can be written."""
    folder = tmp_path / "small"
    folder.mkdir()
    if request.param == "limit":
        yield "limit", folder
        return
    with tmpfs(folder, "8m"):
        yield "tmpfs", folder


def _fill(folder: Path, room: int) -> None:
    """Leave about ``room`` bytes free on ``folder``'s file system."""
    st = os.statvfs(folder)
    with open(folder / "filler", "ab") as fh:
        fh.write(b"\0" * max(0, st.f_bavail * st.f_frsize - room))


def _existing(folder: Path, fmt: RecordingFormat) -> Path:
    if fmt is RecordingFormat.MCAP:
        path = folder / "run.mcap"
        path.write_bytes(PRECIOUS)
    else:
        path = folder / "run"
        path.mkdir()
        (path / "metadata.yaml").write_bytes(PRECIOUS)
        (path / "run.mcap").write_bytes(PRECIOUS)
    return path


def _contents(folder: Path) -> list[tuple[str, bytes]]:
    return sorted((str(p.relative_to(folder)), p.read_bytes()) for p in folder.rglob("*")
                  if p.is_file() and p.name != "filler")


@pytest.mark.parametrize("fmt", list(RecordingFormat))
def test_a_full_disk_names_the_target_and_keeps_the_old_recording(
        disk: tuple[str, Path], fmt: RecordingFormat) -> None:
    kind, folder = disk
    path = _existing(folder, fmt)
    before = _contents(folder)
    if kind == "tmpfs":
        _fill(folder, ROOM)

    def limit() -> None:
        if kind == "limit":
            resource.setrlimit(resource.RLIMIT_FSIZE, (ROOM, ROOM))

    proc = subprocess.run([sys.executable, "-c", CHILD, str(path), fmt.value],
                          capture_output=True, text=True, timeout=300, check=False,
                          preexec_fn=limit)
    assert proc.returncode == 3, proc.stdout + proc.stderr
    message, named = proc.stdout.strip().splitlines()
    reason = os.strerror(errno.ENOSPC if kind == "tmpfs" else errno.EFBIG)
    assert message.startswith(f"cannot write {path}: {reason}; "), message
    assert named == str(path)
    assert ".tfalda-sim-" not in proc.stdout + proc.stderr
    assert _contents(folder) == before
    assert sorted(p.name for p in folder.iterdir() if p.name != "filler") == [path.name]


@pytest.mark.parametrize("fmt", list(RecordingFormat))
def test_a_failure_while_finishing_keeps_the_old_recording(
        tmp_path: Path, fmt: RecordingFormat, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / ("run.mcap" if fmt is RecordingFormat.MCAP else "run")
    with Recorder(path, fmt) as rec:
        rec.write(steps(1)[0])
    old = read_mcap(path) if fmt is RecordingFormat.MCAP else read_bag(path)
    rec = Recorder(path, fmt)
    for step in steps(3, seed=5):
        rec.write(step)
    assert rec._sink is not None
    plain = rec._sink.finish

    def finish_on_a_full_disk() -> None:
        plain()
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(rec._sink, "finish", finish_on_a_full_disk)
    with pytest.raises(WriteError, match=f"cannot write {path}: No space left") as err:
        rec.close()
    assert err.value.path == path
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]
    again = read_mcap(path) if fmt is RecordingFormat.MCAP else read_bag(path)
    assert again.counts == old.counts and again.counts[CAMERA_TOPIC] == 1
