"""File utilities: put a finished file in place in one step.

``atomic_write`` writes through a temporary file in the target's folder and renames it
over the target, so a failed or interrupted write leaves an existing file untouched;
``publish`` is that last step for a temporary file written by other means (a video).
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any


def publish(tmp: str | os.PathLike[str], target: str | os.PathLike[str]) -> None:
    """Move a finished temporary file onto ``target`` in one step. mkstemp creates 0600;
    the file gets the permissions a plain open() would have given it."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    os.replace(tmp, target)


@contextmanager
def atomic_write(path: str | os.PathLike[str], mode: str = "w") -> Iterator[IO[Any]]:
    """Write ``path`` through a temporary file in its folder (created if missing), put in
    place in one step: a failed or interrupted write leaves an existing file untouched."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    # A short name: a long target name must not become an over-long temporary one.
    fd, tmp = tempfile.mkstemp(prefix=".tfalda-sim-", suffix=".tmp", dir=target.parent)
    try:
        with os.fdopen(fd, mode, encoding=None if "b" in mode else "utf-8") as fh:
            yield fh
        publish(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
