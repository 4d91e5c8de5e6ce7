"""Recordings for tests: frames written as a ROS 1 bag, a ROS 2 bag (sqlite3 or mcap
storage), a plain MCAP file or an image folder, the way teams' cameras record them.

Every writer takes ``frames`` (uint8, grey ``(H, W)`` or BGR ``(H, W, 3)``) and
``stamps_ns`` (each frame's ``header.stamp`` [ns since the epoch]; 0: unstamped) and
writes them on ``topic`` as ``sensor_msgs/Image`` in ``encoding`` or, with
``compressed``, as ``sensor_msgs/CompressedImage`` (``"png"``, lossless, or
``"jpeg"``). Common options:

- ``log_times_ns``: the messages' log (receive) times [ns]; default the stamps, or 1 s +
  the frame's index × 40 ms for an unstamped frame.
- ``camera_info``: a ``CameraInfo`` written once on ``camera_info_topic`` (default: the
  image topic's namespace + ``/camera_info``).
- ``extra_topics``: more image topics with the same frames (a name ending in
  ``/compressed``: CompressedImage PNG), for choosing among topics.
- ``raw``: frame index → bytes written instead of that frame's serialized message (a
  corrupt message).
- ``step_padding`` bytes [B] after each row; ``bigendian`` for mono16.

Pixels of the encodings: ``mono16`` is the grey value × 257 (its top byte is the grey
value); colour encodings of a grey frame repeat it in each channel; Bayer encodings sample
a BGR frame (or a grey one, in every channel) with the pattern.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np
from mcap.well_known import MessageEncoding
from mcap_ros2.writer import Writer as McapRos2Writer
from rosbags.rosbag1 import Writer as Ros1Writer
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Ros2Writer
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from tfalda_sim.sources.base import CameraInfo

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
TOPIC = "/camera/image_raw"

ROS1_STORE = get_typestore(Stores.ROS1_NOETIC)
ROS2_STORE = get_typestore(Stores.ROS2_JAZZY)

Compressed = Literal[False, True, "png", "jpeg"]

# Bayer patterns: the colour (BGR channel) at (row % 2, col % 2).
_PATTERNS = {"bayer_rggb8": ((2, 1), (1, 0)), "bayer_bggr8": ((0, 1), (1, 2)),
             "bayer_gbrg8": ((1, 0), (2, 1)), "bayer_grbg8": ((1, 2), (0, 1))}


def mosaic(bgr: np.ndarray, encoding: str) -> np.ndarray:
    """A BGR (or grey) frame as the raw data of a Bayer camera with ``encoding``'s
    pattern."""
    if bgr.ndim == 2:
        bgr = np.repeat(bgr[..., None], 3, axis=2)
    out = np.empty(bgr.shape[:2], np.uint8)
    for dy in (0, 1):
        for dx in (0, 1):
            out[dy::2, dx::2] = bgr[dy::2, dx::2, _PATTERNS[encoding][dy][dx]]
    return out


def pixels(frame: np.ndarray, encoding: str, *, bigendian: bool = False) -> np.ndarray:
    """``frame`` as the pixel array of ``encoding`` (rows × bytes of a row)."""
    grey = frame if frame.ndim == 2 else None
    bgr = np.repeat(frame[..., None], 3, axis=2) if frame.ndim == 2 else frame
    if encoding == "mono8":
        if grey is None:
            raise ValueError("mono8 needs a grey frame")
        return grey
    if encoding == "mono16":
        if grey is None:
            raise ValueError("mono16 needs a grey frame")
        wide = grey.astype(np.uint16) * 257
        wide = wide.astype(">u2" if bigendian else "<u2")
        return wide.view(np.uint8).reshape(grey.shape[0], -1)
    if encoding in _PATTERNS:
        return mosaic(bgr, encoding)
    alpha = np.full((*bgr.shape[:2], 1), 255, np.uint8)
    out = {"bgr8": bgr, "rgb8": bgr[..., ::-1], "bgra8": np.concatenate([bgr, alpha], 2),
           "rgba8": np.concatenate([bgr[..., ::-1], alpha], 2)}.get(encoding)
    if out is None:
        raise ValueError(f"cannot write encoding {encoding!r}")
    return np.ascontiguousarray(out).reshape(bgr.shape[0], -1)


def _stamp(store: Typestore, ns: int) -> Any:
    return store.types["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000,
                                                       nanosec=ns % 1_000_000_000)


def _header(store: Typestore, ns: int, ros1: bool) -> Any:
    header = store.types["std_msgs/msg/Header"]
    if ros1:
        return header(seq=0, stamp=_stamp(store, ns), frame_id="camera")
    return header(stamp=_stamp(store, ns), frame_id="camera")


def image_message(store: Typestore, frame: np.ndarray, stamp_ns: int, *, encoding: str,
                  compressed: Compressed = False, step_padding: int = 0,
                  bigendian: bool = False, ros1: bool = False) -> tuple[str, Any]:
    """(message type, message) of one frame, built with ``store``'s types."""
    header = _header(store, stamp_ns, ros1)
    if compressed:
        fmt = "jpeg" if compressed == "jpeg" else "png"
        ok, data = cv2.imencode("." + fmt, frame)
        assert ok
        return COMPRESSED, store.types[COMPRESSED](header=header, format=fmt,
                                                    data=data.reshape(-1))
    px = pixels(frame, encoding, bigendian=bigendian)
    if step_padding:
        px = np.concatenate([px, np.full((px.shape[0], step_padding), 0xAB, np.uint8)], 1)
    return IMAGE, store.types[IMAGE](
        header=header, height=frame.shape[0], width=frame.shape[1], encoding=encoding,
        is_bigendian=int(bigendian), step=px.shape[1], data=np.ascontiguousarray(px).reshape(-1))


def camera_info_message(store: Typestore, info: CameraInfo, stamp_ns: int, ros1: bool
                        ) -> Any:
    k = np.asarray(info.K, np.float64).reshape(9)
    d = np.asarray(info.D, np.float64).reshape(-1)
    r = np.eye(3).reshape(9)
    p = np.concatenate([np.asarray(info.K, np.float64), np.zeros((3, 1))], 1).reshape(12)
    roi = store.types["sensor_msgs/msg/RegionOfInterest"](
        x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    fields = {"D": d, "K": k, "R": r, "P": p} if ros1 else {"d": d, "k": k, "r": r, "p": p}
    return store.types[CAMERA_INFO](
        header=_header(store, stamp_ns, ros1), height=info.height_px, width=info.width_px,
        distortion_model=info.distortion_model, binning_x=0, binning_y=0, roi=roi, **fields)


def camera_info_topic_of(topic: str) -> str:
    """The camera_info topic beside an image topic (``/cam/image_raw`` → ``/cam/camera_info``)."""
    base = topic.removesuffix("/compressed")
    return base.rsplit("/", 1)[0] + "/camera_info"


def _messages(store: Typestore, frames: Sequence[np.ndarray], stamps_ns: Sequence[int], *,
              topic: str, encoding: str, compressed: Compressed,
              log_times_ns: Sequence[int] | None, camera_info: CameraInfo | None,
              camera_info_topic: str | None, extra_topics: Sequence[str],
              step_padding: int, bigendian: bool, ros1: bool
              ) -> list[tuple[str, str, int, Any]]:
    """(topic, type, log time [ns], message) of every message, in log-time order."""
    if len(frames) != len(stamps_ns):
        raise ValueError(f"{len(frames)} frames but {len(stamps_ns)} stamps")
    logs = list(log_times_ns) if log_times_ns is not None else [
        s if s else 1_000_000_000 + 40_000_000 * k for k, s in enumerate(stamps_ns)]
    out = []
    topics = [(topic, compressed), *((t, "png" if t.endswith("/compressed") else False)
                                     for t in extra_topics)]
    for k, (frame, stamp) in enumerate(zip(frames, stamps_ns, strict=True)):
        for name, comp in topics:
            msgtype, msg = image_message(store, frame, stamp, encoding=encoding,
                                         compressed=comp, step_padding=step_padding,
                                         bigendian=bigendian, ros1=ros1)
            out.append((name, msgtype, logs[k], msg))
    if camera_info is not None:
        first = logs[0] if logs else 1_000_000_000
        out.append((camera_info_topic or camera_info_topic_of(topic), CAMERA_INFO, first,
                    camera_info_message(store, camera_info, stamps_ns[0] if stamps_ns else 0,
                                        ros1)))
    out.sort(key=lambda m: m[2])
    return out


def _types(topic: str, compressed: Compressed, extra_topics: Sequence[str],
           camera_info: CameraInfo | None, camera_info_topic: str | None) -> dict[str, str]:
    """Topic → message type of every topic a writer declares (also without messages)."""
    types = {topic: COMPRESSED if compressed else IMAGE}
    types.update({t: COMPRESSED if t.endswith("/compressed") else IMAGE for t in extra_topics})
    if camera_info is not None:
        types[camera_info_topic or camera_info_topic_of(topic)] = CAMERA_INFO
    return types


def write_ros1_bag(path: str | Path, frames: Sequence[np.ndarray], stamps_ns: Sequence[int],
                   *, topic: str = TOPIC, encoding: str = "mono8",
                   compressed: Compressed = False, camera_info: CameraInfo | None = None,
                   camera_info_topic: str | None = None, extra_topics: Sequence[str] = (),
                   log_times_ns: Sequence[int] | None = None,
                   raw: Mapping[int, bytes] | None = None, step_padding: int = 0,
                   bigendian: bool = False) -> Path:
    """A ROS 1 bag (rosbags' writer, uncompressed chunks) at ``path`` (see the module)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    raw = dict(raw or {})
    msgs = _messages(ROS1_STORE, frames, stamps_ns, topic=topic, encoding=encoding,
                     compressed=compressed, log_times_ns=log_times_ns,
                     camera_info=camera_info, camera_info_topic=camera_info_topic,
                     extra_topics=extra_topics, step_padding=step_padding,
                     bigendian=bigendian, ros1=True)
    with Ros1Writer(path) as writer:
        conns = {name: writer.add_connection(name, msgtype, typestore=ROS1_STORE)
                 for name, msgtype in _types(topic, compressed, extra_topics, camera_info,
                                             camera_info_topic).items()}
        index = 0
        for name, msgtype, log_ns, msg in msgs:
            data = ROS1_STORE.serialize_ros1(msg, msgtype)
            if name == topic:
                data = raw.get(index, data)
                index += 1
            writer.write(conns[name], log_ns, data)
    return path


def write_ros2_bag(path: str | Path, frames: Sequence[np.ndarray], stamps_ns: Sequence[int],
                   *, storage: Literal["sqlite3", "mcap"] = "sqlite3", topic: str = TOPIC,
                   encoding: str = "mono8", compressed: Compressed = False,
                   camera_info: CameraInfo | None = None, camera_info_topic: str | None = None,
                   extra_topics: Sequence[str] = (), camera_topic: str | None = None,
                   log_times_ns: Sequence[int] | None = None,
                   raw: Mapping[int, bytes] | None = None, step_padding: int = 0,
                   bigendian: bool = False) -> Path:
    """A ROS 2 bag folder at ``path`` (must not exist) with ``storage``; ``camera_topic``
    goes to the metadata's ``custom_data`` as ``tfalda_sim.camera_topic`` (as our
    recordings name their camera topic). See the module."""
    path = Path(path)
    raw = dict(raw or {})
    msgs = _messages(ROS2_STORE, frames, stamps_ns, topic=topic, encoding=encoding,
                     compressed=compressed, log_times_ns=log_times_ns,
                     camera_info=camera_info, camera_info_topic=camera_info_topic,
                     extra_topics=extra_topics, step_padding=step_padding,
                     bigendian=bigendian, ros1=False)
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Ros2Writer(path, version=9, storage_plugin=plugin) as writer:
        if camera_topic is not None:
            writer.set_custom_data("tfalda_sim.camera_topic", camera_topic)
        conns = {name: writer.add_connection(name, msgtype, typestore=ROS2_STORE)
                 for name, msgtype in _types(topic, compressed, extra_topics, camera_info,
                                             camera_info_topic).items()}
        index = 0
        for name, msgtype, log_ns, msg in msgs:
            data = ROS2_STORE.serialize_cdr(msg, msgtype)
            if name == topic:
                data = raw.get(index, data)
                index += 1
            writer.write(conns[name], log_ns, data)
    return path


def _as_dict(msg: Any) -> Any:
    """A rosbags message as the dicts mcap_ros2's writer encodes."""
    if isinstance(msg, np.ndarray):
        return msg.tobytes() if msg.dtype == np.uint8 else msg.tolist()
    if hasattr(msg, "__dataclass_fields__"):
        return {k: _as_dict(getattr(msg, k)) for k in msg.__dataclass_fields__}
    return msg


def write_mcap(path: str | Path, frames: Sequence[np.ndarray], stamps_ns: Sequence[int], *,
               topic: str = TOPIC, encoding: str = "mono8", compressed: Compressed = False,
               camera_info: CameraInfo | None = None, camera_info_topic: str | None = None,
               extra_topics: Sequence[str] = (), camera_topic: str | None = None,
               log_times_ns: Sequence[int] | None = None,
               raw: Mapping[int, bytes] | None = None, step_padding: int = 0,
               bigendian: bool = False, chunk_size: int = 1 << 20) -> Path:
    """A plain MCAP file (ROS 2 CDR messages; mcap_ros2's writer, zstd chunks) at
    ``path``; ``camera_topic`` goes to a metadata record ``tfalda-sim`` (key
    ``camera_topic``), as our recordings write it. See the module."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    raw = dict(raw or {})
    msgs = _messages(ROS2_STORE, frames, stamps_ns, topic=topic, encoding=encoding,
                     compressed=compressed, log_times_ns=log_times_ns,
                     camera_info=camera_info, camera_info_topic=camera_info_topic,
                     extra_topics=extra_topics, step_padding=step_padding,
                     bigendian=bigendian, ros1=False)
    with path.open("wb") as f:
        writer = McapRos2Writer(f, chunk_size=chunk_size)
        schemas = {t: writer.register_msgdef(t, ROS2_STORE.generate_msgdef(t, ros_version=2)[0])
                   for t in (IMAGE, COMPRESSED, CAMERA_INFO)}
        channels: dict[str, int] = {}
        for name, msgtype in _types(topic, compressed, extra_topics, camera_info,
                                    camera_info_topic).items():
            # Registered up front (mcap_ros2 registers on the first message): a topic
            # without messages is declared too.
            channels[name] = writer._writer.register_channel(
                topic=name, message_encoding=MessageEncoding.CDR,
                schema_id=schemas[msgtype].id)
            writer._channel_ids[name] = channels[name]
        index = 0
        for name, msgtype, log_ns, msg in msgs:
            if name == topic and index in raw:
                writer._writer.add_message(channel_id=channels[name], log_time=log_ns,
                                           publish_time=log_ns, sequence=index,
                                           data=raw[index])
            else:
                writer.write_message(name, schemas[msgtype], _as_dict(msg), log_time=log_ns,
                                     publish_time=log_ns)
            index += name == topic
        if camera_topic is not None:
            writer.add_metadata("tfalda-sim", {"camera_topic": camera_topic})
        writer.finish()
    return path


def write_image_folder(folder: str | Path, frames: Sequence[np.ndarray], *,
                       names: Sequence[str] | None = None) -> list[Path]:
    """``frames`` as image files (OpenCV; the format from each name's suffix) in
    ``folder`` (created); ``names`` default ``frame_0000.png``, … The files, in order."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    names = list(names) if names is not None else [f"frame_{k:04d}.png"
                                                    for k in range(len(frames))]
    if len(names) != len(frames):
        raise ValueError(f"{len(frames)} frames but {len(names)} names")
    files = []
    for frame, name in zip(frames, names, strict=True):
        file = folder / name
        if not cv2.imwrite(str(file), frame):
            raise OSError(f"OpenCV could not write {file}")
        files.append(file)
    return files
