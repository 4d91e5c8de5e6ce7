"""Video files: MP4 recording of frame sequences (H.264 through ffmpeg, which browsers play);
reading any recording back is ``tfalda_sim.sources``'.

``VideoWriter`` streams the frames through a pipe to imageio-ffmpeg's bundled ffmpeg
(``libx264``, ``yuv420p``, the index at the file's start), so memory stays bounded however
long the recording, and a write that fails — a full disk, a size limit — shows as
ffmpeg's exit code and message: a ``fileio.WriteError`` naming the file, and no partial
file replaces an existing one. Without ffmpeg (or without libx264 in it) the writer falls
back to MPEG-4 Part 2 (``mp4v``) and says so in one line on stderr.
"""

from __future__ import annotations

import collections
import errno
import functools
import os
import signal
import subprocess
import sys
import threading
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import IO

import cv2
import numpy as np

from tfalda_sim.fileio import WriteError, create_temp, publish, stage, unstage
from tfalda_sim.interrupts import deferring_stops, holding_stops

MP4_FOURCC = "mp4v"
"""The fallback codec: every OpenCV build can write it into an MP4 container."""

H264_CRF: int = 18
"""x264's quality (lower is better): 18 keeps the thin lane markings of a camera video
sharp enough for ``tfalda-sim replay`` to detect as in the live drive."""

H264_PRESET = "veryfast"
"""x264's speed preset: the encoder keeps up with a drive on one core."""


@dataclass(frozen=True)
class Encoder:
    """How videos are written: ``ffmpeg`` (None: OpenCV's writer), its ``codec``
    (``h264`` or ``mp4v``) and, when that is not H.264, ``why``."""

    ffmpeg: str | None
    codec: str
    why: str = ""


@functools.cache
def encoder() -> Encoder:
    """The best way this installation has to write an MP4 (found once per process)."""
    try:
        import imageio_ffmpeg

        exe = imageio_ffmpeg.get_ffmpeg_exe()
    except (ImportError, RuntimeError, OSError) as exc:
        return Encoder(None, MP4_FOURCC, f"no ffmpeg ({_short(exc)}; pip install "
                                         "imageio-ffmpeg)")
    try:
        listing = subprocess.run([exe, "-hide_banner", "-encoders"], capture_output=True,
                                 text=True, timeout=60, check=False,
                                 stdin=subprocess.DEVNULL).stdout
    except (OSError, subprocess.SubprocessError) as exc:
        return Encoder(None, MP4_FOURCC, f"{exe} does not run ({_short(exc)})")
    if " libx264 " not in listing:
        return Encoder(exe, MP4_FOURCC, f"{exe} has no libx264")
    return Encoder(exe, "h264")


def _short(exc: BaseException) -> str:
    return str(exc).splitlines()[0][:120] if str(exc) else type(exc).__name__


_noted: set[str] = set()


def _note_fallback(enc: Encoder) -> None:
    """Say once per process why the videos are not H.264."""
    if enc.why in _noted:
        return
    _noted.add(enc.why)
    print(f"note: writing MP4 videos as MPEG-4 Part 2 (mp4v), which browsers do not play: "
          f"H.264 is unavailable, {enc.why}", file=sys.stderr)


_FAILURES = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.EIO, errno.EACCES)


def _reason(message: str) -> tuple[str, int]:
    """The cause ffmpeg gave for a failed write, as (reason, errno): a system error it
    names (``No space left on device``), or its last line."""
    for code in _FAILURES:
        if os.strerror(code) in message:
            return os.strerror(code), code
    lines = [ln.strip() for ln in message.splitlines() if ln.strip()]
    return (f"ffmpeg failed: {lines[-1][:300]}" if lines else "ffmpeg failed"), 0


class _FfmpegSink:
    """An ffmpeg process encoding raw BGR frames from its stdin into ``path``. It runs in
    its own session: a Ctrl-C to the terminal's process group must not cut the file
    short — the writer finishes it (``finish``) after the command has stopped."""

    STDERR_LINES = 50

    def __init__(self, exe: str, path: Path, size: tuple[int, int], fps: float,
                 codec: str) -> None:
        self.path = path
        w, h = size
        if codec == "h264":
            # yuv420p (what browsers decode) needs even sides: pad by one pixel.
            out = ["-c:v", "libx264", "-preset", H264_PRESET, "-crf", str(H264_CRF),
                   "-pix_fmt", "yuv420p", "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2"]
        else:
            out = ["-c:v", "mpeg4", "-q:v", "2", "-tag:v", "mp4v"]
        cmd = [exe, "-hide_banner", "-nostats", "-loglevel", "error", "-y",
               "-f", "rawvideo", "-pix_fmt", "bgr24", "-s", f"{w}x{h}",
               "-framerate", repr(fps), "-i", "pipe:0", "-an", *out,
               "-movflags", "+faststart", "-f", "mp4", str(path)]
        # restore_signals=False: ffmpeg keeps Python's ignored SIGXFSZ, so a file size
        # limit is a write error it reports, not a silent kill.
        self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
                                     stderr=subprocess.PIPE, start_new_session=True,
                                     restore_signals=False)
        assert self.proc.stdin is not None and self.proc.stderr is not None
        self._stdin: IO[bytes] = self.proc.stdin
        self._errors: collections.deque[str] = collections.deque(maxlen=self.STDERR_LINES)
        # Drained all along: ffmpeg blocked on a full stderr pipe would block our writes.
        self._drain = threading.Thread(target=self._read_errors, args=(self.proc.stderr,),
                                       daemon=True)
        self._drain.start()

    def _read_errors(self, stream: IO[bytes]) -> None:
        with stream:
            for line in stream:
                self._errors.append(line.decode("utf-8", "replace"))

    def _failure(self) -> WriteError:
        self._drain.join(timeout=10)
        status = self.proc.returncode
        if status == -signal.SIGXFSZ:
            return WriteError(self.path, os.strerror(errno.EFBIG), errno.EFBIG)
        if status is not None and status < 0 and not self._errors:
            return WriteError(self.path, f"ffmpeg was killed by {signal.Signals(-status).name}")
        reason, code = _reason("".join(self._errors))
        return WriteError(self.path, reason, code)

    def write(self, frame: np.ndarray) -> None:
        try:
            self._stdin.write(frame.tobytes())
        except (BrokenPipeError, ValueError):
            # ffmpeg has ended early: it has said why.
            self.abort()
            raise self._failure() from None
        except OSError as exc:
            self.abort()
            raise WriteError.of(self.path, exc) from None

    def finish(self) -> None:
        """Close the pipe and wait for the file; a ``WriteError`` if ffmpeg failed."""
        try:
            self._stdin.close()
        except OSError:
            pass  # a broken pipe: the exit code below says what happened
        if self.proc.wait() != 0:
            raise self._failure()
        self._drain.join(timeout=10)

    def abort(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        try:
            self._stdin.close()
        except OSError:
            pass
        self.proc.wait()
        self._drain.join(timeout=10)


class _OpenCvSink:
    """OpenCV's ``mp4v`` writer, when there is no ffmpeg. OpenCV only warns when a frame
    cannot be written, so the file is checked when it is finished: it must open and hold
    every frame written."""

    def __init__(self, path: Path, size: tuple[int, int], fps: float) -> None:
        self.path = path
        self.frames = 0
        self.writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*MP4_FOURCC), fps,
                                      size)
        if not self.writer.isOpened():
            raise WriteError(path, f"OpenCV cannot write {MP4_FOURCC} video there")

    def write(self, frame: np.ndarray) -> None:
        self.writer.write(frame)
        self.frames += 1

    def finish(self) -> None:
        self.writer.release()
        cap = cv2.VideoCapture(str(self.path))
        try:
            found = int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) if cap.isOpened() else 0
        finally:
            cap.release()
        if found != self.frames:
            try:
                st = os.statvfs(self.path.parent)
                full = st.f_bavail * st.f_frsize < 1 << 20
            except OSError:
                full = False
            raise WriteError(self.path, os.strerror(errno.ENOSPC) if full else
                             f"the file holds {found} of the {self.frames} frames written",
                             errno.ENOSPC if full else 0)

    def abort(self) -> None:
        self.writer.release()


class VideoWriter:
    """Write BGR or grey uint8 frames of one size to an MP4 file (H.264; see the module).

    Frames go to a temporary file next to ``path``, which replaces ``path`` only when
    the writer closes without error: an interrupted recording never destroys an existing
    file, and a failed write (a full disk) is a ``fileio.WriteError`` naming ``path``.
    Use as a context manager, or call ``close()``."""

    def __init__(self, path: str | os.PathLike[str], fps: float, *,
                 size: tuple[int, int] | None = None) -> None:
        self.path = Path(path)
        if self.path.suffix.lower() != ".mp4":
            raise ValueError(f"video path must end in .mp4, got {self.path.name!r}")
        if not (np.isfinite(fps) and fps > 0):
            raise ValueError(f"fps must be finite and > 0, got {fps}")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            fd, self._tmp = create_temp(self.path.parent, ".mp4")
        except OSError as exc:
            raise WriteError.of(self.path, exc) from None
        os.close(fd)
        stage(self._tmp, self.path)  # an error about the temporary file names ``path``
        self.fps = float(fps)
        self.size = size
        self.frames = 0
        self.codec = encoder().codec
        self._sink: _FfmpegSink | _OpenCvSink | None = None
        self._failed: WriteError | None = None

    def _open(self) -> _FfmpegSink | _OpenCvSink:
        assert self.size is not None
        enc = encoder()
        if enc.codec != "h264":
            _note_fallback(enc)
        if enc.ffmpeg is None:
            return _OpenCvSink(self._tmp, self.size, self.fps)
        return _FfmpegSink(enc.ffmpeg, self._tmp, self.size, self.fps, enc.codec)

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
        if self._failed is not None:
            raise self._failed
        if frame.ndim == 2:
            frame = cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
        try:
            # A frame goes whole or not at all, and is counted: a Ctrl-C in the middle of
            # one would leave a torn frame at the end of the pipe, which ffmpeg reports as
            # an error; one while ffmpeg starts would lose track of the process.
            with deferring_stops():
                if self._sink is None:
                    self._sink = self._open()
                self._sink.write(np.ascontiguousarray(frame))
                self.frames += 1
        except WriteError as exc:
            self._sink, self._failed = None, exc
            self._tmp.unlink(missing_ok=True)
            raise

    def close(self, keep: bool = True) -> None:
        """Finish the file and move it into place (``keep=False``: discard it). A write
        that failed is a ``WriteError`` naming the file; the temporary file is gone then,
        and an existing file at ``path`` untouched."""
        sink, self._sink = self._sink, None
        # Finishing the file must not be cut by a Ctrl-C: it would lose every frame.
        with holding_stops():
            try:
                if sink is not None:
                    if keep:
                        sink.finish()
                    else:
                        sink.abort()
                if keep and self.frames > 0 and self._failed is None:
                    publish(self._tmp, self.path)
            except OSError as exc:
                raise WriteError.of(self.path, exc) from None
            finally:
                self._tmp.unlink(missing_ok=True)
                unstage(self._tmp)

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close(keep=exc_type is None)


GREY_TOLERANCE_DN: int = 3
"""A three-channel frame whose channels differ by at most this [DN] is a grey video stored
as BGR (lossy codecs leave a little chroma noise), not a colour one."""


def is_grey(frame: np.ndarray) -> bool:
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
