"""Where serialized messages go: a plain MCAP file (``McapSink``) or a ROS 2 bag folder
with MCAP storage (``BagSink``). Both stream: messages collect in a chunk of
``CHUNK_SIZE`` bytes, zstd-compressed (``zstandard``, a dependency of ``mcap``; rosbags
has its own zstd) and written when full, so memory stays bounded however long the run.

A channel is created with its first message, its schema the type's ``ros2msg``
definition (``messages.msgdef``), so Foxglove and ROS 2 read the file without set-up.
The sinks know nothing of temporary files: the recorder (``writer``) does that.
"""

from __future__ import annotations

from pathlib import Path
from typing import BinaryIO, Protocol

from mcap.writer import LIBRARY_IDENTIFIER, CompressionType
from mcap.writer import Writer as McapWriter
from rosbags.interfaces import Connection
from rosbags.rosbag2 import Writer as BagWriter
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode, StoragePlugin

from tfalda_sim.recording.channels import Channel
from tfalda_sim.recording.messages import msgdef, rihs01

CHUNK_SIZE = 1 << 20
"""Bytes of messages per MCAP chunk (rosbags' MCAP storage uses the same, fixed)."""

BAG_VERSION = 8
"""rosbag2 metadata version written (rosbags writes 8 or 9): 8 is read by ROS 2 Iron and
later (and by rosbags, Foxglove); 9 only by Jazzy and later."""

SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"


class Sink(Protocol):
    """A recording's file being written: messages in, then ``finish`` or ``abort``."""

    def write(self, channel: Channel, stamp_ns: int, data: bytes) -> None:
        """Append one serialized (CDR) message on ``channel`` at ``stamp_ns`` [ns]."""

    def finish(self) -> None:
        """Write the index and summary: the file is complete and readable."""

    def abort(self) -> None:
        """Stop writing; the file is incomplete (the caller removes it)."""


class McapSink:
    """A plain MCAP file (profile ``ros2``) written to ``stream``, with a metadata record
    ``metadata_name`` holding ``metadata``. The caller closes the stream."""

    def __init__(self, stream: BinaryIO, *, library: str, metadata_name: str,
                 metadata: dict[str, str]) -> None:
        self._writer = McapWriter(stream, chunk_size=CHUNK_SIZE,
                                  compression=CompressionType.ZSTD)
        self._writer.start(profile="ros2", library=f"{library}; {LIBRARY_IDENTIFIER}")
        self._writer.add_metadata(metadata_name, metadata)
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._sequence: dict[str, int] = {}

    def _channel_id(self, channel: Channel) -> int:
        cid = self._channels.get(channel.topic)
        if cid is None:
            sid = self._schemas.get(channel.msgtype)
            if sid is None:
                sid = self._writer.register_schema(channel.msgtype, SCHEMA_ENCODING,
                                                   msgdef(channel.msgtype).encode())
                self._schemas[channel.msgtype] = sid
            cid = self._writer.register_channel(channel.topic, MESSAGE_ENCODING, sid)
            self._channels[channel.topic] = cid
            self._sequence[channel.topic] = 0
        return cid

    def write(self, channel: Channel, stamp_ns: int, data: bytes) -> None:
        cid = self._channel_id(channel)
        self._writer.add_message(cid, log_time=stamp_ns, data=data, publish_time=stamp_ns,
                                 sequence=self._sequence[channel.topic])
        self._sequence[channel.topic] += 1

    def finish(self) -> None:
        self._writer.finish()

    def abort(self) -> None:
        pass  # nothing but the stream, which the caller closes and removes


class BagSink:
    """A ROS 2 bag (rosbag2, ``BAG_VERSION``) in the new folder ``path``: one MCAP file
    with zstd chunks and ``metadata.yaml``, whose ``custom_data`` holds ``custom_data``."""

    def __init__(self, path: Path, *, custom_data: dict[str, str]) -> None:
        self.path = path
        self._writer = BagWriter(path, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP)
        # STORAGE: the MCAP file's own chunks are compressed (ROS 2 reads them as they
        # are), not the file as a whole, which would need unpacking before reading.
        self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        for key, value in custom_data.items():
            self._writer.set_custom_data(key, value)
        self._writer.open()
        self._connections: dict[str, Connection] = {}

    @property
    def files(self) -> list[Path]:
        """The files the bag is written to (for naming them in errors)."""
        return [self.path / f"{self.path.name}.mcap", self.path / "metadata.yaml"]

    def write(self, channel: Channel, stamp_ns: int, data: bytes) -> None:
        conn = self._connections.get(channel.topic)
        if conn is None:
            conn = self._writer.add_connection(
                channel.topic, channel.msgtype, msgdef=msgdef(channel.msgtype),
                rihs01=rihs01(channel.msgtype), serialization_format=MESSAGE_ENCODING)
            self._connections[channel.topic] = conn
        self._writer.write(conn, stamp_ns, data)

    def finish(self) -> None:
        self._writer.close()

    def abort(self) -> None:
        try:
            self._writer.abort()
        except OSError:
            pass  # the file's buffer cannot be written either: the bag is removed anyway
