"""What the command-line tests share: the parser's commands, walked from ``build_parser``
(so a new subcommand or option is picked up by the tests without editing them)."""

from __future__ import annotations

import argparse

from tfalda_sim.cli import build_parser


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """The subcommands of ``parser`` by name (empty for a leaf command)."""
    out: dict[str, argparse.ArgumentParser] = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            out.update(action.choices)
    return out


def command_tree() -> dict[tuple[str, ...], argparse.ArgumentParser]:
    """Every command of ``tfalda-sim`` by its path, groups included: ``()`` is the top
    level, ``("track",)`` the group, ``("track", "list")`` a leaf."""
    tree: dict[tuple[str, ...], argparse.ArgumentParser] = {}
    stack: list[tuple[tuple[str, ...], argparse.ArgumentParser]] = [((), build_parser())]
    while stack:
        path, parser = stack.pop()
        tree[path] = parser
        stack.extend(((*path, name), sub) for name, sub in _subcommands(parser).items())
    return dict(sorted(tree.items()))


def leaf_commands() -> dict[tuple[str, ...], argparse.ArgumentParser]:
    """The commands that do something (``track list``, ``render``, …) by path."""
    return {path: p for path, p in command_tree().items() if path and not _subcommands(p)}
