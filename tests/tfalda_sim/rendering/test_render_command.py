"""``tfalda-sim render``: where the car may stand (through the installed console script)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.cli_helpers import tfalda

BAD_PLACES = [
    # (option, value, track, what the one-line error says)
    ("--lateral", "1e300", "oval", "--lateral 1e+300 m is off the road"),
    ("--lateral", "-0.5", "oval", "--lateral -0.5 m is off the road"),
    ("--s", "1e300", "oval", "--s 1e+300 m is more than a lap"),
    ("--s", "-30", "oval", "--s -30 m is more than a lap"),
    ("--s", "11", "straight", "--s 11 m is off the open track"),
    ("--heading", "1e300", "oval", "--heading 1e+300 rad"),
    ("--heading", "-3.2", "oval", "--heading -3.2 rad"),
]


@pytest.mark.parametrize("option,value,track,message", BAD_PLACES)
def test_render_refuses_a_place_off_the_track_in_one_line(option: str, value: str, track: str,
                                                          message: str, tmp_path: Path) -> None:
    argv = {"--s": "1", "--lateral": "-0.2", "--heading": "0"} | {option: value}
    run = tfalda("render", "--track", track, "--out", "f.png",
                 *[a for kv in argv.items() for a in kv], cwd=tmp_path, code=2)
    lines = run.err.strip().splitlines()
    assert len(lines) == 1 and message in lines[0] and "use " in lines[0], run
    assert len(lines[0]) < 200 and run.out == "" and not (tmp_path / "f.png").exists()


def test_render_accepts_the_bounds_themselves(tmp_path: Path) -> None:
    """A closed track wraps: a lap back is the start line; the road's edge and a half turn
    are still places to render from."""
    doc = tfalda("render", "--track", "oval", "--s", "-1", "--lateral", "0.4",
                 "--heading", "-3.14159", "--out", "f.png", "--json", cwd=tmp_path).json()
    assert doc["s_m"] == -1 and (tmp_path / "f.png").stat().st_size > 0
