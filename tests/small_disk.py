"""A folder on a small tmpfs, for the tests of writes on a full disk (``test_full_disk``,
the recorder's): mounted for the block, skipped where tmpfs cannot be mounted (it needs
root; the file-size-limit cases run anywhere)."""

from __future__ import annotations

import contextlib
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest


@contextlib.contextmanager
def tmpfs(folder: Path, size: str) -> Iterator[Path]:
    """``folder`` (existing, empty) as a tmpfs of ``size`` (e.g. ``"4m"``) for the block."""
    try:
        mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs",
                                  str(folder)], capture_output=True, check=False).returncode
    except OSError:
        mounted = -1
    if mounted != 0:
        pytest.skip("cannot mount a tmpfs here (needs root); the size limit case runs")
    try:
        yield folder
    finally:
        if subprocess.run(["umount", str(folder)], check=False).returncode != 0:
            subprocess.run(["umount", "-l", str(folder)], check=False)
