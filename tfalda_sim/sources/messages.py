"""What the two readers of recorded messages share (ROS bags through rosbags, MCAP files
through mcap): the first frames' time stamps, a frame's time and image from its message,
and a camera_info that does not decode turned into a note. Each reader supplies its
messages as ``(log time [ns], decode)``, ``decode()`` giving ``(message type, message)``."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

from tfalda_sim.sources.base import CameraInfo, SourceError
from tfalda_sim.sources.decode import (
    COMPRESSED,
    DecodeError,
    encoding_label,
    encoding_note,
    encoding_of,
    image_of,
    stamp_ns,
)
from tfalda_sim.sources.stream import RATE_SAMPLE_FRAMES

Decode = Callable[[], tuple[str, Any]]
"""Deserialises one message: ``(message type, message)``; a ``SourceError`` naming the
file and the frame when it cannot."""


def stamp_or_log_ns(msg: Any, log_ns: int) -> int:
    """A message's ``header.stamp`` [ns], or its log time where it has none (0)."""
    stamp = stamp_ns(msg)
    return stamp if stamp != 0 else log_ns


def first_frames(path: Path, topic: str, messages: Iterable[tuple[int, Decode]]
                 ) -> tuple[tuple[str, Any], list[int], int]:
    """The first message ``(type, message)``, the time stamps [ns] of the first
    ``RATE_SAMPLE_FRAMES`` frames (up to one that does not decode: that frame's error
    belongs to a pass that reaches it), and how many of those had no header stamp."""
    first: tuple[str, Any] | None = None
    stamps: list[int] = []
    logged = 0
    for log_ns, decode in messages:
        try:
            msgtype, msg = decode()
        except SourceError:
            if first is None:
                raise
            break
        if first is None:
            first = (msgtype, msg)
        logged += stamp_ns(msg) == 0 and log_ns != 0
        stamps.append(stamp_or_log_ns(msg, log_ns))
        if len(stamps) >= RATE_SAMPLE_FRAMES:
            break
    if first is None:
        raise SourceError(f"{path}: topic {topic} has no messages; the recording holds no "
                          "frames")
    return first, stamps, logged


def frame_of(path: Path, topic: str, index: int, msgtype: str, msg: Any, log_ns: int,
             stamp0_ns: int) -> tuple[float, np.ndarray]:
    """Frame ``index``'s time from the recording's first frame [s] and its image."""
    try:
        image = image_of(msgtype, msg)
    except DecodeError as exc:
        raise SourceError(f"{path}: frame {index} of {topic}: {exc}; select frames without "
                          "it with --frames A:B") from None
    return (stamp_or_log_ns(msg, log_ns) - stamp0_ns) / 1e9, image


def optional_camera_info(read: Callable[[], CameraInfo | None] | None
                         ) -> tuple[CameraInfo | None, str | None]:
    """The camera_info ``read`` gives (None without a topic) and, when its message does
    not decode, a note saying so: the frames are read without it."""
    if read is None:
        return None, None
    try:
        return read(), None
    except SourceError as exc:
        return None, f"camera_info not used: {exc}"


def first_frame(path: Path, topic: str, first: tuple[str, Any], notes: list[str | None],
                logged: int, sampled: int, rate_hz: float | None
                ) -> tuple[str, np.ndarray, list[str]]:
    """The first frame's encoding label and image (a ``SourceError`` naming the topic when
    it does not decode: nothing of the recording could be read), and the notes of opening:
    ``notes`` given (None: none), the encoding's, ``logged`` of the ``sampled`` first
    frames timed by their log times, a ``--rate`` the recording's stamps replace."""
    msgtype, msg = first
    label = encoding_label(msgtype, msg)
    try:
        if msgtype != COMPRESSED:
            encoding_of(label)
        image = image_of(msgtype, msg)
    except DecodeError as exc:
        raise SourceError(f"{path}: topic {topic}, frame 0: {exc}") from None
    out = [n for n in [encoding_note(label), *notes] if n]
    if logged:
        out.append(f"{logged} of the first {sampled} frames have no header stamp: time "
                   "stamps from the log (receive) times there")
    if rate_hz is not None:
        out.append(f"--rate {rate_hz:g} Hz not used: the recording's time stamps time its "
                   "frames")
    return label, image, out
