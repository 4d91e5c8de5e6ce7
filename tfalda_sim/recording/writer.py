"""``Recorder``: a run's steps written as a plain MCAP file or a ROS 2 bag folder, under
the house rules for outputs (``tfalda_sim.outputs``).

- **Nothing half-written in place.** The recording grows under a temporary name beside its
  target (``fileio.create_temp``; a bag in a temporary folder) and takes the target's
  place on ``close(keep=True)``: an existing file or bag is replaced only by a finished
  recording. ``close(keep=False)`` leaves nothing.
- **A failed write names the target.** A full disk, a file size limit or a failing disk
  is a ``fileio.WriteError`` naming the file (or bag folder) asked for, raised by the
  ``write`` or ``close`` that hit it; the temporary file is gone then and the target
  untouched.
- **Ctrl-C keeps the finished frames.** A step goes to the file whole or not at all (the
  stop is deferred while it is written), so a caller that catches the interrupt and calls
  ``close(keep=True)`` gets a valid recording of every step written before it.
- **Bounded memory**: the file is streamed in compressed chunks (``sinks``).

How a reader finds the camera: a plain MCAP carries a metadata record ``METADATA_NAME``
(``camera_topic``, ``source``, ``version``); a bag the ``custom_data`` key
``CUSTOM_DATA_KEY`` (and ``tfalda_sim.source``, ``tfalda_sim.version``) in its
``metadata.yaml``.
"""

from __future__ import annotations

import contextlib
import enum
import os
import shutil
import time
from pathlib import Path
from types import TracebackType
from typing import IO

from tfalda_sim import __version__
from tfalda_sim.fileio import (
    WriteError,
    create_temp,
    publish,
    remove_stale_temps,
    stage,
    temp_path,
    unstage,
)
from tfalda_sim.interrupts import deferring_stops, holding_stops
from tfalda_sim.recording.channels import CAMERA_IMAGE, StepMessages, offset_ns
from tfalda_sim.recording.messages import typestore
from tfalda_sim.recording.sinks import BagSink, McapSink, Sink
from tfalda_sim.recording.step import RecordedStep
from tfalda_sim.sources.base import CameraInfo

CAMERA_TOPIC = CAMERA_IMAGE.topic
"""The camera's topic; a recording names it in its metadata (a reader's way to tell it
from the top view's)."""

METADATA_NAME = "tfalda-sim"
"""A plain MCAP's metadata record: ``camera_topic``, ``source``, ``version``."""

CUSTOM_DATA_KEY = "tfalda_sim.camera_topic"
"""A bag's ``custom_data`` key for the camera topic (beside ``tfalda_sim.source`` and
``tfalda_sim.version``)."""

MCAP_SUFFIX = ".mcap"

BAG_MARKER = "metadata.yaml"
"""A folder with this file is a ROS 2 bag, which a new bag may replace."""


class RecordingFormat(enum.Enum):
    """What a ``Recorder`` writes: a plain MCAP file (``--mcap FILE``) or a ROS 2 bag
    folder with MCAP storage (``--rosbag DIR``)."""

    MCAP = "mcap"
    ROSBAG = "rosbag"


def _check_bag_target(path: Path) -> None:
    """A bag may replace nothing but a bag or an empty folder: refuse any other thing."""
    if path.is_symlink() or (path.exists() and not path.is_dir()):
        raise WriteError(path, "a file is in its place, not a ROS 2 bag folder; choose "
                               "another path")
    if path.is_dir() and not (path / BAG_MARKER).is_file() and any(path.iterdir()):
        raise WriteError(path, f"the folder is not a ROS 2 bag (no {BAG_MARKER}) and not "
                               "empty; choose another path")


class Recorder:
    """Write ``RecordedStep``s to ``path`` as ``fmt`` (see the module and
    ``tfalda_sim.recording.channels`` for the channels). Use as a context manager (any
    exception, a Ctrl-C too, discards the recording), or call ``close()``: a command that
    survives a Ctrl-C catches it and calls ``close(keep=True)``, which keeps every step
    written before it.

    ``path``: a ``.mcap`` file, or the bag's folder (which may replace only an earlier
    bag or an empty folder); ``camera_info``: written with every frame on
    ``/camera/camera_info`` (its size must be the frames'); ``source``: what the frames
    are (a track and seed, a replayed file), in the metadata; ``compress_frames``:
    ``"png"`` (lossless, the default: a replay detects exactly as the run did) or
    ``"jpeg"`` (smaller; not frame-identical); ``start_ns``: the run's start as a time
    stamp [ns since the Unix epoch] (None: now; give one for byte-identical files).
    ``frames``: steps written so far."""

    def __init__(self, path: str | os.PathLike[str], fmt: RecordingFormat, *,
                 camera_info: CameraInfo | None = None, source: str = "",
                 compress_frames: str = "png", start_ns: int | None = None) -> None:
        self.path = Path(path)
        self.format = RecordingFormat(fmt)
        if self.format is RecordingFormat.MCAP and self.path.suffix.lower() != MCAP_SUFFIX:
            raise ValueError(f"an MCAP recording's path must end in {MCAP_SUFFIX}, got "
                             f"{self.path.name!r}")
        self._encoder = StepMessages(camera_info=camera_info, image_format=compress_frames)
        typestore()  # the types are built now, not within the first frame
        self.camera_info = camera_info
        self.source = source
        self.start_ns = time.time_ns() if start_ns is None else int(start_ns)
        if self.start_ns < 0:
            raise ValueError(f"start_ns must be ≥ 0 [ns since the Unix epoch], got {start_ns}")
        self.frames = 0
        self._last_ns = -1
        self._size: tuple[int, int] | None = None
        self._failed: BaseException | None = None
        self._closed = False
        self._stream: IO[bytes] | None = None
        self._staged: list[Path] = []
        self._tmp: Path  # the temporary file (MCAP) or folder (a bag's scratch folder)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            if self.format is RecordingFormat.MCAP:
                self._sink: Sink | None = self._open_mcap()
            else:
                self._sink = self._open_bag()
        except OSError as exc:
            self._discard()
            raise WriteError.of(self.path, exc) from None
        except BaseException:
            self._discard()
            raise

    # -- opening and putting in place -------------------------------------------------------

    def _stage(self, tmp: Path) -> None:
        stage(tmp, self.path)  # an error about ``tmp`` names the target
        self._staged.append(tmp)

    def _metadata(self) -> dict[str, str]:
        return {"camera_topic": CAMERA_TOPIC, "source": self.source, "version": __version__}

    def _open_mcap(self) -> McapSink:
        if self.path.is_dir():
            raise WriteError(self.path, "a folder is in its place; give a file name")
        fd, self._tmp = create_temp(self.path.parent, MCAP_SUFFIX)
        self._stage(self._tmp)
        self._stream = os.fdopen(fd, "wb")
        return McapSink(self._stream, library=f"tfalda-sim {__version__}",
                        metadata_name=METADATA_NAME, metadata=self._metadata())

    def _open_bag(self) -> BagSink:
        _check_bag_target(self.path)
        remove_stale_temps(self.path.parent)
        self._tmp = temp_path(self.path.parent)
        self._tmp.mkdir(mode=0o700)
        self._stage(self._tmp)
        # The bag is built under the target's own name inside the scratch folder: its
        # MCAP file is named after the folder (NAME/NAME.mcap), as it will be in place.
        bag = BagSink(self._tmp / self.path.name, custom_data={
            f"tfalda_sim.{k}": v for k, v in self._metadata().items()})
        for p in (bag.path, *bag.files):
            self._stage(p)
        return bag

    def _publish(self) -> None:
        """Put the finished recording in place in one step (a bag: the old one moved
        aside into the scratch folder first, put back if the new one cannot go in)."""
        if self.format is RecordingFormat.MCAP:
            publish(self._tmp, self.path)
            return
        built = self._tmp / self.path.name
        old = self._tmp / ".replaced"
        _check_bag_target(self.path)  # what was there may have changed since the start
        replacing = self.path.exists()
        if replacing:
            os.rename(self.path, old)
        try:
            os.rename(built, self.path)
        except OSError:
            if replacing:
                os.rename(old, self.path)
            raise

    def _discard(self) -> None:
        """Remove the temporary file or folder (and the bag replaced, if any)."""
        if self._stream is not None:
            stream, self._stream = self._stream, None
            with contextlib.suppress(OSError):
                stream.close()  # a buffer that cannot be flushed: the file goes anyway
        tmp = getattr(self, "_tmp", None)
        if tmp is not None:
            if tmp.is_dir() and not tmp.is_symlink():
                shutil.rmtree(tmp, ignore_errors=True)
            else:
                tmp.unlink(missing_ok=True)
        for p in self._staged:
            unstage(p)
        self._staged.clear()

    def _fail(self, exc: BaseException) -> None:
        """A write went wrong: the file is unusable; drop it, remember why."""
        self._failed = exc
        sink, self._sink = self._sink, None
        if sink is not None:
            sink.abort()
        self._discard()

    # -- writing ------------------------------------------------------------------------------

    def _check(self, step: RecordedStep, ns: int) -> None:
        if ns <= self._last_ns:
            raise ValueError(f"steps must come in time order: t_s {step.t_s} s is not after "
                             f"the previous step's {(self._last_ns - self.start_ns) / 1e9} s")
        h, w = step.frame.shape
        if self._size is None:
            info = self.camera_info
            if info is not None and (info.width_px, info.height_px) != (w, h):
                raise ValueError(f"frame size {w}×{h} px differs from camera_info's "
                                 f"{info.width_px}×{info.height_px} px")
            self._size = (w, h)
        elif (w, h) != self._size:
            raise ValueError(f"frame size {w}×{h} px differs from the recording's "
                             f"{self._size[0]}×{self._size[1]} px")

    def write(self, step: RecordedStep) -> None:
        """Append one step: its messages on every channel it has data for."""
        if self._closed:
            raise ValueError(f"the recorder of {self.path} is closed")
        if self._failed is not None:
            raise self._failed
        ns = self.start_ns + offset_ns(step.t_s)
        self._check(step, ns)
        # Encoded and serialized first (the slow part, which may be interrupted freely),
        # then written whole under a deferred stop: an interrupt inside the writer would
        # leave a torn chunk that no reader can read past.
        store = typestore()
        payload = [(ch, bytes(store.serialize_cdr(msg, ch.msgtype)))
                   for ch, msg in self._encoder.messages(step, ns)]
        assert self._sink is not None
        try:
            with deferring_stops():
                for ch, data in payload:
                    self._sink.write(ch, ns, data)
                self.frames += 1
                self._last_ns = ns
        except OSError as exc:
            err = WriteError.of(self.path, exc)
            self._fail(err)
            raise err from None
        except Exception as exc:
            self._fail(exc)
            raise

    def close(self, keep: bool = True) -> None:
        """Finish the recording and put it in place (``keep=False``: discard it). Nothing
        is written when no step was, or when a write failed (which raised then). A write
        failing here is a ``WriteError`` naming the target; the target is untouched then.
        Calling it again does nothing."""
        if self._closed:
            return
        self._closed = True
        sink, self._sink = self._sink, None
        # Finishing must not be cut by a Ctrl-C: the index written last makes the file.
        with holding_stops():
            try:
                if sink is not None:
                    if keep and self.frames > 0:
                        try:
                            sink.finish()
                        except BaseException:
                            sink.abort()  # its files closed: the scratch goes below
                            raise
                        if self._stream is not None:
                            stream, self._stream = self._stream, None
                            stream.close()
                        self._publish()
                    else:
                        sink.abort()
            except OSError as exc:
                raise WriteError.of(self.path, exc) from None
            finally:
                self._discard()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close(keep=exc_type is None)
