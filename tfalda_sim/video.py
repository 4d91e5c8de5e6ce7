"""Video files: MP4 recording of frame sequences (OpenCV's writer, ``mp4v`` codec) and
reading a recording back as the camera's grey 752×480 frames (``VideoReader``)."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType

import cv2
import numpy as np

from tfalda_sim.fileio import publish

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
        fd, tmp = tempfile.mkstemp(prefix=".tfalda-sim-", suffix=".mp4",
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


class VideoError(ValueError):
    """A video file that cannot be read: not a video, or a codec this OpenCV cannot decode."""


_REENCODE = "re-encode it, e.g. `ffmpeg -i IN -c:v mpeg4 -q:v 2 OUT.mp4`"


@dataclass(frozen=True)
class VideoInfo:
    """What a video file holds (as OpenCV reports it)."""

    width_px: int
    height_px: int
    fps: float
    """Frame rate the file declares [1/s] (0 when it declares none)."""
    frame_count: int
    """Frames the container declares (an estimate for some formats)."""
    codec: str
    """FOURCC of the video stream, e.g. ``mp4v``."""
    colour: bool
    """The first frame has three or four channels that differ (judged on that frame)."""


class VideoReader:
    """Read a video file as uint8 grey frames of ``size`` = (width, height) [px].

    Colour frames are converted to grey and frames of another size are resized
    (``INTER_AREA``); ``conversions`` says which happened. Opening checks that the file
    exists, is a video OpenCV can open, and that its first frame decodes, so a missing
    file, a file that is not a video and an unknown codec fail here with a
    ``FileNotFoundError`` / ``VideoError`` that says what to do."""

    def __init__(self, path: str | os.PathLike[str], *, size: tuple[int, int] = (752, 480)
                 ) -> None:
        self.path = Path(path)
        self.size = (int(size[0]), int(size[1]))
        if not self.path.exists():
            raise FileNotFoundError(f"no video file {self.path}")
        if not self.path.is_file():
            raise VideoError(f"{self.path} is not a file; give a video file (.mp4, .avi, …)")
        cap = self._open()
        try:
            ok, first = cap.read()
            fourcc = int(cap.get(cv2.CAP_PROP_FOURCC))
            codec = "".join(chr((fourcc >> (8 * k)) & 0xFF) for k in range(4)).strip("\x00 ")
            if not ok or first is None:
                raise VideoError(
                    f"{self.path}: no frame decodes (codec {codec or 'unknown'!r}, which this "
                    f"OpenCV build cannot decode, or the file is cut short); {_REENCODE}")
            self.info = VideoInfo(
                width_px=first.shape[1], height_px=first.shape[0],
                fps=float(cap.get(cv2.CAP_PROP_FPS) or 0.0),
                frame_count=max(0, int(cap.get(cv2.CAP_PROP_FRAME_COUNT))), codec=codec,
                colour=first.ndim == 3 and first.shape[2] in (3, 4)
                and not _is_grey(first))
        finally:
            cap.release()
        self.passes_completed = 0
        self.conversions: list[str] = []
        if self.info.colour:
            self.conversions.append("colour → grey")
        if (self.info.width_px, self.info.height_px) != self.size:
            self.conversions.append(f"{self.info.width_px}×{self.info.height_px} → "
                                    f"{self.size[0]}×{self.size[1]} px")
            if abs(self.info.width_px / self.info.height_px - self.size[0] / self.size[1]) \
                    > 0.01:
                self.conversions.append("aspect ratio changed")

    def _open(self) -> cv2.VideoCapture:
        cap = cv2.VideoCapture(str(self.path))
        if not cap.isOpened():
            cap.release()
            raise VideoError(f"cannot open {self.path}: not a video, or a container or codec "
                             f"this OpenCV build cannot decode; {_REENCODE}")
        return cap

    def convert(self, frame: np.ndarray) -> np.ndarray:
        """One decoded frame as grey uint8 of ``size``."""
        if frame.ndim == 3:
            code = cv2.COLOR_BGRA2GRAY if frame.shape[2] == 4 else cv2.COLOR_BGR2GRAY
            frame = cv2.cvtColor(frame, code) if frame.shape[2] != 1 else frame[..., 0]
        if frame.dtype != np.uint8:  # 16-bit video: keep the top byte
            frame = (frame >> 8).astype(np.uint8) if frame.dtype == np.uint16 else \
                cv2.convertScaleAbs(frame)
        if (frame.shape[1], frame.shape[0]) != self.size:
            frame = cv2.resize(frame, self.size, interpolation=cv2.INTER_AREA)
        return np.ascontiguousarray(frame)

    def frames(self) -> Iterator[np.ndarray]:
        """One pass over the file, converted frames."""
        cap = self._open()
        try:
            while True:
                ok, frame = cap.read()
                if not ok or frame is None:
                    return
                yield self.convert(frame)
        finally:
            cap.release()

    def loop(self, loops: int | None = None) -> Iterator[tuple[int, np.ndarray]]:
        """``(loop, frame)`` over ``loops`` passes (``None``: endlessly), the file read
        again from its start after its last frame; ``passes_completed`` counts the passes
        read to their end."""
        if loops is not None and loops < 1:
            raise ValueError(f"loops must be ≥ 1 or None (endless), got {loops}")
        self.passes_completed = 0
        while loops is None or self.passes_completed < loops:
            empty = True
            for frame in self.frames():
                empty = False
                yield self.passes_completed, frame
            if empty:
                raise VideoError(f"{self.path}: a pass over the file gave no frame")
            self.passes_completed += 1


GREY_TOLERANCE_DN: int = 3
"""A three-channel frame whose channels differ by at most this [DN] is a grey video stored
as BGR (lossy codecs leave a little chroma noise), not a colour one."""


def _is_grey(frame: np.ndarray) -> bool:
    """The frame's channels are equal within ``GREY_TOLERANCE_DN``."""
    c = frame[..., :3].astype(np.int16)
    return bool(np.abs(c - c[..., :1]).max() <= GREY_TOLERANCE_DN)


class ImageError(ValueError):
    """An image file that cannot be read as a grey frame; the message names the file."""


def read_grey_image(path: Path) -> np.ndarray:
    """``path`` (PNG, JPEG, …; 8 or 16 bit, grey or colour) as an 8-bit grey image."""
    if not path.exists():
        raise ImageError(f"{path}: no such file")
    if path.is_dir():
        raise ImageError(f"{path}: is a folder, not an image")
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ImageError(f"{path}: not an image OpenCV can read (PNG, JPEG, …)")
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY if img.shape[2] == 4 else cv2.COLOR_BGR2GRAY)
    if img.dtype == np.uint16:
        img = (img >> 8).astype(np.uint8)
    if img.dtype != np.uint8:
        raise ImageError(f"{path}: {img.dtype} images are not supported; give 8 or 16 bit")
    return img
