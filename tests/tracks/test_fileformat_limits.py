"""Hostile track files: every limit is checked before anything
proportional to the size is allocated, and refused with an error that names the file,
the field and the limit; never a traceback, never gigabytes, never minutes."""

from __future__ import annotations

import json
import math
import resource
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from tests.conftest import generated
from tfalda_sim.cli import main
from tfalda_sim.tracks import (
    NAMED_TRACKS,
    TrackFileError,
    load_named,
    load_track,
    rasterize,
    validate,
)
from tfalda_sim.tracks.fileformat import (
    MAX_FILE_BYTES,
    MAX_GAPS,
    MAX_INTERSECTIONS,
    MAX_JSON_DEPTH,
    MAX_OBSTACLES,
    MAX_SEGMENTS,
    save_track,
)
from tfalda_sim.tracks.model import MAX_LANE_WIDTH_M, MAX_TRACK_LENGTH_M, Arc, Straight, Track

GiB = 1024**3


@contextmanager
def address_space_cap(extra_bytes: int = GiB) -> Iterator[None]:
    """Let the process grow by at most ``extra_bytes``: a regression to the old
    behaviour (8–19 GB for a 1e7 m straight) fails with MemoryError at once instead of
    swapping the machine to death."""
    if not sys.platform.startswith("linux"):
        yield
        return
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    pages = int(Path("/proc/self/statm").read_text().split()[0])
    cap = pages * resource.getpagesize() + extra_bytes
    if hard != resource.RLIM_INFINITY:
        cap = min(cap, hard)
    resource.setrlimit(resource.RLIMIT_AS, (cap, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def strip_doc(length_m: Any = 2.0) -> dict[str, Any]:
    """The smallest valid document: an open straight strip."""
    return {"format": "tfalda-sim/track", "version": 1, "closed": False, "lane_width_m": 0.4,
            "start": {"x_m": 0.0, "y_m": 0.0, "heading_rad": 0.0}, "start_line_s_m": None,
            "segments": [{"type": "straight", "length_m": length_m}]}


def write(path: Path, doc: object) -> Path:
    if isinstance(doc, bytes):
        path.write_bytes(doc)
    else:
        path.write_text(doc if isinstance(doc, str) else json.dumps(doc), encoding="utf-8")
    return path


def refused(path: Path, match: str, *, seconds: float = 2.0) -> str:
    """``load_track`` refuses ``path`` quickly, within a 1 GiB growth cap; the message."""
    start = time.perf_counter()
    with address_space_cap(), pytest.raises(TrackFileError, match=match) as err:
        load_track(path)
    assert time.perf_counter() - start < seconds
    return str(err.value)


def cli_error(path: Path, capsys: pytest.CaptureFixture[str]) -> str:
    """``tfalda-sim track validate path``: exit 2 and one ``error: …`` line, no traceback."""
    with address_space_cap():
        assert main(["track", "validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "Traceback" not in err and "internal error" not in err
    return err


# ------------------------------------------------------------ the reproductions


def test_a_1e7_m_straight_is_refused_before_anything_is_laid_out(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = write(tmp_path / "t.json", strip_doc(1e7))
    expected = (f"{path}: segments[0].length_m: 1e+07 m exceeds the largest track length "
                "250 m (tfalda_sim.tracks.model.MAX_TRACK_LENGTH_M)")
    assert refused(path, "largest track length") == expected
    assert cli_error(path, capsys) == f"error: {expected}\n"


def test_a_1e300_m_straight_is_refused(tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    path = write(tmp_path / "t.json", strip_doc(1e300))
    refused(path, r"segments\[0\].length_m: 1e\+300 m exceeds the largest track length")
    assert "MAX_TRACK_LENGTH_M" in cli_error(path, capsys)


@pytest.mark.parametrize("field", ["length_m", "x_m", "version", "seed", "lane_width_m"])
def test_integers_beyond_the_float_range_are_refused(tmp_path: Path, field: str) -> None:
    doc = strip_doc()
    big = 10**400
    if field == "length_m":
        doc["segments"][0]["length_m"] = big
    elif field == "x_m":
        doc["start"]["x_m"] = -big
    else:
        doc[field] = big
    where = {"length_m": r"segments\[0\].length_m", "x_m": "start.x_m"}.get(field, field)
    # 10**400 has 401 digits; the seed (an integer field) is refused as well, by its rule.
    refused(write(tmp_path / "t.json", doc), f"{where}: .*an integer of 401 digits")


def test_integers_longer_than_python_converts_are_refused(tmp_path: Path) -> None:
    # json.loads itself raises a bare ValueError beyond 4300 digits.
    text = json.dumps(strip_doc()).replace("2.0", "9" * 5000)
    refused(write(tmp_path / "t.json", text), r"length_m: .*an integer of 5000 digits")


def test_100000_nested_brackets_are_refused(tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    path = write(tmp_path / "t.json", "[" * 100_000)
    refused(path, r"t.json: nested too deeply \(100000 levels.*MAX_JSON_DEPTH")
    assert "nested too deeply" in cli_error(path, capsys)


def test_200000_tiny_segments_are_refused_quickly(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    doc = strip_doc()
    doc["segments"] = [{"type": "straight", "length_m": 0.001}] * 200_000
    path = write(tmp_path / "t.json", doc)
    refused(path, "larger than the largest track file .*MAX_FILE_BYTES")
    assert "MAX_FILE_BYTES" in cli_error(path, capsys)


# ------------------------------------------------------------------- each limit alone


@pytest.mark.parametrize(("key", "limit", "name"), [
    ("segments", MAX_SEGMENTS, "MAX_SEGMENTS"),
    ("gaps", MAX_GAPS, "MAX_GAPS"),
    ("obstacles", MAX_OBSTACLES, "MAX_OBSTACLES"),
    ("intersections", MAX_INTERSECTIONS, "MAX_INTERSECTIONS"),
])
def test_list_lengths_are_checked_before_the_first_element(
        tmp_path: Path, key: str, limit: int, name: str) -> None:
    doc = strip_doc()
    doc[key] = [0] * (limit + 1)  # not even objects: the count is refused first
    refused(write(tmp_path / "t.json", doc),
            rf"{key}: {limit + 1} entries exceed the largest number of {key} {limit} "
            rf"\(tfalda_sim.tracks.fileformat.{name}\)")
    doc[key] = [0] * limit  # at the limit, the elements themselves are read
    refused(write(tmp_path / "t.json", doc), rf"{key}\[0\]: must be an object")


def test_segments_adding_up_beyond_the_longest_track_are_refused(tmp_path: Path) -> None:
    doc = strip_doc()
    doc["segments"] = [{"type": "straight", "length_m": 200.0},
                       {"type": "arc", "radius_m": 20.0, "angle_rad": 3.0}]
    refused(write(tmp_path / "t.json", doc),
            r"segments\[1\]: the segments up to here add up to 260 m, more than the largest "
            r"track length 250 m")


def test_a_file_at_the_length_limit_still_loads(tmp_path: Path) -> None:
    doc = strip_doc(MAX_TRACK_LENGTH_M)
    track = load_track(write(tmp_path / "t.json", doc))
    assert track.length_m == MAX_TRACK_LENGTH_M


def test_a_file_at_the_segment_limit_validates_within_seconds(tmp_path: Path) -> None:
    """The rule check's cost is samples × segments: the longest track with the most
    segments, each segment a circle stacked on the others, so every sample is close to
    every segment (the most hostile case; ≈ 3.5 s on a 2-core VM)."""
    radius = 0.999 * MAX_TRACK_LENGTH_M / (2 * math.pi * MAX_SEGMENTS)
    doc = strip_doc()
    doc.update(closed=True, start_line_s_m=0.0,
               segments=[{"type": "arc", "radius_m": radius, "angle_rad": 2 * math.pi}]
               * MAX_SEGMENTS)
    path = write(tmp_path / "t.json", doc)
    validate(load_named("figure-eight"))  # numba's compiled kernels loaded before timing
    start = time.perf_counter()
    with address_space_cap():
        violations = validate(load_track(path, check_rules=False))
    assert time.perf_counter() - start < 15.0  # generous for a loaded CI machine
    assert {v.rule for v in violations} == {"overlap", "min_radius"}


def test_huge_files_are_not_read(tmp_path: Path) -> None:
    path = tmp_path / "t.json"
    with path.open("wb") as fh:
        fh.truncate(10 * GiB)  # sparse: no disk used; reading it would need 10 GiB
    refused(path, rf"t.json: file is larger than the largest track file {MAX_FILE_BYTES} bytes")
    path.write_text(json.dumps(strip_doc()) + " " * (MAX_FILE_BYTES - 300))
    assert load_track(path).length_m == 2.0  # just below the limit: read as usual


def test_nesting_up_to_the_limit_is_not_refused_for_depth(tmp_path: Path) -> None:
    doc = strip_doc()
    deep = "[" * (MAX_JSON_DEPTH - 1) + "]" * (MAX_JSON_DEPTH - 1)  # + the top object
    text = json.dumps(doc).replace('"start_line_s_m": null', f'"start_line_s_m": {deep}')
    refused(write(tmp_path / "t.json", text), "start_line_s_m: must be a number, got a list")
    deeper = "[" * MAX_JSON_DEPTH + "]" * MAX_JSON_DEPTH
    text = json.dumps(doc).replace('"start_line_s_m": null', f'"start_line_s_m": {deeper}')
    refused(write(tmp_path / "t.json", text), "nested too deeply")
    # Brackets inside strings are text, not nesting.
    doc["description"] = "[" * 1000
    assert load_track(write(tmp_path / "t.json", doc)).description == "[" * 1000


@pytest.mark.parametrize(("mutate", "match"), [
    (lambda d: d["segments"][0].update(length_m=float("nan")), r"length_m: must be finite"),
    (lambda d: d["start"].update(y_m=float("inf")), r"start.y_m: must be finite"),
    (lambda d: d["segments"][0].update(length_m=True), r"length_m: must be a number, got true"),
    (lambda d: d.update(lane_width_m=False), r"lane_width_m: must be a number, got false"),
    (lambda d: d.update(lane_width_m=3.0),
     r"lane_width_m: 3 m exceeds the widest lane 1 m \(tfalda_sim.tracks.model.MAX_LANE_WIDTH_M\)"),
    (lambda d: d["start"].update(x_m=-5000.0),
     r"start.x_m: \|-5000\| m exceeds the largest mat extent 1000 m "
     r"\(tfalda_sim.tracks.fileformat.MAX_MAT_EXTENT_M\)"),
    (lambda d: d["start"].update(heading_rad=1e9),
     r"start.heading_rad: 1e\+09 rad exceeds the largest heading 100 rad"),
    (lambda d: d.update(segments=[{"type": "arc", "radius_m": 1e-310, "angle_rad": 1.0}]),
     r"segments\[0\].radius_m: 1e-310 m is below the smallest arc radius 0.001 m"),
    (lambda d: d.update(segments=[{"type": "arc", "radius_m": 1e300, "angle_rad": 1e-300}]),
     r"segments\[0\].radius_m: 1e\+300 m exceeds the largest mat extent"),
    (lambda d: d.update(obstacles=[{"s_m": 1.0, "lane": "right", "length_m": 0.2,
                                    "width_m": 1e200, "height_m": 0.1}]),
     r"obstacles\[0\].width_m: 1e\+200 m exceeds the largest mat extent"),
    (lambda d: d.update(gaps=[{"line": "left", "s_m": -1e12, "length_m": 0.5}]),
     r"gaps\[0\].s_m: \|-1e\+12\| m exceeds the largest mat extent"),
    # Found by the fuzz suite: a negative gap used to crash the rule check (KeyError).
    (lambda d: d.update(gaps=[{"line": "right", "s_m": 1.0, "length_m": -1.0}]),
     r"gaps\[0\].length_m: must be ≥ 0, got -1"),
])
def test_magnitudes_and_types(tmp_path: Path, mutate, match: str) -> None:
    doc = strip_doc()
    mutate(doc)
    refused(write(tmp_path / "t.json", doc), match)


def test_json_number_text_beyond_the_float_range(tmp_path: Path) -> None:
    text = json.dumps(strip_doc()).replace("2.0", "1e400")
    refused(write(tmp_path / "t.json", text), r"length_m: must be finite")


def test_non_utf8_bytes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    raw = json.dumps(strip_doc()).encode().replace(b'"closed"', b'"clos\xff\xfeed"')
    path = write(tmp_path / "t.json", raw)
    refused(path, r"t.json: not UTF-8 text \(byte 0xff at offset \d+\)")
    assert "not UTF-8" in cli_error(path, capsys)


def test_lone_surrogates_in_text_are_refused(tmp_path: Path) -> None:
    # Valid JSON, but the name could never be printed or written as UTF-8.
    text = json.dumps(strip_doc() | {"name": "a\ud800b"})
    assert "\\ud800" in text
    refused(write(tmp_path / "t.json", text), r"name: must be Unicode text, has a lone surrogate")


def test_duplicate_keys_are_refused(tmp_path: Path) -> None:
    text = json.dumps(strip_doc()).replace('"closed": false', '"closed": false, "closed": true')
    refused(write(tmp_path / "t.json", text), r"\(top level\): duplicate key\(s\) 'closed'")
    text = json.dumps(strip_doc()).replace('"length_m": 2.0', '"length_m": 2.0, "length_m": 9')
    refused(write(tmp_path / "t.json", text), r"segments\[0\]: duplicate key\(s\) 'length_m'")


def test_error_messages_stay_short(tmp_path: Path) -> None:
    doc = strip_doc()
    doc.update({f"k{i}": 0 for i in range(50_000)})
    message = refused(write(tmp_path / "t.json", doc), r"unknown key\(s\) 'k0', .*50000 in all")
    assert len(message) < 400
    doc = strip_doc("x" * 100_000)
    assert len(refused(write(tmp_path / "t.json", doc), "must be a number")) < 200


# ------------------------------------------------------------------ the in-memory path


def test_an_in_memory_track_beyond_the_longest_is_refused_by_validate_and_rasterize() -> None:
    # Refused as the Track is built, before validate / rasterize lay out samples or pixels.
    for check in (validate, rasterize):
        with address_space_cap(), pytest.raises(
                ValueError, match=r"track too large: .* 1e\+07 m, more than the largest track "
                                  r"length 250 m \(tfalda_sim.tracks.model.MAX_TRACK_LENGTH_M\)"):
            check(Track((Straight(1e7),), closed=False))
    with pytest.raises(ValueError, match="MAX_TRACK_LENGTH_M"):
        Track((Straight(200.0), Arc(20.0, 3.0)), closed=False)


def test_an_in_memory_track_with_an_absurd_lane_width_is_refused() -> None:
    with address_space_cap(), pytest.raises(ValueError, match="MAX_LANE_WIDTH_M"):
        validate(Track((Straight(2.0),), closed=False, lane_width_m=50.0))
    Track((Straight(2.0),), closed=False, lane_width_m=MAX_LANE_WIDTH_M)  # the limit itself


# --------------------------------------- real tracks stay far within every limit


@pytest.mark.parametrize("track_id", [*NAMED_TRACKS, *range(0, 1000, 50)])
def test_real_tracks_are_far_within_the_limits(tmp_path: Path, track_id: str | int) -> None:
    track = generated(track_id) if isinstance(track_id, int) else load_named(track_id)
    assert track.length_m < MAX_TRACK_LENGTH_M / 4
    assert len(track.segments) < MAX_SEGMENTS / 3
    assert len(track.gaps) < MAX_GAPS / 10 and len(track.obstacles) < MAX_OBSTACLES / 10
    assert len(track.intersections) < MAX_INTERSECTIONS
    xmin, ymin, xmax, ymax = track.bounds(0.3)
    assert max(abs(xmin), abs(ymin), abs(xmax), abs(ymax)) < 1000 / 20
    path = save_track(track, tmp_path / "t.json")
    assert path.stat().st_size < MAX_FILE_BYTES / 50
    assert load_track(path) == track


def test_a_document_at_every_count_limit_fits_the_file_size_limit(tmp_path: Path) -> None:
    doc = strip_doc()
    doc.update(segments=[{"type": "arc", "radius_m": 1.4142135623730951,
                          "angle_rad": -0.0012345678901234567}] * MAX_SEGMENTS,
               gaps=[{"line": "centre", "s_m": 123.45678901234567,
                      "length_m": 0.12345678901234567}] * MAX_GAPS,
               obstacles=[{"s_m": 123.45678901234567, "lane": "right",
                           "offset_m": -0.012345678901234567, "length_m": 0.12345678901234567,
                           "width_m": 0.12345678901234567, "height_m": 0.12345678901234567}]
               * MAX_OBSTACLES,
               intersections=[{"s1_m": 123.45678901234567, "s2_m": 123.45678901234567}]
               * MAX_INTERSECTIONS,
               name="n" * 100, description="d" * 10_000)
    assert len(json.dumps(doc, indent=2)) < MAX_FILE_BYTES / 4


def test_a_track_of_vanishing_segments_is_refused(tmp_path) -> None:
    """100 straights of 1e-300 m validated as a closed track of 1e-298 m."""
    import json

    from tfalda_sim.tracks.fileformat import TrackFileError, load_track

    doc = {"format": "tfalda-sim/track", "version": 1, "name": "dot", "closed": False,
           "lane_width_m": 0.4, "start": {"x_m": 0, "y_m": 0, "heading_rad": 0},
           "start_line_s_m": None,
           "segments": [{"type": "straight", "length_m": 1e-300}] * 100}
    path = tmp_path / "dot.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(TrackFileError, match="MIN_SEGMENT_LENGTH_M"):
        load_track(path, check_rules=False)
