"""The ``tfalda-sim`` command line: assembles the domains' commands.

Each domain keeps its commands in its own ``command.py`` with one scheme: a
``register(subparsers)`` that adds them, and a ``cmd_<command>(args) -> int`` per command.
The shared option types, the output check and the exit codes live in
``tfalda_sim.cli_common``: 0 success, 1 the command ran but the result is negative (an
invalid track, laps not completed), 2 bad input, 130 stopped by Ctrl-C.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

from .agents import command as agents_command
from .cli_common import EXIT_BAD_INPUT, EXIT_NEGATIVE, EXIT_OK, CliError, interrupted
from .evaluation import command as evaluation_command
from .outputs import OutputError
from .rendering import command as rendering_command
from .replay import command as replay_command
from .tracks import command as tracks_command

COMMAND_MODULES = (tracks_command, rendering_command, evaluation_command, agents_command,
                   replay_command)
"""The domains' command modules, in the order ``tfalda-sim --help`` lists them."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="tfalda-sim", description="Carolo-Cup lane-keeping simulator (tfalda-sim).")
    sub = parser.add_subparsers(dest="command", required=True)
    for module in COMMAND_MODULES:
        module.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command and return its exit code (``tfalda_sim.cli_common``); a bad
    argument is reported with the usage and returns 2 (``--help`` returns 0)."""
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:  # argparse has printed the usage and the error
        return exc.code if isinstance(exc.code, int) else EXIT_BAD_INPUT
    try:
        return int(args.func(args))
    except (CliError, OutputError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except SystemExit as exc:  # a handler's parser.error(): usage and message printed
        return exc.code if isinstance(exc.code, int) else EXIT_BAD_INPUT
    except KeyboardInterrupt:
        # The long commands catch Ctrl-C themselves and keep what they finished; here
        # it struck before any result existed.
        return interrupted("stopped before any result was finished; nothing written")
    except BrokenPipeError:
        # stdout closed by its reader (`… | head`): the files are written, stop quietly.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_OK
    except OSError as exc:
        print(f"error: {exc.strerror or exc}"
              + (f": {exc.filename}" if exc.filename else ""), file=sys.stderr)
        return EXIT_BAD_INPUT
    except Exception as exc:  # a bug: one line, the traceback on demand
        if os.environ.get("TFALDA_SIM_DEBUG"):
            raise
        print(f"internal error: {type(exc).__name__}: {exc} (set TFALDA_SIM_DEBUG=1 for the "
              "traceback and please report it)", file=sys.stderr)
        return EXIT_NEGATIVE


if __name__ == "__main__":
    sys.exit(main())
