"""Track files: human-readable JSON, strict schema, exact round trip.

Schema (``"format": "tfalda-sim/track"``, ``"version": 1``); lengths in metres, angles in
radians, ``s_m`` = arc length along the road's centre line from the start pose::

    {
      "format": "tfalda-sim/track", "version": 1,
      "name": "oval", "description": "…",            # optional text
      "seed": 7,                                      # optional: generator scenario id
      "closed": true,                                 # circuit (true) or open strip
      "lane_width_m": 0.4,                            # line centre to line centre
      "start": {"x_m": 0.0, "y_m": 0.0, "heading_rad": 0.0},
      "start_line_s_m": 0.0,                          # or null (open strips)
      "segments": [{"type": "straight", "length_m": 2.0},
                   {"type": "arc", "radius_m": 2.0, "angle_rad": 3.14159}],  # + = left
      "gaps": [{"line": "left|centre|right", "s_m": 3.0, "length_m": 0.5}],
      "obstacles": [{"s_m": 6.0, "lane": "right|left", "offset_m": 0.0,
                     "length_m": 0.2, "width_m": 0.2, "height_m": 0.15}],
      "intersections": [{"s1_m": 4.8, "s2_m": 20.0}]
    }

Unknown keys are errors (a typo must not be silently ignored). Floats are written with
Python's shortest round-trip repr, so ``load(save(track)) == track`` exactly.

A hostile file must not cost more than a few seconds or megabytes: the ``MAX_*`` limits
below (and ``tfalda_sim.tracks.model.MAX_TRACK_LENGTH_M`` / ``MAX_LANE_WIDTH_M``) are checked before
anything proportional to the size is allocated, with an error naming field and limit.
"""

from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from ..fileio import atomic_write
from .model import (
    MAX_LANE_WIDTH_M,
    MAX_TRACK_LENGTH_M,
    Arc,
    Gap,
    Intersection,
    Lane,
    Line,
    Obstacle,
    Pose,
    Straight,
    Track,
)
from .rules import validate

FORMAT = "tfalda-sim/track"
VERSION = 1

__all__ = [
    "FORMAT", "MAX_FILE_BYTES", "MAX_GAPS", "MAX_HEADING_RAD", "MAX_INTERSECTIONS",
    "MAX_JSON_DEPTH", "MAX_LANE_WIDTH_M", "MAX_MAT_EXTENT_M", "MAX_NAME_CHARS", "MAX_OBSTACLES",
    "MAX_SEGMENTS",
    "MAX_TRACK_LENGTH_M", "MIN_RADIUS_M", "MIN_SEGMENT_LENGTH_M", "VERSION", "TrackFileError",
    "load_track", "save_track", "track_from_dict", "track_to_dict",
]

MAX_SEGMENTS: int = 100
"""Most segments in a file [count]. Generated tracks have ≤ 25, the named ones ≤ 9. The
rule check compares every 5 cm sample with every segment and keeps every close pair, so
its cost is (track length / 5 cm) × segments: at this count and the longest track
(``MAX_TRACK_LENGTH_M``) the most hostile file (every segment close to every sample, each
close pair its own overlap) takes ≈ 3.5 s to validate on a 2-core VM."""

MAX_GAPS: int = 200
"""Most marking gaps in a file [count]. Generated tracks have ≤ 8. Every line pixel the
rasteriser paints looks at every gap, so the count multiplies the time to draw the map."""

MAX_OBSTACLES: int = 250
"""Most obstacles in a file [count]. Generated tracks have ≤ 7; with the rules' ≥ 1 m
of free road between cartons the longest track holds fewer than 230."""

MAX_INTERSECTIONS: int = 4
"""Most intersections in a file [count]. Generated tracks have ≤ 1, Carolo-Cup tracks one
or two. Every close approach the overlap check finds is compared with every one (in
Python): each intersection adds ≈ 0.5 s to the most hostile file's rule check."""

MAX_MAT_EXTENT_M: float = 1000.0
"""Largest magnitude [m] of any coordinate, radius, position along the road, offset or
size in a file. Generated tracks lie within 11 m of the origin on mats ≤ 20 m wide and
use radii ≤ 4 m; at 1 km a float still resolves 1e-13 m, and nothing on a mat is larger.
Segment lengths have the tighter ``MAX_TRACK_LENGTH_M``."""

MAX_HEADING_RAD: float = 100.0
"""Largest magnitude [rad] of the start heading (≈ 16 turns; headings mean the same
modulo 2π and are written within ±π). Keeps ``heading + curvature × s`` exact to 1e-14."""

MIN_SEGMENT_LENGTH_M: float = 0.001
"""Shortest straight [m] (1 mm, a quarter of a map pixel): shorter ones are numerical
noise, and a track of 1e-300 m pieces would validate as a point."""

MIN_RADIUS_M: float = 0.001
"""Smallest arc radius [m] a file may give. The rules' minimum (≈ 1.41 m) is reported by
``validate``; below 1 mm (a quarter of a map pixel) an arc has no shape to draw, and near
1e-308 m its curvature 1/r overflows to infinity and the geometry turns NaN."""

MAX_FILE_BYTES: int = 1024 * 1024
"""Largest track file [bytes] (1 MiB). A generated track's file is ≈ 5 kB; one at every
count limit above, indented as ``save_track`` writes it, ≈ 80 kB. At most this + 1
bytes are read, so a huge file (or a device) is refused without reading it."""

MAX_JSON_DEPTH: int = 16
"""Deepest nesting of JSON arrays and objects [levels]. A track document needs 3 (top
object → list → element); deeper files are refused before decoding, so the decoder's
recursion never meets a hostile depth."""

MAX_NAME_CHARS: int = 100
"""Longest track name [characters]. A name is a label (``oval``, ``seed-7``) that commands
print on one line and draw into videos; the named and generated tracks' are ≤ 12. Its
characters must all be printable (``str.isprintable``): no control characters, which a
terminal would act on (clear the screen, return the cursor to fake a line)."""

_MAX_INT_DIGITS = 400
"""Longer integers are not converted (no float holds one; Python refuses > 4300 digits)."""


class TrackFileError(ValueError):
    """A track file that cannot be read: names the file, the field and what is wrong."""


@dataclass(frozen=True)
class _BigInt:
    """A JSON integer too long to convert: kept as its digit count, refused by the reader."""

    digits: int


class _Object(dict[str, Any]):
    """A decoded JSON object that remembers the keys it was given more than once."""

    duplicates: tuple[str, ...] = ()


def _parse_int(text: str) -> int | _BigInt:
    digits = len(text) - text.startswith("-")
    return _BigInt(digits) if digits > _MAX_INT_DIGITS else int(text)


def _make_object(pairs: list[tuple[str, Any]]) -> _Object:
    obj = _Object(pairs)  # the last value of a repeated key wins, as in json.loads
    if len(obj) != len(pairs):
        seen: set[str] = set()
        repeated: set[str] = set()
        for key, _ in pairs:
            (repeated if key in seen else seen).add(key)
        obj.duplicates = tuple(sorted(repeated))
    return obj


# A string, or an unterminated one up to the end: every match attempt succeeds, so the
# scan is linear even for hostile quote/backslash runs (a failed attempt would be retried
# from every later quote).
_JSON_STRING = re.compile(r'"(?:[^"\\]|\\.)*(?:"|\\?\Z)', re.DOTALL)
_NOT_BRACKET = re.compile(r"[^\[\]{}]+")
_BRACKET_STEP = np.zeros(256, dtype=np.int32)
_BRACKET_STEP[[ord("["), ord("{")]] = 1
_BRACKET_STEP[[ord("]"), ord("}")]] = -1


def _json_depth(text: str) -> int:
    """Deepest bracket nesting of JSON ``text``, brackets inside strings not counted
    (linear time, no recursion)."""
    brackets = _NOT_BRACKET.sub("", _JSON_STRING.sub("", text)).encode("ascii")
    if not brackets:
        return 0
    return int(np.cumsum(_BRACKET_STEP[np.frombuffer(brackets, dtype=np.uint8)]).max())


def _show(v: Any) -> str:
    """A short rendering of a JSON value for an error message (never huge, never raises)."""
    if isinstance(v, _BigInt):
        return f"an integer of {v.digits} digits"
    if isinstance(v, int) and not isinstance(v, bool) and abs(v) >= 10**30:
        return f"an integer of {len(str(abs(v)))} digits"
    if isinstance(v, dict):
        return "an object"
    if isinstance(v, list):
        return f"a list of {len(v)}"
    return _clip(json.dumps(v))


def _clip(text: str, most: int = 60) -> str:
    return text if len(text) <= most else text[:most - 3] + "..."


def _some(keys: list[str] | tuple[str, ...], most: int = 5) -> str:
    """The first ``most`` keys for an error message (a hostile object may have 100,000)."""
    shown = ", ".join(_clip(repr(k)) for k in keys[:most])
    return shown if len(keys) <= most else f"{shown}, … ({len(keys)} in all)"


def _kind(v: Any) -> str:
    return "dict" if isinstance(v, dict) else "int" if isinstance(v, _BigInt) else type(v).__name__


@dataclass(frozen=True)
class _Limit:
    """Largest magnitude of a number field, and how an error names it."""

    value: float
    unit: str
    what: str
    name: str


_EXTENT = _Limit(MAX_MAT_EXTENT_M, "m", "the largest mat extent",
                 "tfalda_sim.tracks.fileformat.MAX_MAT_EXTENT_M")
_TRACK_LENGTH = _Limit(MAX_TRACK_LENGTH_M, "m", "the largest track length",
                       "tfalda_sim.tracks.model.MAX_TRACK_LENGTH_M")
_HEADING = _Limit(MAX_HEADING_RAD, "rad", "the largest heading",
                  "tfalda_sim.tracks.fileformat.MAX_HEADING_RAD")
_LANE_WIDTH = _Limit(MAX_LANE_WIDTH_M, "m", "the widest lane",
                     "tfalda_sim.tracks.model.MAX_LANE_WIDTH_M")


class _Reader:
    """Typed access to one JSON object, with errors that name the field's path."""

    def __init__(self, source: str, obj: Any, path: str, allowed: set[str]) -> None:
        self.source = source
        self.path = path
        if not isinstance(obj, dict):
            self.fail(f"must be an object, got {_kind(obj)}")
        duplicates = getattr(obj, "duplicates", ())
        if duplicates:
            self.fail(f"duplicate key(s) {_some(duplicates)}")
        unknown = sorted(set(obj) - allowed)
        if unknown:
            self.fail(f"unknown key(s) {_some(unknown)}; allowed: {', '.join(sorted(allowed))}")
        self.obj = obj

    def fail(self, message: str, key: str | None = None) -> NoReturn:
        where = self.path + (f".{key}" if key and self.path else key or "")
        raise TrackFileError(f"{self.source}: {where or '(top level)'}: {message}")

    def _get(self, key: str, default: Any, required: bool) -> Any:
        if key not in self.obj:
            if required:
                self.fail("missing required field", key)
            return default
        return self.obj[key]

    def number(self, key: str, default: float | None = None, required: bool = True,
               limit: _Limit | None = _EXTENT) -> float:
        v = self._get(key, default, required)
        if isinstance(v, _BigInt):
            self.fail(f"must be a finite number, got {_show(v)}", key)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self.fail(f"must be a number, got {_show(v)}", key)
        try:
            f = float(v)
        except OverflowError:  # an int beyond the float range
            self.fail(f"must be a finite number, got {_show(v)}", key)
        if not math.isfinite(f):
            self.fail("must be finite", key)
        return f if limit is None else self.within(key, f, limit)

    def within(self, key: str, value: float, limit: _Limit) -> float:
        """``value`` if its magnitude is within ``limit``; fails naming the limit."""
        if abs(value) > limit.value:
            shown = f"{value:g}" if value >= 0 else f"|{value:g}|"
            self.fail(f"{shown} {limit.unit} exceeds {limit.what} {limit.value:g} {limit.unit} "
                      f"({limit.name})", key)
        return value

    def optional_number(self, key: str) -> float | None:
        if self.obj.get(key) is None:
            return None
        return self.number(key)

    def boolean(self, key: str, default: bool | None = None, required: bool = True) -> bool:
        v = self._get(key, default, required)
        if not isinstance(v, bool):
            self.fail(f"must be true or false, got {_show(v)}", key)
        return v

    def text(self, key: str, default: str = "", required: bool = False) -> str:
        v = self._get(key, default, required)
        if not isinstance(v, str):
            self.fail(f"must be a string, got {_show(v)}", key)
        try:
            v.encode("utf-8")  # a lone surrogate (from a \ud800 escape) cannot be printed
        except UnicodeEncodeError as exc:
            self.fail(f"must be Unicode text, has a lone surrogate at character {exc.start}", key)
        return v

    def label(self, key: str, most: int) -> str:
        """Optional printable one-line text of at most ``most`` characters."""
        v = self.text(key)
        if len(v) > most:
            self.fail(f"must be at most {most} characters, has {len(v)}", key)
        bad = next((i for i, c in enumerate(v) if not c.isprintable()), None)
        if bad is not None:
            # repr: the error line must not carry the character it refuses
            self.fail(f"must be printable text on one line; character {bad} is {v[bad]!r}",
                      key)
        return v

    def choice(self, key: str, options: tuple[str, ...]) -> str:
        v = self.text(key, required=True)
        if v not in options:
            self.fail(f"must be one of {', '.join(options)}, got {_clip(repr(v))}", key)
        return v

    def items(self, key: str, required: bool = False, limit: int | None = None,
              limit_name: str = "") -> list[Any]:
        v = self._get(key, [], required)
        if not isinstance(v, list):
            self.fail(f"must be a list, got {_kind(v)}", key)
        if limit is not None and len(v) > limit:
            self.fail(f"{len(v)} entries exceed the largest number of {key} {limit} "
                      f"(tfalda_sim.tracks.fileformat.{limit_name})", key)
        return v

    def child(self, obj: Any, key: str, allowed: set[str]) -> _Reader:
        return _Reader(self.source, obj, f"{self.path}.{key}" if self.path else key, allowed)


def _segment(r: _Reader, raw: Any, i: int, before_m: float) -> Straight | Arc:
    """Segment ``i``; ``before_m`` [m] is the length of the segments before it."""
    probe = r.child(raw, f"segments[{i}]", {"type", "length_m", "radius_m", "angle_rad"})
    kind = probe.choice("type", ("straight", "arc"))
    if kind == "straight":
        seg = r.child(raw, f"segments[{i}]", {"type", "length_m"})
        length = seg.number("length_m", limit=None)
        if length <= 0:
            seg.fail(f"must be > 0, got {length}", "length_m")
        if length < MIN_SEGMENT_LENGTH_M:
            seg.fail(f"{length:g} m is shorter than the shortest segment "
                     f"{MIN_SEGMENT_LENGTH_M:g} m (tfalda_sim.tracks.fileformat."
                     "MIN_SEGMENT_LENGTH_M)", "length_m")
        result: Straight | Arc = Straight(seg.within("length_m", length, _TRACK_LENGTH))
    else:
        seg = r.child(raw, f"segments[{i}]", {"type", "radius_m", "angle_rad"})
        radius, angle = seg.number("radius_m", limit=None), seg.number("angle_rad", limit=None)
        if radius <= 0:
            seg.fail(f"must be > 0, got {radius}", "radius_m")
        if radius < MIN_RADIUS_M:
            seg.fail(f"{radius:g} m is below the smallest arc radius {MIN_RADIUS_M:g} m "
                     "(tfalda_sim.tracks.fileformat.MIN_RADIUS_M)", "radius_m")
        seg.within("radius_m", radius, _EXTENT)
        if not 0 < abs(angle) <= 2 * math.pi:
            seg.fail(f"must be non-zero and within ±2π, got {angle}", "angle_rad")
        result = Arc(radius, angle)
    # Summed as Track.__post_init__ sums, so a file accepted here is accepted there.
    total = before_m + result.length_m
    if total > MAX_TRACK_LENGTH_M:
        seg.fail(f"the segments up to here add up to {total:g} m, more than the largest track "
                 f"length {MAX_TRACK_LENGTH_M:g} m (tfalda_sim.tracks.model.MAX_TRACK_LENGTH_M)")
    return result


def track_from_dict(data: Any, source: str = "<dict>") -> Track:
    """Parse a track document (already decoded from JSON); raises ``TrackFileError``."""
    top = _Reader(source, data, "", {
        "format", "version", "name", "description", "seed", "closed", "lane_width_m", "start",
        "start_line_s_m", "segments", "gaps", "obstacles", "intersections"})
    if top.text("format", required=True) != FORMAT:
        top.fail(f"must be {FORMAT!r} (is this a track file?)", "format")
    version = top.number("version", limit=None)
    if version != VERSION:
        top.fail(f"version {version:g} is not supported (this tfalda-sim reads {VERSION})",
                 "version")
    seed = data.get("seed")
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or seed < 0):
        top.fail(f"must be a non-negative integer or null, got {_show(seed)}", "seed")
    start = top.child(top._get("start", None, True), "start", {"x_m", "y_m", "heading_rad"})
    # Every list's length is checked before its first element is read.
    segments_raw = top.items("segments", required=True, limit=MAX_SEGMENTS,
                             limit_name="MAX_SEGMENTS")
    if not segments_raw:
        top.fail("needs at least one segment", "segments")
    segment_list: list[Straight | Arc] = []
    total_m = 0.0
    for i, raw in enumerate(segments_raw):
        segment_list.append(_segment(top, raw, i, total_m))
        total_m += segment_list[-1].length_m
    segments = tuple(segment_list)
    gaps = []
    for i, raw in enumerate(top.items("gaps", limit=MAX_GAPS, limit_name="MAX_GAPS")):
        g = top.child(raw, f"gaps[{i}]", {"line", "s_m", "length_m"})
        line = g.choice("line", tuple(m.value for m in Line))
        s_m, length = g.number("s_m"), g.number("length_m")
        if length < 0:  # no meaning, and the rule check's sweep needs starts before ends
            g.fail(f"must be ≥ 0, got {length:g}", "length_m")
        gaps.append(Gap(Line(line), s_m, length))
    obstacles = []
    for i, raw in enumerate(top.items("obstacles", limit=MAX_OBSTACLES,
                                      limit_name="MAX_OBSTACLES")):
        o = top.child(raw, f"obstacles[{i}]",
                      {"s_m", "lane", "offset_m", "length_m", "width_m", "height_m"})
        obstacles.append(Obstacle(
            o.number("s_m"), Lane(o.choice("lane", ("right", "left"))), o.number("length_m"),
            o.number("width_m"), o.number("height_m"), o.number("offset_m", 0.0, required=False)))
    intersections = []
    for i, raw in enumerate(top.items("intersections", limit=MAX_INTERSECTIONS,
                                      limit_name="MAX_INTERSECTIONS")):
        x = top.child(raw, f"intersections[{i}]", {"s1_m", "s2_m"})
        intersections.append(Intersection(x.number("s1_m"), x.number("s2_m")))
    lane_width = top.number("lane_width_m", limit=None)
    if lane_width <= 0:
        top.fail(f"must be > 0, got {lane_width}", "lane_width_m")
    top.within("lane_width_m", lane_width, _LANE_WIDTH)
    return Track(
        segments=segments,
        closed=top.boolean("closed"),
        start=Pose(start.number("x_m"), start.number("y_m"),
                   start.number("heading_rad", limit=_HEADING)),
        lane_width_m=lane_width,
        start_line_s_m=top.optional_number("start_line_s_m"),
        gaps=tuple(gaps),
        obstacles=tuple(obstacles),
        intersections=tuple(intersections),
        name=top.label("name", MAX_NAME_CHARS),
        description=top.text("description"),
        seed=seed,
    )


def track_to_dict(track: Track) -> dict[str, Any]:
    """The JSON document of a track (inverse of ``track_from_dict``)."""
    doc: dict[str, Any] = {"format": FORMAT, "version": VERSION, "name": track.name}
    if track.description:
        doc["description"] = track.description
    if track.seed is not None:
        doc["seed"] = track.seed
    doc.update({
        "closed": track.closed,
        "lane_width_m": track.lane_width_m,
        "start": {"x_m": track.start.x_m, "y_m": track.start.y_m,
                  "heading_rad": track.start.heading_rad},
        "start_line_s_m": track.start_line_s_m,
        "segments": [
            {"type": "straight", "length_m": seg.length_m} if isinstance(seg, Straight)
            else {"type": "arc", "radius_m": seg.radius_m, "angle_rad": seg.angle_rad}
            for seg in track.segments],
        "gaps": [{"line": g.line.value, "s_m": g.s_m, "length_m": g.length_m} for g in track.gaps],
        "obstacles": [{"s_m": o.s_m, "lane": o.lane.value, "offset_m": o.offset_m,
                       "length_m": o.length_m, "width_m": o.width_m, "height_m": o.height_m}
                      for o in track.obstacles],
        "intersections": [{"s1_m": x.s1_m, "s2_m": x.s2_m} for x in track.intersections],
    })
    return doc


def _decode(text: str, source: str) -> Any:
    """The JSON document in ``text``: depth checked first, huge integers kept as
    ``_BigInt``, duplicate keys recorded for the reader to refuse."""
    depth = _json_depth(text)
    if depth > MAX_JSON_DEPTH:
        raise TrackFileError(
            f"{source}: nested too deeply ({depth} levels of lists/objects; the largest JSON "
            f"depth is {MAX_JSON_DEPTH}, tfalda_sim.tracks.fileformat.MAX_JSON_DEPTH)")
    try:
        return json.loads(text, parse_int=_parse_int, object_pairs_hook=_make_object)
    except json.JSONDecodeError as exc:
        raise TrackFileError(
            f"{source}: not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})"
        ) from None
    except RecursionError:  # the depth scan should have caught it; kept as a safety net
        raise TrackFileError(f"{source}: nested too deeply") from None


def load_track(path: str | os.PathLike[str], *, check_rules: bool = True) -> Track:
    """Read a track file. With ``check_rules`` (default) a track that breaks a Carolo-Cup
    rule is refused with every violation listed."""
    source = str(path)
    try:
        with open(path, "rb") as fh:
            raw = fh.read(MAX_FILE_BYTES + 1)  # never more: the file may be huge, or endless
    except FileNotFoundError:
        raise TrackFileError(f"{source}: no such file") from None
    except (OSError, ValueError) as exc:  # ValueError: a NUL byte in the path
        raise TrackFileError(f"{source}: cannot read: {exc}") from None
    if len(raw) > MAX_FILE_BYTES:
        raise TrackFileError(
            f"{source}: file is larger than the largest track file {MAX_FILE_BYTES} bytes "
            "(tfalda_sim.tracks.fileformat.MAX_FILE_BYTES)")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise TrackFileError(
            f"{source}: not UTF-8 text (byte 0x{raw[exc.start]:02x} at offset {exc.start})"
        ) from None
    data = _decode(text, source)
    try:
        track = track_from_dict(data, source)
    except (ValueError, TypeError) as exc:
        if isinstance(exc, TrackFileError):
            raise
        raise TrackFileError(f"{source}: {exc}") from None
    if check_rules:
        violations = validate(track)
        if violations:
            lines = "\n".join(f"  - {v.field}: {v.message} (rule {v.rule})" for v in violations)
            raise TrackFileError(f"{source}: breaks {len(violations)} Carolo-Cup rule(s):\n{lines}")
    return track


def save_track(track: Track, path: str | os.PathLike[str], *, overwrite: bool = False) -> Path:
    """Write a track file atomically. An existing file is kept unless ``overwrite``."""
    target = Path(path)
    if target.exists() and not overwrite:
        raise FileExistsError(f"{target} exists; pass overwrite=True (CLI: --force) to replace it")
    text = json.dumps(track_to_dict(track), indent=2, allow_nan=False) + "\n"
    with atomic_write(target) as fh:
        fh.write(text)
    return target
