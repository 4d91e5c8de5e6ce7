"""Property-based fuzzing of track files.

Property: ``load_track(path)`` returns a ``Track`` or raises ``TrackFileError`` — never
another exception — and each file is answered quickly. Inputs start from valid track
documents and are mutated in structure (deleted, unknown, duplicated and repeated keys
and elements, deep nesting), types and magnitudes (huge / tiny / NaN / infinite numbers,
also as JSON text no ``json.dumps`` writes, integers of thousands of digits, bools as
numbers), then at byte level (truncation, random bytes, not UTF-8).

Reproducible: ``derandomize=True`` and no example database, so CI sees the same inputs.
"""

from __future__ import annotations

import copy
import json
import math
from collections.abc import Iterator
from datetime import timedelta
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from tests.conftest import generated
from tests.tracks.test_fileformat_limits import address_space_cap
from tfalda_sim.tracks import (
    NAMED_TRACKS,
    Track,
    TrackFileError,
    load_named,
    load_track,
    save_track,
)
from tfalda_sim.tracks.fileformat import MAX_SEGMENTS, track_to_dict
from tfalda_sim.tracks.model import MAX_TRACK_LENGTH_M

FUZZ = settings(
    derandomize=True,
    database=None,
    deadline=timedelta(seconds=5),  # the most hostile file within the limits: ≈ 2 s
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)

# Valid documents to mutate: every named track (one with an intersection) and a generated
# one with gaps and obstacles.
BASES: list[dict[str, Any]] = [track_to_dict(load_named(n)) for n in NAMED_TRACKS]
BASES.append(track_to_dict(generated(3)))
assert any(b["gaps"] and b["obstacles"] for b in BASES)
assert any(b["intersections"] for b in BASES)

# Number texts json.dumps never writes, spliced into the document text.
RAW_NUMBERS = ["1e400", "-1e400", "1e-400", "-0", "1E+308", "0.0e-99999", "1" + "0" * 400,
               "9" * 5000, "-" + "9" * 5000, "123456789012345678901234567890", "-5e-324",
               "1" * 500 + ".5"]
RAW_TEXTS = [*RAW_NUMBERS, "NaN", "-Infinity", "[" * 17 + "]" * 17, '"\\ud800"', '"\\u0000"']

HOSTILE_VALUES: st.SearchStrategy[Any] = st.one_of(
    st.none(), st.booleans(),
    st.integers(), st.sampled_from([0, -1, 1, 2**53 + 1, 2**64, 10**30, -(10**400), 10**400]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([1e7, 1e300, -1e300, 5e-324, 1e-310, 1e-7, 250.0, 250.0000001, 1000.5,
                     math.pi, 2 * math.pi + 1e-9, 0.4, 1.0, 1.5]),
    st.text(max_size=12),
    st.sampled_from(["straight", "arc", "left", "centre", "right", "tfalda-sim/track"]),
    st.lists(st.integers(), max_size=3),
    st.dictionaries(st.text(max_size=5), st.integers(), max_size=2),
)

# Numbers of the right type but any magnitude: these pass the type checks and reach the
# limits and the rule check.
MAGNITUDES: st.SearchStrategy[float | int] = st.one_of(
    st.floats(0.0, 3.0), st.floats(0.0, 30.0), st.floats(0.0, 300.0),  # mostly plausible
    st.floats(-3.0, 0.0), st.integers(-(10**6), 10**6),
    st.sampled_from([0.0, -0.0, 1e-300, 5e-324, 1e-3, 0.35, 0.45, 1.42, 2 * math.pi,
                     -2 * math.pi, 249.99, 250.0, 999.0, 1000.0, 1e7, 1e300, 10**400]),
    st.floats(1e-12, 1e12), st.floats(allow_nan=True, allow_infinity=True),
)


@pytest.fixture(scope="module")
def workdir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    # Module scope: @given cannot use function-scoped fixtures such as tmp_path.
    load_track(save_track(load_named("figure-eight"), tmp_path_factory.mktemp("warm") / "w.json"))
    return tmp_path_factory.mktemp("fuzz")  # numba kernels loaded above, not on the clock


def slots(node: Any) -> Iterator[tuple[Any, Any]]:
    """Every ``(container, key or index)`` in a JSON tree, the top level included."""
    if isinstance(node, dict):
        for key in list(node):
            yield node, key
            yield from slots(node[key])
    elif isinstance(node, list):
        for i in range(len(node)):
            yield node, i
            yield from slots(node[i])


ALL_OPS = ("magnitude", "magnitude", "value", "value", "raw", "delete", "unknown", "repeat",
           "nest", "dup")


def mutate(data: st.DataObject, doc: dict[str, Any],
           ops: tuple[str, ...] = ALL_OPS) -> tuple[dict[str, Any], list[str]]:
    """Apply 1–4 random structural, type or magnitude mutations; returns the document
    and the raw texts to splice in for its ``"@@RAWn@@"`` placeholders."""
    raws: list[str] = []
    for _ in range(data.draw(st.integers(1, 4), label="mutations")):
        places = list(slots(doc))
        op = data.draw(st.sampled_from(ops), label="op")
        container, key = data.draw(st.sampled_from(places), label="where") if places else (doc, 0)
        if op == "magnitude":
            numbers = [(c, k) for c, k in places if k != "version"
                       and isinstance(c[k], (int, float)) and not isinstance(c[k], bool)]
            if numbers:
                container, key = data.draw(st.sampled_from(numbers), label="number")
                container[key] = data.draw(MAGNITUDES, label="magnitude")
        elif op == "value":
            container[key] = data.draw(HOSTILE_VALUES, label="value")
        elif op == "raw":
            container[key] = f"@@RAW{len(raws)}@@"
            raws.append(data.draw(st.sampled_from(RAW_TEXTS), label="raw"))
        elif op == "delete":
            del container[key]
        elif op == "unknown":
            target = container[key] if isinstance(container[key], dict) else doc
            target[data.draw(st.text(max_size=8), label="new key")] = 1.0
        elif op == "repeat":  # a list grows by copies of one element, up to past a limit
            lists = [c for c, _ in places if isinstance(c, list) and c]
            if lists:
                target = data.draw(st.sampled_from(lists), label="list")
                n = data.draw(st.sampled_from([2, 10, MAX_SEGMENTS - 30, MAX_SEGMENTS + 1]))
                target.extend(copy.deepcopy(target[:1]) * n)
        elif op == "nest":
            for _ in range(data.draw(st.integers(1, 20), label="depth")):
                container[key] = [container[key]]
        elif op == "dup" and isinstance(container, dict):  # `"k": 1.0, "k": 2.0` in the text
            container[key] = f"@@RAW{len(raws)}@@"
            raws.append(f"1.0, {json.dumps(key)}: 2.0")
    return doc, raws


def to_text(doc: Any, raws: list[str], indent: int | None) -> str:
    text = json.dumps(doc, indent=indent)
    for i, raw in enumerate(raws):
        text = text.replace(f'"@@RAW{i}@@"', raw)
    return text


def answer(workdir: Path, content: bytes) -> Track | TrackFileError:
    """What ``load_track`` makes of ``content``; any other exception fails the test."""
    path = workdir / "t.json"
    path.write_bytes(content)
    try:
        with address_space_cap():  # a regression fails with MemoryError, not by swapping
            track = load_track(path)
    except TrackFileError as exc:
        message = str(exc)
        assert message.startswith(str(path))  # the error names the file
        rules = "Carolo-Cup rule" in message
        assert rules or len(message) < 1000  # never a dump of the input
        # --hypothesis-show-statistics tells how deep the inputs got.
        event("refused: " + ("rules" if rules else "JSON" if "JSON" in message else
                             "limit" if "tfalda_sim.tracks.fileformat.MAX" in message
                             or "tfalda_sim.tracks.model.MAX" in message else "schema"))
        return exc
    event("accepted")
    assert track.length_m <= MAX_TRACK_LENGTH_M and len(track.segments) <= MAX_SEGMENTS
    return track


@settings(FUZZ, max_examples=300)
@given(data=st.data(), base=st.sampled_from(BASES), indent=st.sampled_from([None, 2]))
def test_mutated_documents_load_or_raise_track_file_error(
        workdir: Path, data: st.DataObject, base: dict[str, Any], indent: int | None) -> None:
    doc, raws = mutate(data, copy.deepcopy(base))
    result = answer(workdir, to_text(doc, raws, indent).encode())
    if isinstance(result, Track):
        # Whatever is accepted survives a round trip exactly.
        again = load_track(save_track(result, workdir / "again.json", overwrite=True))
        assert again == result


@settings(FUZZ, max_examples=250)
@given(data=st.data(), base=st.sampled_from(BASES))
def test_odd_magnitudes_reach_the_rule_check_without_crashing_it(
        workdir: Path, data: st.DataObject, base: dict[str, Any]) -> None:
    # Numbers only: the document keeps its shape, so many reach validate() with values
    # no generator would produce (zero-length gaps, obstacles off the road, ...).
    doc, raws = mutate(data, copy.deepcopy(base), ops=("magnitude",))
    answer(workdir, to_text(doc, raws, None).encode())


@settings(FUZZ, max_examples=200)
@given(base=st.sampled_from(BASES), cut=st.floats(0.0, 1.0), junk=st.binary(max_size=40),
       how=st.sampled_from(["truncate", "insert", "overwrite", "prefix", "replace"]))
def test_damaged_bytes_load_or_raise_track_file_error(
        workdir: Path, base: dict[str, Any], cut: float, junk: bytes, how: str) -> None:
    text = json.dumps(base, indent=2).encode()
    at = int(cut * len(text))
    content = {
        "truncate": text[:at],
        "insert": text[:at] + junk + text[at:],
        "overwrite": text[:at] + junk + text[at + len(junk):],
        "prefix": b"\xef\xbb\xbf" + junk + text,  # a BOM, then junk
        "replace": junk,
    }[how]
    answer(workdir, content)


@settings(FUZZ, max_examples=30)
@given(opener=st.sampled_from(["[", "{\"a\":", "[{\"b\":["]),
       depth=st.sampled_from([15, 16, 17, 1000, 100_000]), closed=st.booleans())
def test_deep_nesting_loads_or_raises_track_file_error(
        workdir: Path, opener: str, depth: int, closed: bool) -> None:
    closer = {"[": "]", "{\"a\":": "}", "[{\"b\":[": "]}]"}[opener]
    text = opener * depth + ("0" + closer * depth if closed else "")
    result = answer(workdir, text.encode())
    assert isinstance(result, TrackFileError)
