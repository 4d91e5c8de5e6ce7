"""File utilities: put a finished file in place in one step, name the file a failed write
was for, and clear away the temporary files of runs that were killed.

``atomic_write`` writes through a temporary file in the target's folder and renames it
over the target, so a failed or interrupted write leaves an existing file untouched;
``publish`` is that last step for a temporary file written by other means (a video).

Temporary files are named by ``temp_path``: ``.tfalda-sim-PID.HOST.RANDOM.tmp.SUFFIX``.
A run killed outright (SIGKILL, the OOM killer) cannot remove its own; the next run that
writes into the same folder does (``remove_stale_temps``): a temporary file of this host
whose process is gone. A write that fails for want of space (or a size limit, a read-only
or failing disk) raises ``WriteError``, which names the file the user asked for — not the
temporary one — the reason and what to do.
"""

from __future__ import annotations

import errno
import hashlib
import os
import re
import secrets
import shutil
import socket
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

TEMP_PREFIX = ".tfalda-sim-"
"""How every temporary file of ours begins (and the probe files of ``outputs``)."""

_HOST = hashlib.sha1(socket.gethostname().encode(), usedforsecurity=False).hexdigest()[:4]
"""This host, in temporary names: a folder shared between hosts (NFS) holds files of
processes whose pid means nothing here; only this host's are judged by their pid."""

_TEMP_NAME = re.compile(r"\.tfalda-sim-(\d+)\.([0-9a-f]{4})\.[0-9a-f]+\.tmp(\.[^/]*)?\Z")

WRITE_ERRNOS: frozenset[int] = frozenset(
    {errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.EIO})
"""The errors of a write that a better place, not a better input, fixes."""

_ADVICE: dict[int, str] = {
    errno.ENOSPC: "free some space or write to another disk",
    errno.EDQUOT: "your disk quota is used up: free some space or write elsewhere",
    errno.EFBIG: "the file outgrew the size limit (ulimit -f, or the file system's): "
                 "write a shorter one, raise the limit or write elsewhere",
    errno.EROFS: "write elsewhere",
    errno.EIO: "check the disk or write elsewhere",
}

_STAGED: dict[Path, Path] = {}
"""Temporary path → the file the user asked for (``stage``), for error messages."""


def stage(tmp: str | os.PathLike[str], target: str | os.PathLike[str]) -> None:
    """Note that ``tmp`` is written for ``target``: a ``WriteError`` for ``tmp`` names
    ``target``."""
    _STAGED[Path(tmp)] = Path(target)


def unstage(tmp: str | os.PathLike[str]) -> None:
    _STAGED.pop(Path(tmp), None)


def target_of(path: str | os.PathLike[str]) -> Path:
    """The file the user asked for that ``path`` is written for (``path`` itself if it is
    not a staged temporary file); follows a temporary file of a temporary file."""
    p = Path(path)
    seen = {p}
    while p in _STAGED and _STAGED[p] not in seen:
        p = _STAGED[p]
        seen.add(p)
    return p


class WriteError(OSError):
    """A file that could not be written: one line with the file the user asked for, the
    reason and what to do (``str()`` and ``strerror`` are that line)."""

    def __init__(self, path: str | os.PathLike[str], reason: str, code: int = 0) -> None:
        self.path = target_of(path)
        advice = _ADVICE.get(code, "")
        super().__init__(code, f"cannot write {self.path}: {reason}"
                         + (f"; {advice}" if advice else ""))

    def __str__(self) -> str:
        return str(self.strerror)

    @classmethod
    def of(cls, path: str | os.PathLike[str], exc: OSError) -> WriteError:
        """The ``WriteError`` for ``path`` that ``exc`` caused (itself if it is one)."""
        if isinstance(exc, WriteError):
            return exc
        return cls(path, exc.strerror or str(exc), exc.errno or 0)


def is_write_failure(exc: BaseException, *paths: str | os.PathLike[str]) -> bool:
    """``exc`` is a write to one of ``paths`` (or to an unnamed file) that failed for want
    of space, a size limit or a bad disk (``WRITE_ERRNOS``) — not some other error that
    happened while the file was being written."""
    if not isinstance(exc, OSError) or isinstance(exc, WriteError):
        return False
    if exc.errno not in WRITE_ERRNOS:
        return False
    return exc.filename is None or Path(os.fsdecode(exc.filename)) in {Path(p) for p in paths}


def temp_path(folder: str | os.PathLike[str], suffix: str = "") -> Path:
    """A new temporary name in ``folder`` (not created): this process' pid and host in
    it, so that a later run can tell a killed run's file (``remove_stale_temps``). Short:
    a long target name must not become an over-long temporary one."""
    return Path(folder) / (f"{TEMP_PREFIX}{os.getpid()}.{_HOST}.{secrets.token_hex(4)}"
                           f".tmp{suffix}")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    except OverflowError:
        return False
    return True


def remove_stale_temps(folder: str | os.PathLike[str]) -> list[Path]:
    """Remove the temporary files and folders (a ROS 2 bag being written is a folder) in
    ``folder`` that a process of this host left when it was killed (its pid no longer
    runs); the paths removed. Best effort: what cannot be removed, or a folder that
    cannot be listed, is left alone."""
    removed = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    me = os.getpid()
    for entry in entries:
        m = _TEMP_NAME.match(entry.name)
        if m is None or m.group(2) != _HOST or int(m.group(1)) == me:
            continue
        if _alive(int(m.group(1))):
            continue
        try:
            if entry.is_file(follow_symlinks=False):
                os.unlink(entry.path)
                removed.append(Path(entry.path))
            elif entry.is_dir(follow_symlinks=False):
                shutil.rmtree(entry.path)
                removed.append(Path(entry.path))
        except OSError:
            pass
    return removed


def publish(tmp: str | os.PathLike[str], target: str | os.PathLike[str]) -> None:
    """Move a finished temporary file onto ``target`` in one step. mkstemp creates 0600;
    the file gets the permissions a plain open() would have given it."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    os.replace(tmp, target)


def create_temp(folder: str | os.PathLike[str], suffix: str = "") -> tuple[int, Path]:
    """Create a new temporary file in ``folder`` (``temp_path``, mode 0600, as mkstemp);
    its open descriptor and path. Stale temporary files of killed runs there go first."""
    remove_stale_temps(folder)
    while True:
        path = temp_path(folder, suffix)
        try:
            return os.open(path, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o600), path
        except FileExistsError:
            continue


@contextmanager
def atomic_write(path: str | os.PathLike[str], mode: str = "w") -> Iterator[IO[Any]]:
    """Write ``path`` through a temporary file in its folder (created if missing), put in
    place in one step: a failed or interrupted write leaves an existing file untouched;
    a full disk is a ``WriteError`` naming ``path``."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = create_temp(target.parent)
    try:
        with os.fdopen(fd, mode, encoding=None if "b" in mode else "utf-8") as fh:
            yield fh
        publish(tmp, target)
    except BaseException as exc:
        tmp.unlink(missing_ok=True)
        if is_write_failure(exc, tmp, target):
            assert isinstance(exc, OSError)
            raise WriteError.of(target, exc) from None
        raise
