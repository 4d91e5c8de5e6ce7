"""One track argument for every command — a named track, a seed (a generated track) or a
track file — and one label for it in every output (a seed's track is ``seed-7``, the name
the generator gives it)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.cli_helpers import tfalda
from tfalda_sim.tracks import generate, load_named, seed_name
from tfalda_sim.tracks.command import resolve_track_arg, track_arg_label, track_file_arg
from tfalda_sim.tracks.fileformat import track_to_dict


def test_a_seed_is_named_seed_dash_n() -> None:
    assert seed_name(7) == "seed-7" == generate(7).name


@pytest.mark.parametrize("text, label", [("7", "seed-7"), ("007", "seed-7"),
                                         ("oval", "oval"), ("dir/my.json", "my.json")])
def test_the_label_of_a_track_argument(text: str, label: str) -> None:
    assert track_arg_label(text) == label


def test_the_label_of_a_file_is_escaped() -> None:
    assert track_arg_label("a\x1b[2J\r.json") == r"a\x1b[2J\r.json"


def test_validate_takes_a_seed_as_every_command_does(tmp_path: Path) -> None:
    doc = tfalda("track", "validate", "7", "--json", cwd=tmp_path).json()
    assert doc["name"] == "seed-7" and doc["seed"] == 7 and doc["valid"] is True
    assert doc["file"] is None
    text = tfalda("track", "validate", "7", cwd=tmp_path).out
    assert text.splitlines()[0] == "track        seed-7 (seed 7)"


def test_validate_and_render_read_the_same_arguments(tmp_path: Path) -> None:
    doc = track_to_dict(load_named("oval")) | {"name": "mine"}
    (tmp_path / "mine.json").write_text(json.dumps(doc))
    (tmp_path / "mine.track").write_text(json.dumps(doc))  # any suffix: it is a file
    for arg, label in (("oval", "oval"), ("3", "seed-3"), ("mine.json", "mine.json"),
                       ("mine.track", "mine.track")):
        assert tfalda("track", "validate", arg, "--json", cwd=tmp_path).json()["valid"]
        rendered = tfalda("render", "--track", arg, "--s", "1", "--out", "f.png", "--force",
                          "--json", cwd=tmp_path).json()
        assert rendered["track"] == label
        text = tfalda("render", "--track", arg, "--s", "1", "--out", "f.png", "--force",
                      cwd=tmp_path).out
        assert text.startswith(f"rendered {label} at s = 1.00 m")


@pytest.mark.parametrize("argv", [["track", "validate", "ovl"],
                                  ["render", "--track", "ovl", "--s", "1", "--out", "f.png"]])
def test_an_argument_that_is_none_of_them_is_one_error_listing_them(argv: list[str],
                                                                    tmp_path: Path) -> None:
    run = tfalda(*argv, cwd=tmp_path, code=2)
    assert "'ovl' is neither a named track (straight, " in run.err
    assert "a seed (a non-negative integer) nor a track file (.json)" in run.err
    assert len(run.err.strip().splitlines()) == 1


def test_a_missing_json_file_is_named_as_such(tmp_path: Path) -> None:
    run = tfalda("track", "validate", "gone.json", cwd=tmp_path, code=2)
    assert "gone.json: no such file" in run.err


def test_track_file_arg_names_every_file_argument() -> None:
    assert track_file_arg("7") is None and track_file_arg("oval") is None
    assert track_file_arg("x.json") == Path("x.json")
    assert track_file_arg("x.track") == Path("x.track")


def test_resolve_track_arg_keeps_violations_for_validate(tmp_path: Path) -> None:
    doc = track_to_dict(load_named("oval"))
    doc["segments"][1]["radius_m"] = 0.9
    (tmp_path / "bad.json").write_text(json.dumps(doc))
    track = resolve_track_arg(str(tmp_path / "bad.json"), check_rules=False)
    assert track.segments[1].radius_m == 0.9
