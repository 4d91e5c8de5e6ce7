"""``open_source``: a recording's kind found from its content (magic bytes, a bag folder's
metadata.yaml), not only its name, and opened as a frame source."""

from __future__ import annotations

import math
from pathlib import Path

import cv2

from tfalda_sim.sources.base import FrameRange, FrameSource, SourceError
from tfalda_sim.sources.images import ImageSource, folder_images, glob_images
from tfalda_sim.sources.mcap_file import McapSource
from tfalda_sim.sources.ros import RosBagSource
from tfalda_sim.sources.video import REENCODE, VideoSource, opens_as_video

KINDS = ("a video file (mp4, avi, mkv, … — any OpenCV decodes), a folder of images or a "
         "glob pattern ('clip/*.png'), a ROS 1 bag (.bag), a ROS 2 bag folder (with its "
         "metadata.yaml; sqlite3 or mcap storage) or an MCAP file (.mcap)")
"""What ``open_source`` accepts, for its error messages."""

ROS1_MAGIC = b"#ROSBAG V2.0\n"
MCAP_MAGIC = b"\x89MCAP0\r\n"
SQLITE_MAGIC = b"SQLite format 3\x00"

_GLOB_CHARS = frozenset("*?[")

VIDEO_SUFFIXES = frozenset({".mp4", ".m4v", ".mov", ".avi", ".mkv", ".webm", ".mpg", ".mpeg",
                            ".wmv", ".flv", ".ts", ".h264", ".mjpeg"})
"""Names of video files: one that does not open is a video OpenCV cannot decode."""


def _magic(path: Path) -> bytes:
    try:
        with path.open("rb") as f:
            return f.read(16)
    except OSError as exc:
        raise SourceError(f"cannot read {path}: {exc.strerror or exc}") from None


def _no_topics(path: Path, kind: str, topic: str | None) -> None:
    if topic is not None:
        raise SourceError(f"{path} is {kind}, which has no topics; leave out --topic")


def open_source(path: str | Path, *, topic: str | None = None,
                frames: FrameRange | None = None, rate_hz: float | None = None
                ) -> FrameSource:
    """Open ``path`` as a frame source (see ``base``): a video, a folder of images or a
    glob pattern, a ROS 1 bag, a ROS 2 bag (its folder, or the .db3/.mcap file in it) or a
    plain MCAP file. ``topic``: the image topic of a recording (None: the one the
    recording names, else its only one); ``frames``: the range ``frames()`` yields;
    ``rate_hz``: the frame rate [Hz] that times a video's or an image folder's frames
    (index / rate). Anything that cannot be read is a ``SourceError`` saying what to do."""
    frames = FrameRange() if frames is None else frames
    if rate_hz is not None and not (math.isfinite(rate_hz) and rate_hz > 0):
        raise SourceError(f"--rate {rate_hz}: give a frame rate > 0 [Hz]")
    text = str(path)
    p = Path(path)
    if not p.exists():
        if _GLOB_CHARS & set(text):
            _no_topics(p, "a glob pattern of images", topic)
            return ImageSource(p, glob_images(text), frames=frames, rate_hz=rate_hz)
        raise SourceError(f"{p}: no such file or folder; give {KINDS}")
    if p.is_dir():
        if (p / "metadata.yaml").exists():
            return _ros2(p, topic=topic, frames=frames, rate_hz=rate_hz)
        _no_topics(p, "a folder of images", topic)
        return ImageSource(p, folder_images(p), frames=frames, rate_hz=rate_hz)
    if p.name == "metadata.yaml":
        return _ros2(p.parent, topic=topic, frames=frames, rate_hz=rate_hz)
    magic = _magic(p)
    suffix = p.suffix.lower()
    if magic.startswith(ROS1_MAGIC):
        return _ros1(p, topic=topic, frames=frames, rate_hz=rate_hz)
    if magic.startswith(MCAP_MAGIC):
        if (p.parent / "metadata.yaml").exists():
            return _ros2(p.parent, topic=topic, frames=frames, rate_hz=rate_hz)
        return _mcap(p, topic=topic, frames=frames, rate_hz=rate_hz)
    if magic.startswith(SQLITE_MAGIC):
        if (p.parent / "metadata.yaml").exists():
            return _ros2(p.parent, topic=topic, frames=frames, rate_hz=rate_hz)
        raise SourceError(f"{p} is a ROS 2 bag's database without the bag's metadata.yaml "
                          "beside it; give the bag folder (the .db3 file and its "
                          "metadata.yaml)")
    expected = {".bag": "a ROS 1 bag (it should begin with '#ROSBAG V2.0')",
                ".mcap": "an MCAP file (it should begin with the MCAP magic bytes)",
                ".db3": "a ROS 2 bag database (it should begin with 'SQLite format 3')"}
    if suffix in expected:
        raise SourceError(f"{p} is not {expected[suffix]}: it is damaged or another kind of "
                          f"file; re-record or copy it again, or give {KINDS}")
    if cv2.haveImageReader(str(p)):
        _no_topics(p, "an image", topic)
        return ImageSource(p, [p], frames=frames, rate_hz=rate_hz)
    if opens_as_video(p):
        _no_topics(p, "a video", topic)
        return VideoSource(p, frames=frames, rate_hz=rate_hz)
    if suffix in VIDEO_SUFFIXES:  # named as a video: its codec or container is the problem
        raise SourceError(f"cannot open {p}: not a video, or a container or codec this "
                          f"OpenCV build cannot decode; {REENCODE}")
    raise SourceError(f"{p}: not a kind of recording this reads; give {KINDS}")


def _ros1(path: Path, *, topic: str | None, frames: FrameRange, rate_hz: float | None
          ) -> FrameSource:
    return RosBagSource(path, ros1=True, topic=topic, frames=frames, rate_hz=rate_hz)


def _ros2(path: Path, *, topic: str | None, frames: FrameRange, rate_hz: float | None
          ) -> FrameSource:
    return RosBagSource(path, ros1=False, topic=topic, frames=frames, rate_hz=rate_hz)


def _mcap(path: Path, *, topic: str | None, frames: FrameRange, rate_hz: float | None
          ) -> FrameSource:
    return McapSource(path, topic=topic, frames=frames, rate_hz=rate_hz)
