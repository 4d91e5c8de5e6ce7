"""Video files (any container and codec OpenCV's ``VideoCapture`` decodes) as a frame
source: time stamps from the container (``CAP_PROP_POS_MSEC``), else the frame's index
over the declared frame rate."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np

from tfalda_sim.sources.base import FrameRange, SourceError, SourceInfo
from tfalda_sim.sources.decode import as_uint8
from tfalda_sim.sources.stream import Loader, StreamSource, range_count

NOT_VIDEO_CODECS = frozenset({"ansi"})
"""Codecs of files ffmpeg opens that are not videos: its tty demuxer shows any text file
as ANSI art."""

REENCODE = "re-encode it, e.g. `ffmpeg -i IN -c:v mpeg4 -q:v 2 OUT.mp4`"
"""What to do with a video this OpenCV cannot decode (as ``tfalda_sim.video``)."""


def _codec(cap: cv2.VideoCapture) -> str:
    fourcc = int(cap.get(cv2.CAP_PROP_FOURCC))
    return "".join(chr((fourcc >> (8 * k)) & 0xFF) for k in range(4)).strip("\x00 ")


def opens_as_video(path: Path) -> bool:
    """OpenCV opens ``path`` as a video (whether any frame decodes is not checked)."""
    cap = cv2.VideoCapture(str(path))
    try:
        return bool(cap.isOpened()) and _codec(cap).lower() not in NOT_VIDEO_CODECS
    finally:
        cap.release()


class VideoSource(StreamSource):
    """A video file's frames as decoded (BGR, or grey for grey codecs). ``rate_hz`` given:
    time stamps are index / rate instead of the container's."""

    def __init__(self, path: Path, *, frames: FrameRange, rate_hz: float | None = None
                 ) -> None:
        self.path = path
        cap = self._open()
        try:
            ok, first = cap.read()
            codec = _codec(cap)
            if not ok or first is None:
                raise SourceError(
                    f"{path}: no frame decodes (codec {codec or 'unknown'!r}, which this "
                    f"OpenCV build cannot decode, or the file is cut short); {REENCODE}")
            fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
            declared = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
            self._t0_ms = float(cap.get(cv2.CAP_PROP_POS_MSEC))
        finally:
            cap.release()
        self.fps = fps if math.isfinite(fps) and fps > 0 else 0.0
        total = declared if declared > 0 else None
        self._declared = total
        notes: list[str] = []
        if rate_hz is not None:
            notes.append(f"time stamps from --rate {rate_hz:g} Hz (index / rate)"
                         + (f"; the file declares {self.fps:g} fps" if self.fps else ""))
        elif not self.fps:
            notes.append("the video declares no frame rate: time stamps from the container "
                         "only")
        self._rate = rate_hz
        image = as_uint8(first)
        super().__init__(SourceInfo(
            path=path, kind="video", width_px=image.shape[1], height_px=image.shape[0],
            frame_count=range_count(path, total, frames),
            rate_hz=rate_hz if rate_hz is not None else (self.fps or None),
            encoding=codec or None, notes=tuple(notes)), frames)

    def _open(self) -> cv2.VideoCapture:
        cap = cv2.VideoCapture(str(self.path))
        if not cap.isOpened():
            cap.release()
            raise SourceError(f"cannot open {self.path}: not a video, or a container or "
                              f"codec this OpenCV build cannot decode; {REENCODE}")
        return cap

    def _t_s(self, index: int, pos_ms: float) -> float:
        """Frame ``index``'s time from the first frame [s]: the container's time stamp
        when it has one (a backend without them reports 0 past the first frame), else
        index / rate."""
        if self._rate is not None:
            return index / self._rate
        if math.isfinite(pos_ms) and (index == 0 or pos_ms > self._t0_ms):
            return (pos_ms - self._t0_ms) / 1000.0
        return index / self.fps if self.fps else math.nan

    def _items(self) -> Iterator[tuple[int, Loader]]:
        cap = self._open()
        try:
            index = 0
            # grab() demuxes without converting; retrieve() only for frames in the range.
            while cap.grab():
                pos_ms = float(cap.get(cv2.CAP_PROP_POS_MSEC))

                def load(index: int = index, pos_ms: float = pos_ms
                         ) -> tuple[float, np.ndarray]:
                    ok, frame = cap.retrieve()
                    if not ok or frame is None:
                        raise SourceError(f"{self.path}: frame {index} does not decode "
                                          f"(the file is damaged there); {REENCODE}")
                    return self._t_s(index, pos_ms), as_uint8(frame)

                yield index, load
                index += 1
            if self._declared is not None and index < self._declared:
                self.note(f"the video ends after {index} of the {self._declared} frames its "
                          "container declares (cut short or damaged)")
        finally:
            cap.release()
