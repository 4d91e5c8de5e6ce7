"""Choosing a recording's image topic (``--topic``, the camera topic the recording names in
its metadata, or its only image topic) and the ``camera_info`` topic beside it."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from tfalda_sim.sources.base import SourceError
from tfalda_sim.sources.decode import CAMERA_INFO, IMAGE_TYPES


@dataclass(frozen=True)
class Topic:
    """A topic of a recording: its name, message type (ROS 2 spelling,
    ``sensor_msgs/msg/Image``), message count (None: unknown) and whether the recording is
    ROS 1 (types shown as ``sensor_msgs/Image``)."""

    name: str
    msgtype: str
    count: int | None
    ros1: bool = False

    @property
    def shown_type(self) -> str:
        return self.msgtype.replace("/msg/", "/") if self.ros1 else self.msgtype

    def __str__(self) -> str:
        count = "? messages" if self.count is None else \
            f"{self.count} message{'s' if self.count != 1 else ''}"
        return f"{self.name} ({self.shown_type}, {count})"


def _listing(topics: Sequence[Topic]) -> str:
    return "; ".join(str(t) for t in topics) if topics else "none"


def image_topics(topics: Sequence[Topic]) -> list[Topic]:
    """The topics of an image type (``decode.IMAGE_TYPES``), sorted by name."""
    return sorted((t for t in topics if t.msgtype in IMAGE_TYPES), key=lambda t: t.name)


def choose_image_topic(path: Path, topics: Sequence[Topic], wanted: str | None,
                       named: str | None, named_where: str = "its metadata") -> Topic:
    """The image topic to read from ``path``: ``wanted`` (``--topic``), else ``named``
    (the camera topic the recording names in ``named_where``), else the only image topic.
    A ``SourceError`` listing the image topics (type, count) otherwise, and for a topic
    without messages."""
    images = image_topics(topics)
    by_name = {t.name: t for t in topics}
    hint = "; choose one with --topic NAME"
    if wanted is not None:
        topic = by_name.get(wanted)
        if topic is None:
            raise SourceError(f"{path} has no topic {wanted!r}; its image topics: "
                              f"{_listing(images)}{hint if images else ''}")
        if topic.msgtype not in IMAGE_TYPES:
            raise SourceError(
                f"{path}: topic {wanted!r} is a {topic.shown_type}, not an image "
                f"(sensor_msgs Image or CompressedImage); its image topics: "
                f"{_listing(images)}{hint if images else ''}")
    elif named is not None:
        topic = by_name.get(named)
        if topic is None or topic.msgtype not in IMAGE_TYPES:
            what = "has no such topic" if topic is None else f"it is a {topic.shown_type}"
            raise SourceError(f"{path} names {named!r} as its camera topic in {named_where}, "
                              f"but {what}; its image topics: {_listing(images)}"
                              f"{hint if images else ''}")
    elif len(images) == 1:
        topic = images[0]
    elif not images:
        raise SourceError(f"{path} has no image topic (sensor_msgs Image or CompressedImage); "
                          f"its topics: {_listing(sorted(topics, key=lambda t: t.name))}")
    else:
        raise SourceError(f"{path} has {len(images)} image topics: {_listing(images)}{hint}")
    if topic.count == 0:
        others = [t for t in images if t.name != topic.name and t.count != 0]
        raise SourceError(f"{path}: topic {topic.name} has no messages"
                          + (f"; its other image topics: {_listing(others)}{hint}"
                             if others else "; the recording holds no frames"))
    return topic


def camera_info_topic(image_topic: str, topics: Sequence[Topic]) -> Topic | None:
    """The ``sensor_msgs/CameraInfo`` topic of ``image_topic``: the one in its namespace
    (``/cam/image_raw`` or ``/cam/image_raw/compressed`` → ``/cam/camera_info``), else
    the recording's only one; None when neither is there."""
    infos = [t for t in topics if t.msgtype == CAMERA_INFO and t.count != 0]
    base = image_topic
    for transport in ("/compressed", "/theora", "/zstd"):
        base = base.removesuffix(transport)
    namespace = base.rsplit("/", 1)[0]
    for t in infos:
        if t.name == f"{namespace}/camera_info":
            return t
    return infos[0] if len(infos) == 1 else None
