"""A command's output files: checked before any work, written all or none.

Every ``tfalda-sim`` command that writes files follows the same rules:

1. **Checked first.** Before any work, every output is checked (``check_outputs``): the
   right suffix, not a directory, not one of the command's inputs, two outputs never on
   one path, its folder creatable and writable (probed by creating and removing a
   temporary file there: permission bits say nothing to root or on a read-only mount),
   and an existing file replaced only with ``--force``.
2. **All or none.** The files are written to temporary names beside their targets
   (``Outputs.path``) and put in place together by ``Outputs.commit``; an error before the
   commit removes the temporary files and any folder the command created, so a failed
   command leaves the disk as it found it.
3. **Ctrl-C keeps what was finished.** A command interrupted by Ctrl-C commits what it
   had (the video so far, the results so far) and says so (see ``tfalda_sim.cli``).
4. **A journal survives a kill.** A sweep's ``--results`` file grows under a fixed name
   beside it (``Outputs.journal``: ``F.jsonl.partial``), a line per finished job, and
   becomes the file itself when the command ends; a process killed outright (SIGKILL,
   the OOM killer) leaves the journal, which ``--resume`` continues. (Lines are flushed
   to the kernel, not synced to the disk: a power cut may lose the last ones.)
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from tfalda_sim.fileio import (
    WriteError,
    is_write_failure,
    publish,
    remove_stale_temps,
    stage,
    temp_path,
    unstage,
)

DIRECTORY = "/"
"""The ``suffix`` of an output that is a folder (``stress --out DIR``)."""

JOURNAL_SUFFIX = ".partial"
"""What a journal's name adds to its target's (``Outputs.journal``)."""


def journal_of(target: str | os.PathLike[str]) -> Path:
    """Where ``target`` grows as a journal while its command runs (``F.jsonl.partial``)."""
    target = Path(target)
    return target.with_name(target.name + JOURNAL_SUFFIX)


class OutputError(ValueError):
    """An output that cannot be written as asked: names the option, the path and the fix."""


@dataclass(frozen=True)
class Output:
    """One output of a command: the option that names it, its path and its suffix
    (``".png"``; ``DIRECTORY`` for a folder)."""

    option: str
    path: Path
    suffix: str


def _nearest_existing(path: Path) -> Path:
    p = path
    while not p.exists() and p != p.parent:
        if p.is_symlink():  # a dangling link: its folder is what counts
            break
        p = p.parent
    return p


def _probe_writable(folder: Path) -> str | None:
    """Why ``folder`` cannot take a new file, or None (creates and removes a file)."""
    try:
        fd, tmp = tempfile.mkstemp(prefix=".tfalda-sim-probe.", dir=folder)
    except OSError as exc:
        return exc.strerror or str(exc)
    os.close(fd)
    os.unlink(tmp)
    return None


def _check_name_length(option: str, path: Path) -> None:
    """Every part of ``path`` fits the file system's name limit (checked first: even
    asking whether an over-long path exists fails)."""
    try:
        name_max = os.pathconf("/", "PC_NAME_MAX")
    except (OSError, ValueError):
        name_max = 255
    too_long = [part for part in path.parts if len(os.fsencode(part)) > name_max]
    if too_long:
        raise OutputError(f"{option}: the name {too_long[0][:40]}… is longer than the "
                          f"{name_max} bytes a file name may have; choose a shorter one")


def _check_folder(option: str, path: Path, folder: Path) -> None:
    base = _nearest_existing(folder)
    if not base.is_dir():
        raise OutputError(f"{option} {path}: {base} is a file, not a folder; choose another "
                          "path")
    why = _probe_writable(base)
    if why is not None:
        raise OutputError(f"{option} {path}: cannot write in {base} ({why}); choose a "
                          "writable folder")


def _same(a: Path, b: Path) -> bool:
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return a.resolve() == b.resolve()


def check_outputs(outputs: Iterable[Output], *, force: bool,
                  inputs: Mapping[str, Path] | None = None,
                  files_in: Mapping[str, Iterable[str]] | None = None) -> None:
    """Refuse outputs that cannot be written as asked, before any work (module rules).
    ``inputs``: the command's input files by option (an output may not replace one);
    ``files_in``: for a ``DIRECTORY`` output, the names of the entries it will get, folders
    ending in ``/`` (each existing one needs ``force``; a folder where a file goes, or a
    file where a folder goes, is refused)."""
    outs = list(outputs)
    files_in = files_in or {}
    for out in outs:
        p = out.path
        _check_name_length(out.option, p)
        if out.suffix == DIRECTORY:
            if p.exists() and not p.is_dir():
                raise OutputError(f"{out.option} {p} is a file; give a folder")
            _check_folder(out.option, p, p)
            continue
        if p.suffix.lower() != out.suffix:
            raise OutputError(f"{out.option} {p} must end in {out.suffix}")
        if p.is_dir():
            raise OutputError(f"{out.option} {p} is a folder; give a {out.suffix} file name")
        _check_folder(out.option, p, p.parent)
        if p.exists() and not os.access(p, os.W_OK) and os.geteuid() != 0:
            raise OutputError(f"{out.option} {p} is read-only; choose another path")
    targets = [(o.option, o.path) for o in outs if o.suffix != DIRECTORY]
    for o in outs:
        if o.suffix != DIRECTORY:
            continue
        for name in files_in.get(o.option, ()):
            entry = o.path / name.rstrip("/")
            if name.endswith("/"):
                if entry.exists() and not entry.is_dir():
                    raise OutputError(f"{o.option} {o.path}: {entry} is a file where the "
                                      "command writes a folder; move it away")
            else:
                if entry.is_dir():
                    raise OutputError(f"{o.option} {o.path}: {entry} is a folder where the "
                                      "command writes a file; move it away")
            targets.append((o.option, entry))
    for i, (opt_a, a) in enumerate(targets):
        for opt_b, b in targets[i + 1:]:
            if _same(a, b):
                raise OutputError(f"{opt_a} and {opt_b} name the same file {a}; give each "
                                  "its own path")
        for opt_in, src in (inputs or {}).items():
            if _same(a, src):
                raise OutputError(f"{opt_a} {a} is the {opt_in} input; write elsewhere")
    # A dangling symlink counts as existing: writing would replace the link.
    existing = [str(p) for _, p in targets if p.exists() or p.is_symlink()]
    if existing and not force:
        raise OutputError(f"{', '.join(existing)} exists; add --force to overwrite")


class Outputs:
    """Temporary files for a command's outputs, put in place together by ``commit``.

    ``path(target)`` gives the temporary path to write ``target`` to (same folder, same
    suffix, so writers that go by the suffix — matplotlib, OpenCV — write the right
    format); folders are created on demand and removed again by ``abort`` if the command
    created them. Used as a context manager it aborts on any exception; the caller
    commits explicitly (also after a Ctrl-C it decided to survive)."""

    def __init__(self) -> None:
        self._staged: dict[Path, Path] = {}
        self._kept: set[Path] = set()
        self._made_dirs: list[Path] = []
        self._swept: set[Path] = set()
        self.written: list[Path] = []

    def _makedirs(self, folder: Path) -> None:
        missing = []
        p = folder
        while not p.exists():
            missing.append(p)
            p = p.parent
        for d in reversed(missing):
            d.mkdir()
            self._made_dirs.append(d)

    def _stage(self, target: Path, tmp: Path) -> None:
        if target.parent not in self._swept:
            self._swept.add(target.parent)
            remove_stale_temps(target.parent)
        self._staged[target] = tmp
        stage(tmp, target)

    def path(self, target: str | os.PathLike[str]) -> Path:
        """The temporary path ``target`` is to be written to (one per target)."""
        target = Path(target)
        if target in self._staged:
            return self._staged[target]
        self._makedirs(target.parent)
        tmp = temp_path(target.parent, target.suffix)
        self._stage(target, tmp)
        return tmp

    def journal(self, target: str | os.PathLike[str], *, keep_on_abort: bool = False) -> Path:
        """The fixed path ``target`` grows at (``journal_of``), published as ``target`` by
        ``commit``. ``abort`` removes it, unless ``keep_on_abort`` (a resumed journal:
        it held finished jobs before this command, and holds more now)."""
        target = Path(target)
        self._makedirs(target.parent)
        tmp = journal_of(target)
        self._stage(target, tmp)
        if keep_on_abort:
            self._kept.add(tmp)
        return tmp

    def commit(self) -> list[Path]:
        """Put every written temporary file in place; returns the targets written (a
        target whose temporary file was never created is skipped). Every target is
        checked before the first one is replaced: a folder in a file's place (made since
        the check) fails the whole commit, naming the target."""
        for target, tmp in self._staged.items():
            if tmp.exists() and target.is_dir():
                raise OutputError(f"cannot write {target}: a folder is in its place; "
                                  "nothing was written")
        for target, tmp in self._staged.items():
            if tmp.exists():
                try:
                    publish(tmp, target)
                except OSError as exc:
                    raise WriteError.of(target, exc) from None
                self.written.append(target)
        self._forget()
        self._kept.clear()
        self._made_dirs.clear()
        return list(self.written)

    def _forget(self) -> None:
        for tmp in self._staged.values():
            unstage(tmp)
        self._staged.clear()
        self._kept.clear()

    def abort(self) -> None:
        """Remove the temporary files and the folders this command created."""
        for tmp in self._staged.values():
            if tmp not in self._kept:
                tmp.unlink(missing_ok=True)
        self._forget()
        for d in reversed(self._made_dirs):
            try:
                d.rmdir()
            except OSError:  # someone else put a file there meanwhile: keep it
                pass
        self._made_dirs.clear()

    def __enter__(self) -> Outputs:
        return self

    def failed_target(self, exc: BaseException) -> Path | None:
        """The target whose write ``exc`` is, if it is a write that failed for want of space
        (or a size limit, a bad disk): the one whose temporary file it names, or, for an
        error that names no file (a full disk shows in ``write()``), the target written
        last."""
        staged = {tmp: target for target, tmp in self._staged.items()}
        if not is_write_failure(exc, *staged):
            return None
        name = getattr(exc, "filename", None)
        if name is not None:
            return staged[Path(os.fsdecode(name))]
        written = []
        for k, (tmp, target) in enumerate(staged.items()):
            try:
                written.append((tmp.stat().st_mtime_ns, k, target))
            except OSError:
                continue
        if written:
            return max(written)[2]
        return next(reversed(staged.values()), None)

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 *_: object) -> None:
        failed = self.failed_target(exc) if exc is not None else None
        if exc_type is not None or self._staged:
            # Anything not committed explicitly is not kept.
            self.abort()
        if failed is not None:
            assert isinstance(exc, OSError)
            raise WriteError.of(failed, exc) from None


@contextmanager
def staged(*targets: str | os.PathLike[str] | None) -> Iterator[list[Path | None]]:
    """Write several files all or none: yields their temporary paths (None stays None)
    and commits them when the block ends without an exception."""
    with Outputs() as outs:
        yield [None if t is None else outs.path(t) for t in targets]
        outs.commit()
