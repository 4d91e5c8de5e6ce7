"""Check the import contracts of pyproject.toml ([tool.importlinter]) with import-linter.

    python tools/lint_imports.py          # part of `make test`

import-linter (grimp) finds a package's modules by walking its folder. The repository
keeps tfalda_sim.tracks, .envs and .agents in root folders of their own (setuptools'
``package-dir``), which the editable install maps with an import hook, not a folder:
grimp would not see them. So the check runs on a tree of the installed layout
(``tfalda_sim/`` with ``tracks``, ``envs``, ``agents`` inside it), built in a temporary
folder and put first on ``sys.path`` (a copy of the .py files: grimp does not follow
symbolic links).
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MAPPED = {"tracks": "tracks", "envs": "envs", "agents": "agents"}
"""Subpackage of tfalda_sim → its folder at the repository root (pyproject package-dir)."""


def layout_tree(into: Path) -> Path:
    """``into/tfalda_sim``: a copy of the Python files of ``tfalda_sim/`` with the mapped
    folders in place — the installed layout (copies: grimp does not follow links)."""
    keep = shutil.ignore_patterns("__pycache__", "*.nbi", "*.nbc", "data", "policies")
    pkg = into / "tfalda_sim"
    shutil.copytree(ROOT / "tfalda_sim", pkg, ignore=keep)
    for name, folder in MAPPED.items():
        shutil.copytree(ROOT / folder, pkg / name, ignore=keep)
    return pkg


def check(tree: Path) -> int:
    """Run the contracts on the package tree under ``tree``; the exit code (0: all kept)."""
    from importlinter.cli import lint_imports

    sys.path.insert(0, str(tree))
    # import-linter puts the working folder first on sys.path: the repository root
    # would win over the tree (its tfalda_sim/ lacks the mapped subpackages).
    os.chdir(tree)
    return lint_imports(config_filename=str(ROOT / "pyproject.toml"), no_cache=True,
                        no_logo=True)


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if args:  # a tree made by layout_tree (the tests break an import in one)
        return check(Path(args[0]))
    with tempfile.TemporaryDirectory(prefix="tfalda-sim-imports-") as tmp:
        layout_tree(Path(tmp))
        return check(Path(tmp))


if __name__ == "__main__":
    sys.exit(main())
