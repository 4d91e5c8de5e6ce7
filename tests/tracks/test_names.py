"""Track names: a file's name is short printable text, and every name a command prints is
escaped (a name reaches a terminal: it must not move the cursor or fake a line)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.cli_helpers import tfalda
from tfalda_sim.tracks import TrackFileError, load_named, load_track, printable
from tfalda_sim.tracks.command import _print_summary, track_summary
from tfalda_sim.tracks.fileformat import MAX_NAME_CHARS, track_to_dict

HOSTILE = "evil\x1b[2J\x1b[31m\r\nfake: wrote /etc/passwd"


def track_file(tmp_path: Path, name: str) -> Path:
    doc = track_to_dict(load_named("oval")) | {"name": name}
    path = tmp_path / "t.json"
    path.write_text(json.dumps(doc))
    return path


@pytest.mark.parametrize("name,says", [
    (HOSTILE, r"character 4 is '\x1b'"),
    ("tab\there", r"character 3 is '\t'"),
    ("n" * 100_000, f"at most {MAX_NAME_CHARS} characters, has 100000"),
    ("n" * (MAX_NAME_CHARS + 1), f"at most {MAX_NAME_CHARS} characters"),
])
def test_the_reader_refuses_a_long_or_unprintable_name(name: str, says: str,
                                                       tmp_path: Path) -> None:
    with pytest.raises(TrackFileError, match="name: ") as err:
        load_track(track_file(tmp_path, name))
    assert says in str(err.value) and len(str(err.value)) < 300


def test_a_name_of_printable_unicode_up_to_the_limit_is_read(tmp_path: Path) -> None:
    for name in ("Straße – große Kurve ⟳", "n" * MAX_NAME_CHARS, ""):
        assert load_track(track_file(tmp_path, name)).name == name


def test_validate_refuses_the_hostile_name_in_one_escaped_line(tmp_path: Path) -> None:
    track_file(tmp_path, HOSTILE)
    for argv in (["track", "validate", "t.json"], ["track", "validate", "t.json", "--json"]):
        run = tfalda(*argv, cwd=tmp_path, code=2)
        assert run.out == "" and len(run.err.splitlines()) == 1, run
        assert "\x1b" not in run.err and "\r" not in run.err, run
        assert "name" in run.err and "printable" in run.err


def test_validate_of_a_long_name_is_refused(tmp_path: Path) -> None:
    track_file(tmp_path, "n" * 100_000)
    run = tfalda("track", "validate", "t.json", cwd=tmp_path, code=2)
    assert len(run.err) < 300 and "at most" in run.err


def test_printable_escapes_control_characters_only() -> None:
    assert printable(HOSTILE) == r"evil\x1b[2J\x1b[31m\r\nfake: wrote /etc/passwd"
    assert printable("Straße ⟳ 'x'") == "Straße ⟳ 'x'"
    assert printable("a\u2028b\x7f") == r"a\u2028b\x7f"


def test_the_summary_prints_a_name_escaped(capsys: pytest.CaptureFixture[str]) -> None:
    """A track built in Python skips the reader; what a command prints is still escaped."""
    from dataclasses import replace

    track = replace(load_named("oval"), name=HOSTILE)
    _print_summary(track_summary(track, []))
    out = capsys.readouterr().out
    assert "\x1b" not in out and "\r" not in out
    assert out.splitlines()[0] == r"track        evil\x1b[2J\x1b[31m\r\nfake: wrote /etc/passwd"
