"""Track files: exact round trip, clear errors for corrupt files, no lost files."""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path

import pytest

from tests.conftest import generated
from tfalda_sim.tracks import NAMED_TRACKS, TrackFileError, load_named, load_track, save_track
from tfalda_sim.tracks.fileformat import track_to_dict


@pytest.mark.parametrize("track_id", [*NAMED_TRACKS, 3, 11, 25])
def test_round_trip_is_exact(tmp_path: Path, track_id: str | int) -> None:
    track = generated(track_id) if isinstance(track_id, int) else load_named(track_id)
    path = save_track(track, tmp_path / "t.json")
    again = load_track(path)
    assert again == track
    assert again.table.end == track.table.end  # floats survive bit for bit
    assert save_track(again, tmp_path / "u.json").read_text() == path.read_text()


def write(tmp_path: Path, doc: object) -> Path:
    path = tmp_path / "bad.json"
    path.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return path


def oval_doc() -> dict:
    return track_to_dict(load_named("oval"))


def test_bad_json_names_line_and_column(tmp_path: Path) -> None:
    with pytest.raises(TrackFileError, match=r"bad.json: not valid JSON \(line 1, column"):
        load_track(write(tmp_path, '{"format": "tfalda-sim/track",'))


def test_missing_field_is_named(tmp_path: Path) -> None:
    doc = oval_doc()
    del doc["segments"]
    with pytest.raises(TrackFileError, match="segments: missing required field"):
        load_track(write(tmp_path, doc))


def test_impossible_radius_names_field_and_rule(tmp_path: Path) -> None:
    doc = oval_doc()
    doc["segments"][1]["radius_m"] = 0.5
    with pytest.raises(TrackFileError) as err:
        load_track(write(tmp_path, doc))
    text = str(err.value)
    assert "segments[1].radius_m" in text and "rule min_radius" in text
    assert "rule closure" in text  # every violation is listed, not just the first
    # Without the rule check the file still parses (for `track validate`).
    assert load_track(tmp_path / "bad.json", check_rules=False).segments[1].radius_m == 0.5


@pytest.mark.parametrize(("mutate", "match"), [
    (lambda d: d.update(colour="red"), "unknown key.*'colour'"),
    (lambda d: d["segments"][0].update(lenght_m=2.0), r"segments\[0\]: unknown key.*'lenght_m'"),
    (lambda d: d["segments"][0].update(type="spiral"), r"segments\[0\].type: must be one of"),
    (lambda d: d["segments"][0].update(length_m="2"), r"segments\[0\].length_m: must be a number"),
    (lambda d: d["segments"][0].update(length_m=-2.0), r"segments\[0\].length_m: must be > 0"),
    (lambda d: d.update(format="gpx"), "format: must be 'tfalda-sim/track'"),
    (lambda d: d.update(version=7), "version 7 is not supported"),
    (lambda d: d.update(closed="yes"), "closed: must be true or false"),
    (lambda d: d["start"].pop("x_m"), "start.x_m: missing required field"),
    (lambda d: d.update(gaps=[{"line": "middle", "s_m": 1.0, "length_m": 0.5}]),
     r"gaps\[0\].line: must be one of left, centre, right"),
    (lambda d: d.update(seed=-3), "seed: must be a non-negative integer"),
    (lambda d: d.update(segments=[]), "segments: needs at least one segment"),
])
def test_corrupt_documents_give_clear_errors(tmp_path: Path, mutate, match: str) -> None:
    doc = oval_doc()
    mutate(doc)
    with pytest.raises(TrackFileError, match=match):
        load_track(write(tmp_path, doc))


def test_top_level_not_an_object(tmp_path: Path) -> None:
    with pytest.raises(TrackFileError, match=r"\(top level\): must be an object"):
        load_track(write(tmp_path, "[1, 2]"))


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(TrackFileError, match="no such file"):
        load_track(tmp_path / "nope.json")


def test_save_never_overwrites_unless_asked(tmp_path: Path) -> None:
    target = tmp_path / "mine.json"
    target.write_text("my precious data")
    with pytest.raises(FileExistsError, match="overwrite=True"):
        save_track(load_named("oval"), target)
    assert target.read_text() == "my precious data"
    save_track(load_named("oval"), target, overwrite=True)
    assert load_track(target) == load_named("oval")
    assert [p.name for p in tmp_path.iterdir()] == ["mine.json"]  # no temp file left


def test_saved_file_has_the_umask_permissions(tmp_path: Path) -> None:
    umask = os.umask(0o022)
    try:
        path = save_track(load_named("straight"), tmp_path / "t.json")
    finally:
        os.umask(umask)
    assert stat.S_IMODE(path.stat().st_mode) == 0o644
