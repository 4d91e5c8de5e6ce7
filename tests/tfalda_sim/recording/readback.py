"""Synthetic steps, and recordings read back with the readers others use: the ``mcap``
library with ``mcap_ros2``'s decoder (as Foxglove decodes: from the embedded schema
text) and rosbags' ``AnyReader`` (from the bag's connections' msgdef)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader

from tfalda_sim.recording import RecordedStep
from tfalda_sim.sources.base import CameraInfo

SIZE = (752, 480)
"""Frame width, height [px]."""

CAMERA_INFO = CameraInfo(SIZE[0], SIZE[1],
                         np.array([[310.0, 0.0, 376.5], [0.0, 309.0, 241.25], [0.0, 0.0, 1.0]]),
                         np.array([0.1, -0.02, 0.003, -0.0004]), "equidistant")


def steps(n: int, *, seed: int = 0, truth: bool = True, lis: bool = True,
          top_view: bool = True, dt_s: float = 0.02) -> list[RecordedStep]:
    """``n`` steps of noise frames (PNG cannot shrink them), lanes with a NaN row, ROIs,
    Hough segments; with ``truth`` a pose, speed, truth lanes and cross-track error."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        lanes = rng.uniform(0.0, 700.0, (4, 4))
        lanes[i % 4] = np.nan
        accepted = rng.random(4) < 0.7
        accepted[i % 4] = False
        out.append(RecordedStep(
            t_s=i * dt_s,
            frame=rng.integers(0, 256, (SIZE[1], SIZE[0]), dtype=np.uint8),
            lanes=lanes, accepted=accepted,
            rois=rng.integers(0, 400, (4, 4)).astype(np.int32),
            fault_counter=int(i % 5) if lis else None,
            roi_reset=bool(i % 7 == 0) if lis else None,
            state=("TRACKING", "RECOVERY")[i % 2] if lis else None,
            segments=rng.uniform(0.0, 700.0, (int(rng.integers(0, 9)), 4)),
            pose=(float(rng.uniform(-5, 5)), float(rng.uniform(-5, 5)),
                  float(rng.uniform(-np.pi, np.pi))) if truth else None,
            speed_m_s=float(rng.uniform(0, 3)) if truth else None,
            truth_lanes=rng.uniform(0.0, 700.0, (3, 4)) if truth else None,
            cross_track_m=float(rng.normal(0, 0.05)) if truth else None,
            top_view=rng.integers(0, 256, (120, 160, 3), dtype=np.uint8) if top_view
            else None))
    return out


@dataclass
class Readback:
    """A recording as read back: per topic its type, schema encoding (MCAP), messages
    (decoded objects) and log times [ns]; the metadata the reader found."""

    types: dict[str, str] = field(default_factory=dict)
    encodings: dict[str, str] = field(default_factory=dict)
    messages: dict[str, list[Any]] = field(default_factory=dict)
    times: dict[str, list[int]] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)
    metadata: dict[str, str] = field(default_factory=dict)


def read_mcap(path: Path, metadata_name: str = "tfalda-sim") -> Readback:
    """An MCAP file through ``mcap`` + ``mcap_ros2``."""
    out = Readback()
    with open(path, "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        for ch in summary.channels.values():
            schema = summary.schemas[ch.schema_id]
            out.types[ch.topic] = schema.name
            out.encodings[ch.topic] = schema.encoding
            out.counts[ch.topic] = summary.statistics.channel_message_counts.get(ch.id, 0)
            out.messages[ch.topic] = []
            out.times[ch.topic] = []
        for _, ch, msg, decoded in reader.iter_decoded_messages():
            out.messages[ch.topic].append(decoded)
            out.times[ch.topic].append(msg.log_time)
        for record in reader.iter_metadata():
            if record.name == metadata_name:
                out.metadata = dict(record.metadata)
    return out


def read_bag(path: Path) -> Readback:
    """A ROS 2 bag through rosbags' ``AnyReader``; the metadata is the custom_data of its
    ``metadata.yaml``."""
    out = Readback()
    with AnyReader([path]) as reader:
        for conn in reader.connections:
            out.types[conn.topic] = conn.msgtype
            out.counts[conn.topic] = conn.msgcount
            out.messages[conn.topic] = []
            out.times[conn.topic] = []
        for conn, t_ns, raw in reader.messages():
            out.messages[conn.topic].append(reader.deserialize(raw, conn.msgtype))
            out.times[conn.topic].append(t_ns)
    info = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    out.metadata = dict(info.get("custom_data") or {})
    return out


def stamp_ns(time: Any) -> int:
    """A ``builtin_interfaces/Time`` [ns]."""
    return int(time.sec) * 1_000_000_000 + int(time.nanosec)
