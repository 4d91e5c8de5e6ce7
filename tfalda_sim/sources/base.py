"""What every frame source gives: frames with the recording's time stamps, what the source
is (``SourceInfo``), and the frame range a user selects (``FrameRange``, ``--frames A:B``).

A source yields its frames as decoded (grey ``(H, W)`` or BGR ``(H, W, 3)``, uint8); the
conversion to a camera's grey size is ``to_grey`` — one place for every source, so a
recording replays exactly as its frames would directly.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import cv2
import numpy as np


class SourceError(ValueError):
    """A recording, folder or topic that cannot be read as frames; the message names the
    file and says what to do."""


@dataclass(frozen=True)
class FrameRange:
    """Frames ``start`` (inclusive) to ``stop`` (exclusive; None: to the end), counted
    from 0 in the source's own order — ``--frames A:B`` as a Python slice."""

    start: int = 0
    stop: int | None = None

    def __post_init__(self) -> None:
        if self.start < 0 or (self.stop is not None and self.stop <= self.start):
            raise ValueError(f"frame range {self}: needs 0 ≤ A < B")

    def __str__(self) -> str:
        return f"{self.start}:{'' if self.stop is None else self.stop}"

    def __contains__(self, index: int) -> bool:
        return index >= self.start and (self.stop is None or index < self.stop)

    @classmethod
    def parse(cls, text: str) -> FrameRange:
        """``"A:B"``, ``"A:"``, ``":B"``; raises ``ValueError`` with the accepted forms."""
        m = re.fullmatch(r"\s*(\d*)\s*:\s*(\d*)\s*", text)
        if m is None or not (m.group(1) or m.group(2)):
            raise ValueError(f"{text!r} is not a frame range; give A:B (frames A to B−1, "
                             "counted from 0), A: or :B")
        start = int(m.group(1)) if m.group(1) else 0
        stop = int(m.group(2)) if m.group(2) else None
        if stop is not None and stop <= start:
            raise ValueError(f"frame range {text!r} is empty: B must be greater than A")
        return cls(start, stop)


@dataclass(frozen=True)
class CameraInfo:
    """A recording's ``sensor_msgs/CameraInfo`` (the camera package turns it into
    intrinsics): size [px], K (3×3) [px], D, and ROS's ``distortion_model``
    (``plumb_bob``, ``equidistant``, …)."""

    width_px: int
    height_px: int
    K: np.ndarray
    D: np.ndarray
    distortion_model: str


@dataclass(frozen=True)
class SourceFrame:
    """One frame: its position in the source (0-based, before any range), its time stamp
    from the recording's first frame [s], and the image as decoded (uint8, grey
    ``(H, W)`` or BGR ``(H, W, 3)``)."""

    index: int
    t_s: float
    image: np.ndarray


@dataclass(frozen=True)
class SourceInfo:
    """What a source is. ``kind``: ``video``, ``images``, ``ros1``, ``ros2-sqlite3``,
    ``ros2-mcap`` or ``mcap``; ``topic`` and ``message_type`` for recordings;
    ``frame_count`` the frames in the selected range when known; ``rate_hz`` the
    recording's own frame rate (from its time stamps; a video's declared rate; None when
    unknown); ``camera_info`` from a ``camera_info`` topic beside the image topic."""

    path: Path
    kind: str
    width_px: int
    height_px: int
    frame_count: int | None
    rate_hz: float | None
    topic: str | None = None
    message_type: str | None = None
    encoding: str | None = None
    camera_info: CameraInfo | None = None
    notes: tuple[str, ...] = field(default=())
    """Conversions and facts to state in the output (a Bayer pattern demosaiced, frames
    of a changing size resized, time stamps taken from ``--rate``)."""


class FrameSource(Protocol):
    """A recording read as frames: ``frames()`` is one pass over the selected range, and
    can be called again (``replay --loops``). ``notes``: conversions noticed while reading
    (frames of another size resized, with counts); ``info.notes`` has those known at
    opening."""

    info: SourceInfo
    notes: list[str]

    def frames(self) -> Iterator[SourceFrame]: ...


def to_grey(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """A decoded frame as contiguous grey uint8 of ``size`` = (width, height) [px]: colour
    to grey, then ``INTER_AREA`` resizing (the detectors see the same frame from every
    source)."""
    if image.ndim == 3:
        if image.shape[2] == 1:
            image = image[..., 0]
        else:
            code = cv2.COLOR_BGRA2GRAY if image.shape[2] == 4 else cv2.COLOR_BGR2GRAY
            image = cv2.cvtColor(image, code)
    if image.dtype != np.uint8:
        image = (image >> 8).astype(np.uint8) if image.dtype == np.uint16 else \
            cv2.convertScaleAbs(image)
    if (image.shape[1], image.shape[0]) != tuple(size):
        image = cv2.resize(image, tuple(size), interpolation=cv2.INTER_AREA)
    return np.ascontiguousarray(image)
