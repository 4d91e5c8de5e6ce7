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
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

from .model import Arc, Gap, Intersection, Lane, Line, Obstacle, Pose, Straight, Track
from .rules import validate

FORMAT = "tfalda-sim/track"
VERSION = 1


class TrackFileError(ValueError):
    """A track file that cannot be read: names the file, the field and what is wrong."""


class _Reader:
    """Typed access to one JSON object, with errors that name the field's path."""

    def __init__(self, source: str, obj: Any, path: str, allowed: set[str]) -> None:
        self.source = source
        self.path = path
        if not isinstance(obj, dict):
            self.fail(f"must be an object, got {type(obj).__name__}")
        unknown = sorted(set(obj) - allowed)
        if unknown:
            self.fail(f"unknown key(s) {', '.join(map(repr, unknown))}; allowed: "
                      f"{', '.join(sorted(allowed))}")
        self.obj = obj

    def fail(self, message: str, key: str | None = None) -> None:
        where = self.path + (f".{key}" if key and self.path else key or "")
        raise TrackFileError(f"{self.source}: {where or '(top level)'}: {message}")

    def _get(self, key: str, default: Any, required: bool) -> Any:
        if key not in self.obj:
            if required:
                self.fail("missing required field", key)
            return default
        return self.obj[key]

    def number(self, key: str, default: float | None = None, required: bool = True) -> float:
        v = self._get(key, default, required)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self.fail(f"must be a number, got {json.dumps(v)}", key)
        if not math.isfinite(v):
            self.fail("must be finite", key)
        return float(v)

    def optional_number(self, key: str) -> float | None:
        if self.obj.get(key) is None:
            return None
        return self.number(key)

    def boolean(self, key: str, default: bool | None = None, required: bool = True) -> bool:
        v = self._get(key, default, required)
        if not isinstance(v, bool):
            self.fail(f"must be true or false, got {json.dumps(v)}", key)
        return v

    def text(self, key: str, default: str = "", required: bool = False) -> str:
        v = self._get(key, default, required)
        if not isinstance(v, str):
            self.fail(f"must be a string, got {json.dumps(v)}", key)
        return v

    def choice(self, key: str, options: tuple[str, ...]) -> str:
        v = self.text(key, required=True)
        if v not in options:
            self.fail(f"must be one of {', '.join(options)}, got {v!r}", key)
        return v

    def items(self, key: str, required: bool = False) -> list[Any]:
        v = self._get(key, [], required)
        if not isinstance(v, list):
            self.fail(f"must be a list, got {type(v).__name__}", key)
        return v

    def child(self, obj: Any, key: str, allowed: set[str]) -> _Reader:
        return _Reader(self.source, obj, f"{self.path}.{key}" if self.path else key, allowed)


def _segment(r: _Reader, raw: Any, i: int) -> Straight | Arc:
    probe = r.child(raw, f"segments[{i}]", {"type", "length_m", "radius_m", "angle_rad"})
    kind = probe.choice("type", ("straight", "arc"))
    if kind == "straight":
        seg = r.child(raw, f"segments[{i}]", {"type", "length_m"})
        length = seg.number("length_m")
        if length <= 0:
            seg.fail(f"must be > 0, got {length}", "length_m")
        return Straight(length)
    seg = r.child(raw, f"segments[{i}]", {"type", "radius_m", "angle_rad"})
    radius, angle = seg.number("radius_m"), seg.number("angle_rad")
    if radius <= 0:
        seg.fail(f"must be > 0, got {radius}", "radius_m")
    if not 0 < abs(angle) <= 2 * math.pi:
        seg.fail(f"must be non-zero and within ±2π, got {angle}", "angle_rad")
    return Arc(radius, angle)


def track_from_dict(data: Any, source: str = "<dict>") -> Track:
    """Parse a track document (already decoded from JSON); raises ``TrackFileError``."""
    top = _Reader(source, data, "", {
        "format", "version", "name", "description", "seed", "closed", "lane_width_m", "start",
        "start_line_s_m", "segments", "gaps", "obstacles", "intersections"})
    if top.text("format", required=True) != FORMAT:
        top.fail(f"must be {FORMAT!r} (is this a track file?)", "format")
    version = top.number("version")
    if version != VERSION:
        top.fail(f"version {version:g} is not supported (this tfalda-sim reads {VERSION})",
                 "version")
    seed = data.get("seed")
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or seed < 0):
        top.fail(f"must be a non-negative integer or null, got {json.dumps(seed)}", "seed")
    start = top.child(top._get("start", None, True), "start", {"x_m", "y_m", "heading_rad"})
    segments_raw = top.items("segments", required=True)
    if not segments_raw:
        top.fail("needs at least one segment", "segments")
    segments = tuple(_segment(top, raw, i) for i, raw in enumerate(segments_raw))
    gaps = []
    for i, raw in enumerate(top.items("gaps")):
        g = top.child(raw, f"gaps[{i}]", {"line", "s_m", "length_m"})
        gaps.append(Gap(Line(g.choice("line", tuple(m.value for m in Line))), g.number("s_m"),
                        g.number("length_m")))
    obstacles = []
    for i, raw in enumerate(top.items("obstacles")):
        o = top.child(raw, f"obstacles[{i}]",
                      {"s_m", "lane", "offset_m", "length_m", "width_m", "height_m"})
        obstacles.append(Obstacle(
            o.number("s_m"), Lane(o.choice("lane", ("right", "left"))), o.number("length_m"),
            o.number("width_m"), o.number("height_m"), o.number("offset_m", 0.0, required=False)))
    intersections = []
    for i, raw in enumerate(top.items("intersections")):
        x = top.child(raw, f"intersections[{i}]", {"s1_m", "s2_m"})
        intersections.append(Intersection(x.number("s1_m"), x.number("s2_m")))
    lane_width = top.number("lane_width_m")
    if lane_width <= 0:
        top.fail(f"must be > 0, got {lane_width}", "lane_width_m")
    return Track(
        segments=segments,
        closed=top.boolean("closed"),
        start=Pose(start.number("x_m"), start.number("y_m"), start.number("heading_rad")),
        lane_width_m=lane_width,
        start_line_s_m=top.optional_number("start_line_s_m"),
        gaps=tuple(gaps),
        obstacles=tuple(obstacles),
        intersections=tuple(intersections),
        name=top.text("name"),
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


def load_track(path: str | os.PathLike[str], *, check_rules: bool = True) -> Track:
    """Read a track file. With ``check_rules`` (default) a track that breaks a Carolo-Cup
    rule is refused with every violation listed."""
    source = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise TrackFileError(f"{source}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise TrackFileError(f"{source}: cannot read: {exc}") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise TrackFileError(
            f"{source}: not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})"
        ) from None
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


def publish(tmp: str | os.PathLike[str], target: str | os.PathLike[str]) -> None:
    """Move a finished temporary file onto ``target`` in one step. mkstemp creates 0600;
    the file gets the permissions a plain open() would have given it."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    os.replace(tmp, target)


@contextmanager
def atomic_write(path: str | os.PathLike[str], mode: str = "w") -> Iterator[IO[Any]]:
    """Write ``path`` through a temporary file in its folder (created if missing), put in
    place in one step: a failed or interrupted write leaves an existing file untouched."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    try:
        with os.fdopen(fd, mode, encoding=None if "b" in mode else "utf-8") as fh:
            yield fh
        publish(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def save_track(track: Track, path: str | os.PathLike[str], *, overwrite: bool = False) -> Path:
    """Write a track file atomically. An existing file is kept unless ``overwrite``."""
    target = Path(path)
    if target.exists() and not overwrite:
        raise FileExistsError(f"{target} exists; pass overwrite=True (CLI: --force) to replace it")
    text = json.dumps(track_to_dict(track), indent=2, allow_nan=False) + "\n"
    with atomic_write(target) as fh:
        fh.write(text)
    return target
