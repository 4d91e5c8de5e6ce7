"""Hand-made ground truth of real frames: marking polylines in a JSON file, drawn into the
same ``FrameTruth`` the simulator's exact truth gives, so the thesis' black-box metric
scores any detector on labelled real frames.

Format (``format: tfalda-sim-labels/1``)::

    {"format": "tfalda-sim-labels/1", "frame": "straight-road.png",
     "image_width_px": 752, "image_height_px": 480, "note": "free text",
     "markings": [{"kind": "centre_line", "road": "ego",
                   "boundary": "left", "points": [[u, v, width_px], ...]}, ...]}

``frame``: the labelled image's file name; the labels are refused for any other image
(``evaluate --frames`` finds a frame's labels by its name, ``<stem>.labels.json``: a file
copied or renamed to another frame's name would otherwise score it silently).
``kind``: ``right_line``, ``centre_line``, ``left_line``, ``start_line`` or ``stop_line``;
``road``: ``ego`` (the road the car is on) or ``other`` (a neighbouring or
branching road's); ``boundary`` (optional): ``left`` or ``right`` for the two
markings that bound the ego lane in view (on a straight: the centre line and the
right line). ``points`` run along the marking, each with the marking's width there
[px]. As the thesis painted its reference images (section 4.1.7), a dashed line is
labelled continuous.
"""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from tfalda_sim.tracks import Marking

from ..rendering.truth import FrameTruth

LABELS_FORMAT: str = "tfalda-sim-labels/1"
"""The ``format`` value of a labels file."""

MAX_LABELS_BYTES: int = 1 << 20
"""Largest labels file read [bytes]."""

MAX_MARKING_WIDTH_PX: float = 200.0
"""Widest marking a label may give [px]."""

_KINDS = {"right_line": Marking.RIGHT_LINE, "centre_line": Marking.CENTRE_LINE,
          "left_line": Marking.LEFT_LINE, "start_line": Marking.START_LINE,
          "stop_line": Marking.STOP_LINE}
_ROADS = ("ego", "other")
_KEYS = ("format", "frame", "image_width_px", "image_height_px", "note", "markings")
_MARKING_KEYS = ("kind", "road", "boundary", "points")
BOUNDARY_STEP_PX: float = 2.0
"""Spacing of the ego boundaries' sample points along their polylines [px]."""


class LabelsError(ValueError):
    """A labels file that cannot be used; the message names the file and the field."""


def _fail(path: Path, msg: str) -> LabelsError:
    return LabelsError(f"{path}: {msg}")


def _read(path: Path) -> dict[str, Any]:
    if not path.is_file():
        raise _fail(path, "no such file")
    if path.stat().st_size > MAX_LABELS_BYTES:
        raise _fail(path, f"larger than {MAX_LABELS_BYTES} bytes: not a labels file")
    try:
        doc = json.loads(path.read_bytes().decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise _fail(path, f"not valid JSON ({exc})") from None
    if not isinstance(doc, dict):
        raise _fail(path, "expected a JSON object")
    extra = [k for k in doc if k not in _KEYS]
    if extra:
        raise _fail(path, f"unknown key {extra[0]!r} (known: {', '.join(_KEYS)})")
    for key in ("format", "image_width_px", "image_height_px", "markings"):
        if key not in doc:
            raise _fail(path, f"{key} is missing")
    if doc["format"] != LABELS_FORMAT:
        raise _fail(path, f"format {doc['format']!r} is not {LABELS_FORMAT!r}")
    return doc


def _check_frame(path: Path, doc: dict[str, Any], frame: str | Path | None) -> None:
    named = doc.get("frame")
    if named is None:
        return
    if not isinstance(named, str) or not named:
        raise _fail(path, f"frame must be the labelled image's file name, got {named!r}")
    if frame is not None and Path(named).name != Path(frame).name:
        # Labels of another picture score a detector against markings that are not in
        # the frame: every figure would be wrong without a sign of it.
        raise _fail(path, f"labels the frame {Path(named).name!r}, not {Path(frame).name!r} "
                          "it is applied to (a frame's labels are <its name>.labels.json): "
                          "label this frame, or if the labels are its own (the image was "
                          f"renamed) set \"frame\": \"{Path(frame).name}\"")


def labelled_frame(path: str | Path, frame: str | Path) -> None:
    """Refuse (``LabelsError``) a labels file whose ``frame`` names another image than
    ``frame``, without drawing its markings. A file that cannot be read passes: loading it
    with its frame (``load_labels``) says what is wrong, after the frame's own checks."""
    p = Path(path)
    try:
        doc = _read(p)
    except LabelsError:
        return
    _check_frame(p, doc, frame)


def load_labels(path: str | Path, width: int | None = None, height: int | None = None,
                frame: str | Path | None = None) -> FrameTruth:
    """The ground truth of a labels file; ``width``/``height`` [px], if given, must be the
    file's (a frame of another size); ``frame``, if given, must be the image the file's
    ``frame`` names (when it names one)."""
    p = Path(path)
    doc = _read(p)
    _check_frame(p, doc, frame)
    w, h = doc["image_width_px"], doc["image_height_px"]
    for key, value in (("image_width_px", w), ("image_height_px", h)):
        if isinstance(value, bool) or not isinstance(value, int) or not 16 <= value <= 8192:
            raise _fail(p, f"{key} must be an integer in [16, 8192], got {value!r}")
    if (width is not None and width != w) or (height is not None and height != h):
        raise _fail(p, f"labels are for {w}×{h} frames, the frame is {width}×{height}")
    marks = doc["markings"]
    if not isinstance(marks, list) or not marks:
        raise _fail(p, "markings must be a non-empty list")
    labels = np.zeros((h, w), np.uint8)
    boundaries: dict[str, np.ndarray] = {}
    for k, m in enumerate(marks):
        where = f"markings[{k}]"
        if not isinstance(m, dict):
            raise _fail(p, f"{where} must be an object with {', '.join(_MARKING_KEYS)}")
        extra = [key for key in m if key not in _MARKING_KEYS]
        if extra:
            raise _fail(p, f"unknown key {extra[0]!r} in {where} (known: "
                           f"{', '.join(_MARKING_KEYS)})")
        if not isinstance(m.get("kind"), str) or m["kind"] not in _KINDS:
            raise _fail(p, f"{where}.kind must be one of {', '.join(_KINDS)}, got "
                           f"{m.get('kind')!r}")
        if not isinstance(m.get("road"), str) or m["road"] not in _ROADS:
            raise _fail(p, f"{where}.road must be ego or other, got {m.get('road')!r}")
        pts = _points(p, where, m.get("points"), w, h)
        mark = _KINDS[m["kind"]]
        for (u0, v0, w0), (u1, v1, w1) in itertools.pairwise(pts):
            thick = max(1, round(0.5 * (w0 + w1)))
            cv2.line(labels, (round(u0 * 16), round(v0 * 16)), (round(u1 * 16), round(v1 * 16)),
                     int(mark), thick, lineType=cv2.LINE_8, shift=4)
        side = m.get("boundary")
        if side is not None:
            if not isinstance(side, str) or side not in ("left", "right"):
                raise _fail(p, f"{where}.boundary must be left or right, got {side!r}")
            if side in boundaries:
                raise _fail(p, f"{where}: a second {side} boundary of the ego lane")
            boundaries[side] = _densify(pts[:, :2])
    empty = np.zeros((0, 2))
    return FrameTruth(labels, boundaries.get("left", empty), boundaries.get("right", empty))


def _points(path: Path, where: str, value: Any, w: int, h: int) -> np.ndarray:
    ok = isinstance(value, list) and len(value) >= 2 and all(
        isinstance(q, list) and len(q) == 3 and all(
            isinstance(c, (int, float)) and not isinstance(c, bool) and _finite(c)
            for c in q) for q in value)
    if not ok:
        raise _fail(path, f"{where}.points must be ≥ 2 [u, v, width_px] triples of finite "
                          "numbers")
    pts = np.array(value, dtype=np.float64)
    if (pts[:, 0] < -0.5).any() or (pts[:, 0] > w - 0.5).any() or (pts[:, 1] < -0.5).any() \
            or (pts[:, 1] > h - 0.5).any():
        raise _fail(path, f"{where}.points leave the {w}×{h} image")
    if (pts[:, 2] <= 0).any() or (pts[:, 2] > MAX_MARKING_WIDTH_PX).any():
        raise _fail(path, f"{where}.points widths must be in (0, {MAX_MARKING_WIDTH_PX:g}] px")
    return pts


def _finite(value: float) -> bool:
    try:
        return math.isfinite(value)
    except OverflowError:  # an int too large for a float
        return False


def _densify(poly: np.ndarray) -> np.ndarray:
    out = [poly[:1]]
    for a, b in itertools.pairwise(poly):
        n = max(1, math.ceil(float(np.hypot(*(b - a))) / BOUNDARY_STEP_PX))
        t = np.arange(1, n + 1)[:, None] / n
        out.append(a + t * (b - a))
    return np.concatenate(out)


def labels_path_for(frame: Path, labels_dir: Path) -> Path:
    """The labels file of ``frame`` in ``labels_dir``: ``<stem>.labels.json``."""
    return labels_dir / f"{frame.stem}.labels.json"
