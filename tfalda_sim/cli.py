"""The ``tfalda-sim`` command line: assembles the domains' commands.

Each domain keeps its commands in its own ``command.py`` with one scheme: a
``register(subparsers)`` that adds them, and a ``cmd_<command>(args) -> int`` per command.
The shared option types, the output check and the exit codes live in
``tfalda_sim.cli_common``: 0 success, 1 the command ran but the result is negative (an
invalid track, laps not completed), 2 bad input, 130 stopped by Ctrl-C.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import importlib
import io
import os
import signal
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path

from .cli_common import EXIT_BAD_INPUT, EXIT_NEGATIVE, EXIT_OK, CliError, interrupted
from .interrupts import held_stop, is_interrupt, stop_signals_interrupt
from .outputs import OutputError

COMMAND_MODULES: tuple[str, ...] = ("tracks.command", "camera.command", "rendering.command",
                                    "evaluation.command",
                                    "agents.command", "replay.command")
"""The domains' command modules (under ``tfalda_sim``), in the order ``--help`` lists them;
imported by ``build_parser``, inside ``main``'s error handling (numba, OpenCV and the
rest take most of a second to import: a Ctrl-C then must not print a traceback)."""


RENDERING_COMMANDS: frozenset[str] = frozenset(
    {"render", "evaluate", "compare", "drive", "train", "stress", "evaluate-agent"})
"""The commands that render camera frames: each compiles the renderer's numba kernels,
most of the ≈ 1 min a cold kernel cache costs (a fresh install: ``make install`` empties
it)."""

HEAVY_KERNEL_PACKAGES: tuple[str, ...] = ("tfalda_sim.rendering", "tfalda_sim.perception")
"""Whose kernels take most of a cold cache's minute to compile."""

COMPILING_NOTE = ("compiling the simulator's kernels once (≈ 1 min; later runs load them "
                  "from numba's cache) …")


def _renderer_cache_is_cold() -> bool:
    """True if numba's on-disk cache holds none of the renderer's kernels (in the folder
    numba itself would use: NUMBA_CACHE_DIR's, the package's __pycache__ or the user's
    cache); False when unsure (numba's locators are not a public API)."""
    try:
        import importlib.util

        from numba.core.caching import CacheImpl

        spec = importlib.util.find_spec("tfalda_sim.rendering.renderer")
        if spec is None or spec.origin is None:
            return False
        for cls in CacheImpl._locator_classes:
            locator = cls.from_function(_renderer_cache_is_cold, spec.origin)
            if locator is not None:
                return not any(Path(locator.get_cache_path()).glob("renderer.*.nbi"))
    except Exception:
        return False
    return False


@contextlib.contextmanager
def _note_first_compile(command: str | None) -> Iterator[None]:
    """One line on stderr when a rendering command starts compiling on a cold cache: without
    it the first run is silent for a minute. Said at the first compile, not before the
    command (a bad argument then fails at once, without it), and once: the sweep workers
    forked from here inherit the listener and share the one lock."""
    if command not in RENDERING_COMMANDS or not _renderer_cache_is_cold():
        yield
        return
    import multiprocessing

    from numba.core import event
    from tqdm import tqdm

    once = multiprocessing.Lock()

    class Note(event.Listener):
        def on_start(self, ev: event.Event) -> None:
            # The renderer's and the detector's kernels: the minute. A track's few
            # kernels take seconds (and compile before a bad --s is refused).
            data = ev.data if isinstance(ev.data, dict) else {}
            func = getattr(data.get("dispatcher"), "py_func", None)
            if (getattr(func, "__module__", "").startswith(HEAVY_KERNEL_PACKAGES)
                    and once.acquire(block=False)):  # never released: said once
                try:  # above a progress bar of this process, which is drawn again below
                    tqdm.write(COMPILING_NOTE, file=sys.stderr)
                except OSError:
                    _silence_std_streams()

        def on_end(self, ev: event.Event) -> None:
            pass

    with event.install_listener("numba:compile", Note()):
        yield


def _version() -> str:
    """The installed distribution's version (its metadata is what pip and bug reports see);
    the package's own ``__version__`` when run from a tree that is not installed."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("tfalda-sim")
    except PackageNotFoundError:
        from . import __version__
        return __version__


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="tfalda-sim", description="Carolo-Cup lane-keeping simulator (tfalda-sim).")
    parser.add_argument("--version", action="version", version=f"tfalda-sim {_version()}")
    sub = parser.add_subparsers(dest="command", required=True)
    for name in COMMAND_MODULES:
        importlib.import_module(f"tfalda_sim.{name}").register(sub)
    return parser


class _ClosedStdout(io.TextIOBase):
    """``sys.stdout`` when the caller closed descriptor 1 (``>&-``): the first write fails as
    a write to a pipe whose reader has gone, so the command stops on the path of ``| head``
    (quietly, exit 1) — its result reaches no one. Descriptor 1 itself is /dev/null."""

    def writable(self) -> bool:
        return True

    def write(self, text: str) -> int:
        if text:
            raise BrokenPipeError(errno.EPIPE, "stdout is closed")
        return 0

    def fileno(self) -> int:
        return 1


def _fill_closed_std_streams() -> None:
    """Python sets ``sys.stdout``/``sys.stderr`` to None when the descriptor is closed at
    start (``>&-``, ``2>&-``), and the next file opened would take that free descriptor —
    anything then written to "stdout" (a child's, a C library's) would go into that file.
    /dev/null takes the descriptor instead; stdout's writes then fail like a broken pipe,
    stderr's are dropped (its messages have nowhere to go; the exit code still says)."""
    for fd, name in ((0, "stdin"), (1, "stdout"), (2, "stderr")):
        if getattr(sys, name) is not None:
            continue
        try:
            os.fstat(fd)
        except OSError:
            null = os.open(os.devnull, os.O_RDWR)
            if null != fd:
                os.dup2(null, fd)
                os.close(null)
        if name == "stdout":
            sys.stdout = _ClosedStdout()
        elif name == "stderr":
            sys.stderr = open(fd, "w", closefd=False)
        else:
            sys.stdin = open(fd, closefd=False)


def _silence_std_streams() -> None:
    """stdout or stderr gone (a closed pipe): both to /dev/null, so that neither the rest of
    the run nor the interpreter's final flush writes to them again."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    for stream in (sys.stdout, sys.stderr):
        try:
            os.dup2(devnull, stream.fileno())
        except (AttributeError, OSError, ValueError):
            pass  # not a descriptor (a test's capture): nothing reaches a terminal
    os.close(devnull)


def _say(line: str) -> None:
    """One line on stderr; nothing if stderr is a closed pipe (the exit code still says)."""
    try:
        print(line, file=sys.stderr, flush=True)
    except OSError:
        _silence_std_streams()


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command and return its exit code (``tfalda_sim.cli_common``); a bad
    argument is reported with the usage and returns 2 (``--help`` returns 0)."""
    _fill_closed_std_streams()
    with stop_signals_interrupt():  # SIGTERM and SIGHUP take Ctrl-C's clean path
        try:
            return _run(argv)
        except BrokenPipeError:
            # A message of the handlers below (a Ctrl-C's) met a closed stderr.
            _silence_std_streams()
            return EXIT_NEGATIVE


def _run(argv: Sequence[str] | None) -> int:
    try:
        try:
            parser = build_parser()
            args = parser.parse_args(argv)
        except SystemExit as exc:  # argparse has printed the usage and the error
            return exc.code if isinstance(exc.code, int) else EXIT_BAD_INPUT
        with _note_first_compile(getattr(args, "command", None)):
            code = int(args.func(args))
        sys.stdout.flush()  # a closed pipe shows here, inside the handling below
        if held_stop() is not None and code in (EXIT_OK, EXIT_NEGATIVE):
            # A first Ctrl-C that came while the finished command saved its results
            # (``holding_stops``): everything was kept, and the stop is not swallowed.
            return interrupted("it came as the command saved its finished results; all "
                               "of them were kept")
        return code
    except (CliError, OutputError) as exc:
        _say(f"error: {exc}")
        return EXIT_BAD_INPUT
    except SystemExit as exc:  # a handler's parser.error(): usage and message printed
        return exc.code if isinstance(exc.code, int) else EXIT_BAD_INPUT
    except KeyboardInterrupt:
        # The long commands catch Ctrl-C themselves and keep what they finished; here it
        # struck while nothing could be kept (starting up, or before a first result).
        return interrupted("nothing written")
    except BrokenPipeError:
        # stdout or stderr closed by its reader (`… | head`): stop quietly. What was
        # committed before stays; the result did not all reach the reader: exit 1.
        _silence_std_streams()
        return EXIT_NEGATIVE
    except OSError as exc:
        _say(f"error: {exc.strerror or exc}" + (f": {exc.filename}" if exc.filename else ""))
        return EXIT_BAD_INPUT
    except Exception as exc:  # a bug: one line, the traceback on demand
        if is_interrupt(exc):  # a Ctrl-C that numba reported as a SystemError
            return interrupted("nothing written")
        if os.environ.get("TFALDA_SIM_DEBUG"):
            raise
        _say(f"internal error: {type(exc).__name__}: {exc} (set TFALDA_SIM_DEBUG=1 for the "
             "traceback and please report it)")
        return EXIT_NEGATIVE


def console_main() -> int:
    """The ``tfalda-sim`` console script: ``main``, then the stop signals ignored for the
    rest of the process — the command is done, and a late second Ctrl-C during the
    interpreter's shutdown would otherwise kill it and turn exit 130 into a signal death."""
    code = main()
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, signal.SIG_IGN)
    return code


if __name__ == "__main__":
    sys.exit(console_main())
