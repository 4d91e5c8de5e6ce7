"""MP4 recording of frame sequences (OpenCV's writer, ``mp4v`` codec)."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from types import TracebackType

import cv2
import numpy as np

from tracks.fileformat import publish

MP4_FOURCC = "mp4v"
"""The codec every OpenCV build can write into an MP4 container."""


class VideoWriter:
    """Write BGR or grey uint8 frames of one size to an MP4 file.

    Frames go to a temporary file next to ``path``, which replaces ``path`` only when
    the writer closes without error: an interrupted recording never destroys an existing
    file. Use as a context manager, or call ``close()``."""

    def __init__(self, path: str | os.PathLike[str], fps: float, *,
                 size: tuple[int, int] | None = None) -> None:
        self.path = Path(path)
        if self.path.suffix.lower() != ".mp4":
            raise ValueError(f"video path must end in .mp4, got {self.path.name!r}")
        if not (np.isfinite(fps) and fps > 0):
            raise ValueError(f"fps must be finite and > 0, got {fps}")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{self.path.stem}.", suffix=".mp4",
                                   dir=self.path.parent)
        os.close(fd)
        self._tmp = Path(tmp)
        self.fps = float(fps)
        self.size = size
        self.frames = 0
        self._writer: cv2.VideoWriter | None = None

    def write(self, frame: np.ndarray) -> None:
        """Append a (h, w) or (h, w, 3) uint8 frame; every frame must have the first's size."""
        if not isinstance(frame, np.ndarray) or frame.dtype != np.uint8 or \
                frame.ndim not in (2, 3) or (frame.ndim == 3 and frame.shape[2] != 3):
            raise ValueError("a video frame must be a uint8 (h, w) or (h, w, 3) array, got "
                             f"{getattr(frame, 'dtype', type(frame).__name__)} "
                             f"{getattr(frame, 'shape', '')}")
        h, w = frame.shape[:2]
        if self.size is None:
            self.size = (w, h)
        if (w, h) != self.size:
            raise ValueError(f"frame size {w}×{h} differs from the video's {self.size[0]}×"
                             f"{self.size[1]}; resize with cv2.resize first")
        if self._writer is None:
            self._writer = cv2.VideoWriter(str(self._tmp), cv2.VideoWriter_fourcc(*MP4_FOURCC),
                                           self.fps, self.size)
            if not self._writer.isOpened():
                raise OSError(f"OpenCV cannot write {MP4_FOURCC} video to {self._tmp}")
        if frame.ndim == 2:
            frame = cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
        self._writer.write(frame)
        self.frames += 1

    def close(self, keep: bool = True) -> None:
        """Finish the file and move it into place (``keep=False``: discard it)."""
        if self._writer is not None:
            self._writer.release()
            self._writer = None
        if keep and self.frames > 0:
            publish(self._tmp, self.path)
        else:
            self._tmp.unlink(missing_ok=True)

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close(keep=exc_type is None)
