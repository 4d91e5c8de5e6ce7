"""The documents a newcomer reads: a short README whose quick start comes first and whose
Python snippets run as written, a changelog, and no work diary in the project's files."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"

README_MAX_BYTES = 25_000
QUICK_START_WITHIN_LINES = 120


def _python_blocks(text: str) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", text, flags=re.S | re.M)


def test_readme_is_short_with_the_quick_start_in_its_first_lines() -> None:
    text = README.read_text()
    assert len(text.encode()) <= README_MAX_BYTES
    lines = text.splitlines()
    quick = [i for i, line in enumerate(lines) if line.startswith("## Quick start")]
    assert quick and quick[0] < QUICK_START_WITHIN_LINES
    assert "gymnasium.make(" in text and "gymnasium.make_vec(" in text
    # The set-up is the two commands, and the quick start follows it.
    setup = text.index("## Set-up")
    assert setup < text.index("## Quick start")
    assert "make demo" in text[setup:] and "make test" in text[setup:]


@pytest.mark.parametrize("index", range(len(_python_blocks(README.read_text()))))
def test_every_readme_python_snippet_runs_as_written(index: int, tmp_path: Path) -> None:
    """Each snippet alone, as a user pastes it into a file (no main guard) and runs it."""
    code = _python_blocks(README.read_text())[index]
    script = tmp_path / "snippet.py"
    script.write_text(code)
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          timeout=600, cwd=tmp_path)
    assert done.returncode == 0, f"README snippet {index}:\n{code}\n{done.stderr[-3000:]}"


def _command_lines() -> list[tuple[str, str]]:
    """Every ``tfalda-sim …`` line of the README's and docs' shell blocks (a ``$`` prompt,
    a trailing comment and backslash continuations taken off), with its file."""
    out = []
    for path in [README, *sorted((ROOT / "docs").glob("*.md"))]:
        for block in re.findall(r"^```(?:sh|console|bash)\n(.*?)^```", path.read_text(),
                                flags=re.S | re.M):
            text = block.replace("\\\n", " ")
            for line in text.splitlines():
                line = line.removeprefix("$ ").strip()
                # a synopsis ([optional], a|b, …) or a shell loop's $var is not a command
                if line.startswith("tfalda-sim ") and not re.search(r"[\[|<…$]|\.\.\.", line):
                    out.append((path.name, line))
    return out


@pytest.mark.parametrize("where, line", _command_lines())
def test_every_documented_command_line_parses(where: str, line: str) -> None:
    """Options renamed or dropped show here, not in a user's terminal."""
    import shlex

    from tfalda_sim.cli import build_parser

    argv = shlex.split(line, comments=True)[1:]
    try:
        build_parser().parse_args(argv)
    except SystemExit as exc:
        pytest.fail(f"{where}: `{line}` does not parse (exit {exc.code})")


def test_changelog_keeps_a_changelog_form() -> None:
    text = (ROOT / "CHANGELOG.md").read_text()
    assert text.startswith("# Changelog")
    assert "## [Unreleased]" in text
    assert re.search(r"^## \[\d+\.\d+\.\d+\] - \d{4}-\d{2}-\d{2}$", text, flags=re.M)


_DIARY = re.compile(
    r"\b(first|second|third|fourth|fifth|sixth|seventh|eighth|ninth|tenth|eleventh|"
    r"twelfth|thirteenth|fourteenth|fifteenth|sixteenth|seventeenth|eighteenth|nineteenth|"
    r"twentieth|twenty-[a-z]+) session|\bthis session\b|\bwork sessions?\b|\bissue \d+",
    flags=re.I)


def test_no_work_diary_in_the_projects_files() -> None:
    """No work sessions or internal issue numbers in code, docs or comments (history is
    git's and CHANGELOG.md's)."""
    files = subprocess.run(["git", "ls-files"], capture_output=True, text=True, cwd=ROOT,
                           check=False).stdout.split()
    if not files:
        pytest.skip("not a git checkout")
    offenders = []
    for name in files:
        path = ROOT / name
        if path.suffix not in (".py", ".md", ".toml", ".cfg", ".txt", ".yaml", "") or (
                not path.is_file()) or path == Path(__file__):
            continue
        for number, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
            if _DIARY.search(line):
                offenders.append(f"{name}:{number}: {line.strip()[:100]}")
    assert not offenders, "\n".join(offenders)
