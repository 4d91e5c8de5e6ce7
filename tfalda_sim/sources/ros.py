"""ROS 1 bags and ROS 2 bags (sqlite3 or mcap storage) as frame sources, read with rosbags
(no ROS install). A bag's own message definitions decode its messages; a bag without them
(ROS 2 before Iron) is decoded with rosbags' typestore of the latest ROS 2.

Frame k is the k-th message of the image topic in log-time order; its time stamp is the
message's ``header.stamp``, or its log (receive) time where the stamp is zero. Anything
rosbags, sqlite or the YAML parser raise on a damaged bag becomes a ``SourceError`` that
names the bag and says what to do.
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.interfaces import Connection, MessageDefinitionFormat
from rosbags.rosbag1 import Reader as Ros1Reader
from rosbags.rosbag2 import Reader as Ros2Reader
from rosbags.rosbag2.storage_mcap import McapReader
from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from tfalda_sim.sources.base import CameraInfo, FrameRange, SourceError, SourceInfo
from tfalda_sim.sources.decode import (
    DecodeError,
    camera_info,
)
from tfalda_sim.sources.messages import (
    first_frame,
    first_frames,
    frame_of,
    optional_camera_info,
)
from tfalda_sim.sources.stream import (
    Loader,
    StreamSource,
    median_rate_hz,
    range_count,
    reason,
)
from tfalda_sim.sources.topics import Topic, camera_info_topic, choose_image_topic

CUSTOM_DATA_KEY = "tfalda_sim.camera_topic"
"""A ROS 2 bag's metadata.yaml ``custom_data`` key naming its camera topic (our
recordings write it)."""

Reader = Ros1Reader | Ros2Reader


def _definitions(conns: Sequence[Connection], default: Stores) -> Typestore:
    """A typestore for ``conns``: their own definitions, rosbags' ``default`` store for
    connections without one."""
    types: dict[str, Any] = {}
    if any(c.msgdef.format == MessageDefinitionFormat.NONE for c in conns):
        types.update(get_typestore(default).fielddefs)
    for c in conns:
        if c.msgdef.format == MessageDefinitionFormat.MSG:
            types.update(get_types_from_msg(c.msgdef.data, c.msgtype))
        elif c.msgdef.format == MessageDefinitionFormat.IDL:
            sep = "=" * 80 + "\n"
            if c.msgdef.data.startswith(f"{sep}IDL: "):
                for part in c.msgdef.data.split(sep)[1:]:
                    types.update(get_types_from_idl(part.split("\n", 1)[1]))
            else:
                types.update(get_types_from_idl(c.msgdef.data))
    store = get_typestore(Stores.EMPTY)
    store.register(types)
    return store


class RosBagSource(StreamSource):
    """The image topic of a ROS 1 bag (``path`` the .bag file) or a ROS 2 bag (``path``
    its folder) as frames; see the module. ``rate_hz`` is not used: the bag's own time
    stamps time its frames."""

    def __init__(self, path: Path, *, ros1: bool, topic: str | None, frames: FrameRange,
                 rate_hz: float | None = None) -> None:
        self.path = path
        self.ros1 = ros1
        what = "ROS 1 bag" if ros1 else "ROS 2 bag"
        reader = self._open()
        try:
            kind = "ros1" if ros1 else self._ros2_kind(reader)
            try:
                topics = [Topic(name, info.msgtype or "(mixed types)", info.msgcount, ros1)
                          for name, info in reader.topics.items()]
            except Exception as exc:  # a damaged bag: rosbags' error, said plainly
                raise SourceError(f"{path}: cannot list the {what}'s topics "
                                  f"({reason(exc)}); {self._advice()}") from None
            named = None if ros1 else self._custom(reader).get(CUSTOM_DATA_KEY)
            chosen = choose_image_topic(path, topics, topic, named,
                                        "metadata.yaml (custom_data)")
            info_topic = camera_info_topic(chosen.name, topics)
            needed = [c for c in reader.connections
                      if c.topic in {chosen.name, getattr(info_topic, "name", None)}]
            try:
                self._store = _definitions(needed, Stores.ROS1_NOETIC if ros1 else
                                           Stores.LATEST)
            except Exception as exc:  # definitions rosbags cannot parse
                raise SourceError(f"{path}: the {what}'s message definitions do not parse "
                                  f"({reason(exc)}); {self._advice()}") from None
            self.topic = chosen
            self._stamp0 = 0
            name = chosen.name
            first, stamps, logged = first_frames(path, name, (
                (log_ns, functools.partial(self._typed, name, k, msgtype, raw))
                for k, (msgtype, log_ns, raw) in enumerate(self._messages(reader, name))))
            cam, cam_note = optional_camera_info(
                None if info_topic is None
                else functools.partial(self._camera_info, reader, info_topic))
        finally:
            with contextlib.suppress(Exception):
                reader.close()
        label, image, notes = first_frame(path, chosen.name, first, [cam_note], logged,
                                          len(stamps), rate_hz)
        self._stamp0 = stamps[0]
        super().__init__(SourceInfo(
            path=path, kind=kind, width_px=image.shape[1], height_px=image.shape[0],
            frame_count=range_count(path, chosen.count, frames),
            rate_hz=median_rate_hz(stamps), topic=chosen.name,
            message_type=chosen.shown_type, encoding=label, camera_info=cam,
            notes=tuple(notes)), frames)

    # -- rosbags access, every error said plainly ------------------------------------------

    def _advice(self) -> str:
        if self.ros1:
            return ("the bag is cut short or damaged: copy it again, or reindex it "
                    "(`rosbag reindex FILE` in a ROS 1 install)")
        return ("the bag is cut short or damaged, or not a ROS 2 bag: copy it again, or "
                "check its metadata.yaml")

    def _open(self) -> Reader:
        what = "ROS 1 bag" if self.ros1 else "ROS 2 bag"
        try:
            reader: Reader = Ros1Reader(self.path) if self.ros1 else Ros2Reader(self.path)
            reader.open()
        except Exception as exc:  # rosbags, sqlite3, YAML: said plainly
            text = reason(exc)
            if "Storage plugin" in text:
                storage = text.split("'")[1] if text.count("'") >= 2 else "?"
                raise SourceError(
                    f"{self.path}: the ROS 2 bag's storage {storage!r} is not one this "
                    "reads (sqlite3, mcap); convert it, e.g. `ros2 bag convert` to "
                    "storage mcap") from None
            raise SourceError(f"{self.path}: cannot open the {what} ({text}); "
                              f"{self._advice()}") from None
        return reader

    @staticmethod
    def _ros2_kind(reader: Reader) -> str:
        storages = getattr(reader.storage, "storages", [])
        return "ros2-mcap" if storages and isinstance(storages[0], McapReader) else \
            "ros2-sqlite3"

    @staticmethod
    def _custom(reader: Reader) -> dict[str, str]:
        """A ROS 2 bag's metadata ``custom_data`` (empty without)."""
        meta = getattr(reader.storage, "metadata", None)
        custom = getattr(meta, "custom", None)
        return dict(custom) if isinstance(custom, dict) else {}

    def _messages(self, reader: Reader, topic: str) -> Iterator[tuple[str, int, bytes]]:
        """``(type, log time [ns], raw)`` of ``topic``'s messages in log-time order; a
        read failure is a ``SourceError`` naming the frame it stopped at."""
        conns = [c for c in reader.connections if c.topic == topic]
        index = 0
        try:
            messages = reader.messages(connections=conns)
        except Exception as exc:  # rosbags/sqlite3 errors, said plainly
            raise self._read_error(topic, index, exc) from None
        while True:
            try:
                conn, log_ns, raw = next(messages)
            except StopIteration:
                return
            except Exception as exc:  # rosbags/sqlite3 errors, said plainly
                raise self._read_error(topic, index, exc) from None
            yield conn.msgtype, log_ns, raw
            index += 1

    def _read_error(self, topic: str, index: int, exc: BaseException) -> SourceError:
        return SourceError(f"{self.path}: cannot read frame {index} of {topic} "
                           f"({reason(exc)}); {self._advice()}, or select frames before it "
                           "with --frames A:B")

    def _typed(self, topic: str, index: int, msgtype: str, raw: bytes) -> tuple[str, Any]:
        return msgtype, self._deserialize(topic, index, msgtype, raw)

    def _deserialize(self, topic: str, index: int, msgtype: str, raw: bytes) -> Any:
        try:
            if self.ros1:
                return self._store.deserialize_ros1(raw, msgtype)
            return self._store.deserialize_cdr(raw, msgtype)
        except Exception as exc:  # a corrupt message: any parse failure
            raise SourceError(f"{self.path}: frame {index} of {topic} is corrupt: its "
                              f"{msgtype} message does not decode ({reason(exc)}); select "
                              "frames without it with --frames A:B") from None

    # -- what opening reads -----------------------------------------------------------------

    def _camera_info(self, reader: Reader, topic: Topic) -> CameraInfo | None:
        """The first message of the camera_info topic as a ``CameraInfo``."""
        for index, (msgtype, _, raw) in enumerate(self._messages(reader, topic.name)):
            try:
                return camera_info(self._deserialize(topic.name, index, msgtype, raw))
            except DecodeError as exc:
                raise SourceError(f"{self.path}: {topic.name}: {exc}") from None
        return None

    # -- one pass -------------------------------------------------------------------------

    def _load(self, index: int, msgtype: str, log_ns: int, raw: bytes
              ) -> tuple[float, np.ndarray]:
        msg = self._deserialize(self.topic.name, index, msgtype, raw)
        return frame_of(self.path, self.topic.name, index, msgtype, msg, log_ns, self._stamp0)

    def _items(self) -> Iterator[tuple[int, Loader]]:
        reader = self._open()
        try:
            for index, (msgtype, log_ns, raw) in enumerate(
                    self._messages(reader, self.topic.name)):
                yield index, functools.partial(self._load, index, msgtype, log_ns, raw)
        finally:
            with contextlib.suppress(Exception):
                reader.close()
