"""A folder of images or a glob pattern (``"clip/*.png"``) as a frame source, in natural
order (``frame_2`` before ``frame_10``).

Time stamps: ``--rate HZ`` (frame k at k / rate), else the file names when every name
carries a time-stamp-like number (``frame_1712345678123456789.png``: ns, µs, ms or s by
magnitude; ``1712345678.123.png``: s), else none (NaN, and a note asking for ``--rate``).
"""

from __future__ import annotations

import glob
import math
import re
from collections.abc import Iterator, Sequence
from decimal import Decimal
from pathlib import Path

import cv2
import numpy as np
from natsort import natsorted, ns

from tfalda_sim.sources.base import FrameRange, SourceError, SourceInfo
from tfalda_sim.sources.decode import as_uint8
from tfalda_sim.sources.stream import Loader, StreamSource, median_rate_hz, range_count

IMAGE_SUFFIXES = frozenset({".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm",
                            ".ppm", ".pbm", ".pnm", ".webp", ".jp2"})
"""The files of a folder read as frames (a glob pattern takes every file it matches)."""

NO_STAMPS = "no time stamps: give --rate HZ"

_NUMBER = re.compile(r"(?<!\d)(\d+)(?:\.(\d+))?(?!\d)")

# An integer stamp's unit by its magnitude (epoch times since 2001 have 10 digits in s):
# upper bound (exclusive) → ns per unit.
_UNITS = ((10**11, 1_000_000_000), (10**14, 1_000_000), (10**17, 1_000), (10**20, 1))


def name_stamp_ns(stem: str) -> int | None:
    """The time stamp a file name (without its suffix) carries [ns], or None: its last
    number that is a decimal (seconds: ``1712345678.123``, ``0.040``) or an integer of 10
    to 19 digits (an epoch time in s, ms, µs or ns by its magnitude)."""
    found = None
    for m in _NUMBER.finditer(stem):
        whole, frac = m.group(1), m.group(2)
        if frac is not None:
            found = int(Decimal(f"{whole}.{frac}") * 1_000_000_000)
            continue
        if len(whole) < 10 or whole.startswith("0"):
            continue  # a frame number, not a time
        value = int(whole)
        for bound, ns_per_unit in _UNITS:
            if value < bound:
                found = value * ns_per_unit
                break
    return found


def _listing(files: Sequence[Path]) -> str:
    names = ", ".join(p.name for p in files[:3])
    return names + (f", … ({len(files)} files)" if len(files) > 3 else "")


def folder_images(folder: Path) -> list[Path]:
    """The image files of ``folder`` (by suffix; hidden files such as macOS's ``._*``
    left out), in natural order; a ``SourceError`` when there are none."""
    try:
        entries = [p for p in folder.iterdir() if not p.name.startswith(".")]
    except OSError as exc:
        raise SourceError(f"cannot list {folder}: {exc.strerror or exc}") from None
    files = [p for p in entries if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file()]
    if not files:
        others = natsorted((p for p in entries if p.is_file()), alg=ns.PATH)
        held = f" (it holds {_listing(others)})" if others else " (it is empty)"
        raise SourceError(
            f"{folder} holds no images ({', '.join(sorted(s[1:] for s in IMAGE_SUFFIXES))})"
            f"{held}; give a folder of images, a glob pattern such as '{folder}/*.png', a "
            "video file, a ROS bag or an MCAP file")
    return natsorted(files, alg=ns.PATH)


def glob_images(pattern: str) -> list[Path]:
    """The files a glob pattern matches (``**`` recursive), in natural order; a
    ``SourceError`` when it matches none."""
    files = [Path(p) for p in glob.glob(pattern, recursive=True)]
    files = [p for p in files if p.is_file()]
    if not files:
        raise SourceError(f"the pattern {pattern!r} matches no file; give a folder of images "
                          "or a pattern such as 'clip/*.png' (quote it for the shell)")
    return natsorted(files, alg=ns.PATH)


DEEP_NOTE = "images of more than 8 bits → 8 bit: the top byte of each pixel"


def read_image(path: Path) -> tuple[np.ndarray, bool]:
    """One image file as uint8 grey or BGR, and whether it had more than 8 bits; a
    ``SourceError`` naming it when it is not an image."""
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        reason = "no such file" if not path.exists() else \
            "not an image OpenCV can read (PNG, JPEG, …), or damaged"
        raise SourceError(f"{path}: {reason}; replace it or remove it from the frames")
    return as_uint8(image), image.dtype != np.uint8


class ImageSource(StreamSource):
    """Image files as frames, in the order given (``folder_images``, ``glob_images``).
    ``path`` is what the user gave (the folder or the pattern)."""

    def __init__(self, path: Path, files: list[Path], *, frames: FrameRange,
                 rate_hz: float | None = None) -> None:
        self.files = files
        count = range_count(path, len(files), frames)
        first, deep = read_image(files[0])
        notes: list[str] = [DEEP_NOTE] if deep else []
        self._stamps_ns: list[int] | None = None
        self._rate = rate_hz
        if rate_hz is not None:
            notes.append(f"time stamps from --rate {rate_hz:g} Hz (index / rate)")
            rate: float | None = rate_hz
        else:
            self._stamps_ns = self._name_stamps(path, files)
            rate = None if self._stamps_ns is None else median_rate_hz(self._stamps_ns)
            if self._stamps_ns is None:
                notes.append(NO_STAMPS)
            else:
                notes.append("time stamps from the file names")
        super().__init__(SourceInfo(
            path=path, kind="images", width_px=first.shape[1], height_px=first.shape[0],
            frame_count=count, rate_hz=rate, notes=tuple(notes)), frames)

    @staticmethod
    def _name_stamps(path: Path, files: list[Path]) -> list[int] | None:
        """The file names' time stamps [ns] when every name carries a distinct one."""
        stamps = []
        for f in files:
            stamp = name_stamp_ns(f.stem)
            if stamp is None:
                return None
            stamps.append(stamp)
        if len(set(stamps)) < len(stamps):
            return None  # one number shared by names (a run's epoch) times no frame
        for k in range(1, len(stamps)):
            if stamps[k] < stamps[k - 1]:
                raise SourceError(
                    f"{path}: the file names' time stamps go backwards at frame {k}: "
                    f"{files[k].name} ({stamps[k]} ns) comes after {files[k - 1].name} "
                    f"({stamps[k - 1]} ns) in natural order; rename the files, or give "
                    "--rate HZ to time them by their order")
        return stamps

    def _t_s(self, index: int) -> float:
        if self._rate is not None:
            return index / self._rate
        if self._stamps_ns is None:
            return math.nan
        return (self._stamps_ns[index] - self._stamps_ns[0]) / 1e9

    def _items(self) -> Iterator[tuple[int, Loader]]:
        for index, file in enumerate(self.files):
            def load(index: int = index, file: Path = file) -> tuple[float, np.ndarray]:
                image, deep = read_image(file)
                if deep:
                    self.note(DEEP_NOTE)
                return self._t_s(index), image

            yield index, load
