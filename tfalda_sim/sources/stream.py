"""One pass over a source's frames, the part every kind shares: the selected range (frames
outside it are not decoded), time stamps that must not go backwards, and frames of a
changing size brought to the first frame's size.

A kind yields ``(index, load)`` for every frame of the source in order; ``load()`` decodes
that frame into ``(t_s, image)`` and is called only for frames inside the range.
"""

from __future__ import annotations

import math
import re
from collections import Counter
from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import numpy as np

from tfalda_sim.sources.base import FrameRange, SourceError, SourceFrame, SourceInfo

Loader = Callable[[], tuple[float, np.ndarray]]
"""Decodes one frame: its time stamp from the source's first frame [s] and its image."""

RATE_SAMPLE_FRAMES = 100
"""Frames whose time stamps give a recording's frame rate (``median_rate_hz``): enough for
a robust median, few enough that opening a long recording stays quick."""


def reason(exc: BaseException) -> str:
    """A library's exception as a short clause (its own advice to report it dropped)."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    text = re.sub(r";\s*please report\b.*$", "", text)
    return text.rstrip(".")[:300]


def range_count(path: Path, total: int | None, frames: FrameRange) -> int | None:
    """The frames of ``frames`` in a source of ``total`` frames (None: unknown); a range
    that starts after the last frame is a ``SourceError``."""
    if total is None:
        return None
    if frames.start >= total:
        raise start_after_last(path, total, frames)
    stop = total if frames.stop is None else min(frames.stop, total)
    return stop - frames.start


def start_after_last(path: Path, total: int, frames: FrameRange) -> SourceError:
    return SourceError(f"{path} has {total} frames; --frames {frames} starts after the last "
                       f"(frames count from 0: give A below {total})")


def median_rate_hz(stamps_ns: list[int]) -> float | None:
    """A recording's frame rate [Hz] from its time stamps [ns]: one over the median interval
    between consecutive frames (robust to a dropped frame); None without two distinct
    stamps."""
    steps = np.diff(np.asarray(stamps_ns, dtype=np.int64))
    steps = steps[steps > 0]
    if steps.size == 0:
        return None
    return float(1e9 / np.median(steps))


class StreamSource:
    """A frame source read in one pass per ``frames()`` call (see the module). Subclasses
    set ``info`` through ``__init__`` and implement ``_items``."""

    def __init__(self, info: SourceInfo, frames: FrameRange) -> None:
        self.info = info
        self.range = frames
        self.notes: list[str] = []
        """Conversions noticed while reading (``info.notes`` has those known at opening)."""
        self._found: dict[str, None] = {}  # notes noticed while reading, in order, once each
        self._resized: Counter[tuple[int, int]] = Counter()

    def _items(self) -> Iterator[tuple[int, Loader]]:
        """Every frame of the source in order, as ``(index, load)``."""
        raise NotImplementedError

    def note(self, text: str) -> None:
        """Add a conversion noticed while reading to ``notes`` (once; a note of
        ``info.notes`` is not repeated)."""
        if text in self.info.notes:
            return
        if text not in self._found:
            self._found[text] = None
            self._refresh()

    def _refresh(self) -> None:
        w0, h0 = self.info.width_px, self.info.height_px
        resized = [f"{n} frame{'s' if n != 1 else ''} of {w}×{h} resized to {w0}×{h0}"
                   for (w, h), n in sorted(self._resized.items())]
        # In place: a caller may hold on to the list.
        self.notes[:] = [*self._found, *resized]

    def frames(self) -> Iterator[SourceFrame]:
        """One pass over the selected range (see ``FrameSource``). Frame sizes resized in
        this pass are counted in ``notes``."""
        start, stop = self.range.start, self.range.stop
        size = (self.info.width_px, self.info.height_px)
        self._resized.clear()
        self._refresh()
        # Frame 0 is at 0 s by definition: a later frame stamped before it goes backwards too.
        last_index, last_t = 0, 0.0
        seen = 0
        items = self._items()
        try:
            for index, load in items:
                seen = index + 1
                if index < start:
                    continue
                if stop is not None and index >= stop:
                    break
                t_s, image = load()
                if t_s < last_t:
                    raise SourceError(
                        f"{self.info.path}: time stamps go backwards at frame {index}: it is "
                        f"stamped {t_s:.6f} s, before frame {last_index} at {last_t:.6f} s "
                        "(from the first frame); the recording's stamps are out of order — "
                        "select frames before it with --frames A:B")
                if not math.isnan(t_s):
                    last_index, last_t = index, t_s
                h, w = image.shape[:2]
                if (w, h) != size:
                    image = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
                    self._resized[(w, h)] += 1
                    self._refresh()
                yield SourceFrame(index, t_s, np.ascontiguousarray(image))
        finally:
            items.close()
        if seen == 0:
            raise SourceError(f"{self.info.path}: a pass over the source gave no frame "
                              "(the file changed since it was opened?)")
        if seen <= start:
            raise start_after_last(self.info.path, seen, self.range)
