"""Named track files shipped in ``tracks/data/`` (built by ``tools/make_named_tracks.py``)."""

from __future__ import annotations

from pathlib import Path

from .fileformat import load_track
from .model import Track

DATA_DIR = Path(__file__).with_name("data")

NAMED_TRACKS: tuple[str, ...] = ("straight", "left-curve", "thesis", "oval", "figure-eight")
"""Names accepted by ``load_named``: a 10 m straight strip, a single left curve at the
tightest legal radius, the thesis' 183-frame run (straight → left curve → straight), an
oval and a figure-eight with an intersection."""


def named_path(name: str) -> Path:
    """The file of a named track; a clear error lists the names for an unknown one."""
    if name not in NAMED_TRACKS:
        raise ValueError(f"unknown track name {name!r}; known: {', '.join(NAMED_TRACKS)}")
    return DATA_DIR / f"{name}.json"


def load_named(name: str) -> Track:
    """Load a named track (validated against the rules)."""
    return load_track(named_path(name))
