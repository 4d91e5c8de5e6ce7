"""Plain MCAP files (no ROS 2 bag's metadata.yaml beside them) with ROS 2 (CDR) messages
as frame sources, read with the ``mcap`` library and ``mcap_ros2``'s decoder.

Frame k is the k-th message of the image topic in log-time order (in file order when the
file has no index: ordering it would hold every message in memory); its time stamp is the
message's ``header.stamp``, or its log time where the stamp is zero. The camera topic our
recordings name in their ``tfalda-sim`` metadata record is read by default.
"""

from __future__ import annotations

import contextlib
import functools
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np
from mcap.reader import McapReader, make_reader
from mcap.records import Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap_ros2.decoder import DecoderFactory

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

METADATA_NAME = "tfalda-sim"
"""The metadata record in which our recordings name their camera topic (``camera_topic``)."""

ADVICE = ("the file is cut short or damaged: copy it again, or recover what it holds with "
          "the mcap CLI (`mcap recover FILE -o FIXED.mcap`)")


def _ros2_name(name: str) -> str:
    """A schema name in ROS 2's spelling (``sensor_msgs/Image`` → ``sensor_msgs/msg/Image``)."""
    parts = name.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else name


@dataclass
class _Contents:
    """What an MCAP file declares: its channels, schemas, message counts (None: no
    statistics), metadata records, and whether its messages can be read by log time."""

    channels: dict[int, Channel] = field(default_factory=dict)
    schemas: dict[int, Schema] = field(default_factory=dict)
    counts: dict[int, int] | None = None
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    indexed: bool = False


class McapSource(StreamSource):
    """The image topic of a plain MCAP file as frames; see the module. ``rate_hz`` is not
    used: the file's own time stamps time its frames."""

    def __init__(self, path: Path, *, topic: str | None, frames: FrameRange,
                 rate_hz: float | None = None) -> None:
        self.path = path
        self._factory = DecoderFactory()
        with self._reader() as (stream, reader):
            contents = self._contents(stream, reader)
            self._indexed = contents.indexed
            topics = self._topics(contents)
            named = contents.metadata.get(METADATA_NAME, {}).get("camera_topic")
            chosen = choose_image_topic(path, topics, topic, named,
                                        f"its {METADATA_NAME!r} metadata record")
            self.topic = chosen
            for channel in contents.channels.values():
                if channel.topic == chosen.name:
                    self._check_encoding(channel, contents.schemas.get(channel.schema_id))
            self._stamp0 = 0
            name = chosen.name
            first, stamps, logged = first_frames(path, name, (
                (message.log_time, functools.partial(self._decode, name, k, schema, channel,
                                                     message))
                for k, (schema, channel, message) in enumerate(self._messages(reader, name))))
        info_topic = camera_info_topic(chosen.name, topics)
        cam, cam_note = optional_camera_info(
            None if info_topic is None else functools.partial(self._camera_info, info_topic))
        label, image, notes = first_frame(
            path, chosen.name, first,
            [cam_note, None if self._indexed else "the file has no index: frames in file order"],
            logged, len(stamps), rate_hz)
        self._stamp0 = stamps[0]
        super().__init__(SourceInfo(
            path=path, kind="mcap", width_px=image.shape[1], height_px=image.shape[0],
            frame_count=range_count(path, chosen.count, frames),
            rate_hz=median_rate_hz(stamps), topic=chosen.name, message_type=chosen.msgtype,
            encoding=label, camera_info=cam, notes=tuple(notes)), frames)

    # -- the mcap library, every error said plainly ---------------------------------------

    @contextlib.contextmanager
    def _reader(self) -> Iterator[tuple[IO[bytes], McapReader]]:
        try:
            stream = self.path.open("rb")
        except OSError as exc:
            raise SourceError(f"cannot read {self.path}: {exc.strerror or exc}") from None
        with stream:
            try:
                reader = make_reader(stream)
            except Exception as exc:  # mcap's errors (bad magic, …), said plainly
                raise SourceError(f"{self.path}: not a readable MCAP file ({reason(exc)}); "
                                  f"{ADVICE}") from None
            yield stream, reader

    def _contents(self, stream: IO[bytes], reader: McapReader) -> _Contents:
        """The file's summary section, or (a file without one) a scan of its records that
        keeps no message."""
        out = _Contents()
        try:
            summary = reader.get_summary()
            if summary is not None:
                out.channels, out.schemas = dict(summary.channels), dict(summary.schemas)
                if summary.statistics is not None:
                    out.counts = dict(summary.statistics.channel_message_counts)
                out.metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
                out.indexed = bool(summary.chunk_indexes)
                return out
            stream.seek(0)
            counts: Counter[int] = Counter()
            for record in StreamReader(stream, skip_magic=False).records:
                if isinstance(record, Message):
                    counts[record.channel_id] += 1
                elif isinstance(record, Channel):
                    out.channels[record.id] = record
                elif isinstance(record, Schema):
                    out.schemas[record.id] = record
                elif isinstance(record, Metadata):
                    out.metadata[record.name] = dict(record.metadata)
            out.counts = dict(counts)
        except Exception as exc:  # mcap's errors on a damaged file, said plainly
            raise SourceError(f"{self.path}: cannot read the MCAP file's index "
                              f"({reason(exc)}); {ADVICE}") from None
        return out

    @staticmethod
    def _topics(contents: _Contents) -> list[Topic]:
        types: dict[str, str] = {}
        counts: dict[str, int | None] = {}
        for cid, channel in contents.channels.items():
            schema = contents.schemas.get(channel.schema_id)
            types[channel.topic] = _ros2_name(schema.name) if schema else "(no schema)"
            n = None if contents.counts is None else contents.counts.get(cid, 0)
            before = counts.get(channel.topic, 0)
            counts[channel.topic] = None if n is None or before is None else before + n
        return [Topic(name, types[name], counts[name]) for name in types]

    def _check_encoding(self, channel: Channel, schema: Schema | None) -> None:
        if channel.message_encoding != "cdr" or schema is None or schema.encoding != "ros2msg":
            raise SourceError(
                f"{self.path}: topic {channel.topic} holds {channel.message_encoding!r} "
                f"messages with {schema.encoding if schema else 'no'!r} schemas; this reads "
                "ROS 2 messages (CDR, ros2msg schemas) from a plain MCAP file — convert it, "
                "e.g. record it as a ROS 2 bag")

    def _messages(self, reader: McapReader, topic: str
                  ) -> Iterator[tuple[Schema | None, Channel, Message]]:
        """``topic``'s messages by log time (file order without an index); a read failure
        is a ``SourceError`` naming the frame it stopped at."""
        index = 0
        messages = reader.iter_messages(topics=[topic], log_time_order=self._indexed)
        while True:
            try:
                item = next(messages)
            except StopIteration:
                return
            except Exception as exc:  # mcap's errors on a damaged file, said plainly
                raise SourceError(f"{self.path}: cannot read frame {index} of {topic} "
                                  f"({reason(exc)}); {ADVICE}, or select frames before it "
                                  "with --frames A:B") from None
            yield item
            index += 1

    def _decode(self, topic: str, index: int, schema: Schema | None, channel: Channel,
                message: Message) -> tuple[str, Any]:
        """(message type, decoded message); a corrupt message is a ``SourceError`` naming
        the frame."""
        try:
            decoder: Callable[[bytes], Any] | None = self._factory.decoder_for(
                channel.message_encoding, schema)
            if decoder is None:
                raise ValueError(f"no ROS 2 decoder for {channel.message_encoding!r} messages")
            msg = decoder(message.data)
        except Exception as exc:  # mcap_ros2's parse failures, said plainly
            raise SourceError(f"{self.path}: frame {index} of {topic} is corrupt: its message "
                              f"does not decode ({reason(exc)}); select frames without it "
                              "with --frames A:B") from None
        return _ros2_name(schema.name) if schema else "", msg

    # -- what opening reads -----------------------------------------------------------------

    def _camera_info(self, topic: Topic) -> CameraInfo | None:
        """The first message of the camera_info topic as a ``CameraInfo``."""
        with self._reader() as (_, reader):
            for index, (schema, channel, message) in enumerate(
                    self._messages(reader, topic.name)):
                try:
                    return camera_info(self._decode(topic.name, index, schema, channel,
                                                    message)[1])
                except DecodeError as exc:
                    raise SourceError(f"{self.path}: {topic.name}: {exc}") from None
        return None

    # -- one pass -------------------------------------------------------------------------

    def _load(self, index: int, schema: Schema | None, channel: Channel, message: Message
              ) -> tuple[float, np.ndarray]:
        msgtype, msg = self._decode(self.topic.name, index, schema, channel, message)
        return frame_of(self.path, self.topic.name, index, msgtype, msg, message.log_time,
                        self._stamp0)

    def _items(self) -> Iterator[tuple[int, Loader]]:
        with self._reader() as (_, reader):
            for index, (schema, channel, message) in enumerate(
                    self._messages(reader, self.topic.name)):
                yield index, functools.partial(self._load, index, schema, channel, message)
