"""The ``tfalda-sim`` command line: assembles the domains' commands.

Each domain keeps its commands in its own ``command.py`` with one scheme: a
``register(subparsers)`` that adds them, and a ``cmd_<command>(args) -> int`` per command.
The shared option types, the output check and the exit codes live in
``tfalda_sim.cli_common``: 0 success, 1 the command ran but the result is negative (an
invalid track, laps not completed), 2 bad input, 130 stopped by Ctrl-C.
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
from collections.abc import Sequence

from .cli_common import EXIT_BAD_INPUT, EXIT_NEGATIVE, EXIT_OK, CliError, interrupted
from .interrupts import held_stop, is_interrupt, stop_signals_interrupt
from .outputs import OutputError

COMMAND_MODULES: tuple[str, ...] = ("tracks.command", "camera.command", "rendering.command",
                                    "evaluation.command",
                                    "agents.command", "replay.command")
"""The domains' command modules (under ``tfalda_sim``), in the order ``--help`` lists them;
imported by ``build_parser``, inside ``main``'s error handling (numba, OpenCV and the
rest take most of a second to import: a Ctrl-C then must not print a traceback)."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="tfalda-sim", description="Carolo-Cup lane-keeping simulator (tfalda-sim).")
    sub = parser.add_subparsers(dest="command", required=True)
    for name in COMMAND_MODULES:
        importlib.import_module(f"tfalda_sim.{name}").register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command and return its exit code (``tfalda_sim.cli_common``); a bad
    argument is reported with the usage and returns 2 (``--help`` returns 0)."""
    with stop_signals_interrupt():  # SIGTERM and SIGHUP take Ctrl-C's clean path
        return _run(argv)


def _run(argv: Sequence[str] | None) -> int:
    try:
        try:
            parser = build_parser()
            args = parser.parse_args(argv)
        except SystemExit as exc:  # argparse has printed the usage and the error
            return exc.code if isinstance(exc.code, int) else EXIT_BAD_INPUT
        code = int(args.func(args))
        sys.stdout.flush()  # a closed pipe shows here, inside the handling below
        if held_stop() is not None and code in (EXIT_OK, EXIT_NEGATIVE):
            # A first Ctrl-C that came while the finished command saved its results
            # (``holding_stops``): everything was kept, and the stop is not swallowed.
            return interrupted("it came as the command saved its finished results; all "
                               "of them were kept")
        return code
    except (CliError, OutputError) as exc:
        print(f"error: {exc}", file=sys.stderr)
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
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.dup2(devnull, sys.stderr.fileno())
        return EXIT_NEGATIVE
    except OSError as exc:
        print(f"error: {exc.strerror or exc}"
              + (f": {exc.filename}" if exc.filename else ""), file=sys.stderr)
        return EXIT_BAD_INPUT
    except Exception as exc:  # a bug: one line, the traceback on demand
        if is_interrupt(exc):  # a Ctrl-C that numba reported as a SystemError
            return interrupted("nothing written")
        if os.environ.get("TFALDA_SIM_DEBUG"):
            raise
        print(f"internal error: {type(exc).__name__}: {exc} (set TFALDA_SIM_DEBUG=1 for the "
              "traceback and please report it)", file=sys.stderr)
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
