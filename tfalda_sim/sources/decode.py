"""ROS image messages as images: ``sensor_msgs/Image`` in the encodings a camera driver
publishes (grey, colour, Bayer), ``sensor_msgs/CompressedImage`` (JPEG, PNG), and
``sensor_msgs/CameraInfo`` as a ``CameraInfo``.

Messages come from rosbags' typestores and from ``mcap_ros2``'s decoder; both give fields
as attributes (``data``: a uint8 array or bytes). Every decoder returns uint8, grey
``(H, W)`` or BGR ``(H, W, 3)``; a decoding problem is a ``DecodeError``, which the
readers turn into a ``SourceError`` naming the file and the frame.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from tfalda_sim.sources.base import CameraInfo

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
IMAGE_TYPES = (IMAGE, COMPRESSED)
"""Message types read as frames (rosbags spells ROS 1's ``sensor_msgs/Image`` so too)."""

# Bayer: OpenCV names a pattern by the second row's first two pixels, so ROS's
# bayer_rggb8 is OpenCV's BayerBG (as cv_bridge converts it).
_BAYER = {
    "bayer_rggb8": cv2.COLOR_BayerBG2BGR,
    "bayer_bggr8": cv2.COLOR_BayerRG2BGR,
    "bayer_gbrg8": cv2.COLOR_BayerGR2BGR,
    "bayer_grbg8": cv2.COLOR_BayerGB2BGR,
}
_BYTES_PER_PIXEL = {"mono8": 1, "mono16": 2, "rgb8": 3, "bgr8": 3, "rgba8": 4, "bgra8": 4,
                    **dict.fromkeys(_BAYER, 1)}
ENCODINGS: tuple[str, ...] = tuple(_BYTES_PER_PIXEL)
"""``sensor_msgs/Image`` encodings read (OpenCV's ``8UC1``/``16UC1`` as mono8/mono16)."""
_ALIASES = {"8uc1": "mono8", "16uc1": "mono16", "8uc3": "bgr8", "8uc4": "bgra8"}


class DecodeError(ValueError):
    """A message that does not hold the image it declares."""


def encoding_of(encoding: str) -> str:
    """The encoding ``encoding`` is read as; a ``DecodeError`` naming the supported ones
    when it is none of them."""
    name = encoding.strip().lower()
    name = _ALIASES.get(name, name)
    if name not in _BYTES_PER_PIXEL:
        raise DecodeError(f"image encoding {encoding!r} is not supported; supported: "
                          f"{', '.join(ENCODINGS)} (and CompressedImage JPEG/PNG)")
    return name


def encoding_note(encoding: str) -> str | None:
    """The conversion an encoding needs, to state in a source's notes (None: none)."""
    name = encoding.split(";")[0].strip().lower()
    name = _ALIASES.get(name, name)
    if name in _BAYER:
        return f"Bayer {name[6:10].upper()} demosaiced (OpenCV, bilinear)"
    if name == "mono16":
        return "mono16 → 8 bit: the top byte of each pixel"
    return None


def _buffer(data: Any) -> np.ndarray:
    if isinstance(data, np.ndarray):
        return data.reshape(-1).view(np.uint8)
    return np.frombuffer(data, dtype=np.uint8)


def raw_image(msg: Any) -> np.ndarray:
    """A ``sensor_msgs/Image`` as uint8 grey or BGR: rows of ``step`` bytes (padding
    dropped), mono16 byte order from ``is_bigendian``, Bayer demosaiced."""
    encoding = encoding_of(str(msg.encoding))
    width, height, step = int(msg.width), int(msg.height), int(msg.step)
    if width <= 0 or height <= 0:
        raise DecodeError(f"image of {width}×{height} px")
    row = width * _BYTES_PER_PIXEL[encoding]
    if step < row:
        raise DecodeError(f"step {step} B is less than a row of {width} px {encoding} "
                          f"({row} B)")
    buf = _buffer(msg.data)
    # The last row's padding may be left out: a full step for every row but the last.
    need = step * (height - 1) + row
    if buf.size < need:
        raise DecodeError(f"{buf.size} B of data for a {width}×{height} {encoding} image "
                          f"with a step of {step} B (needs {need} B)")
    rows = np.lib.stride_tricks.as_strided(buf, shape=(height, row), strides=(step, 1),
                                           writeable=False)
    if encoding == "mono16":
        pixels = rows.copy().view(">u2" if msg.is_bigendian else "<u2")
        return (pixels >> 8).astype(np.uint8)
    if encoding == "mono8" or encoding in _BAYER:
        image = np.array(rows)
        return cv2.cvtColor(image, _BAYER[encoding]) if encoding in _BAYER else image
    channels = _BYTES_PER_PIXEL[encoding]
    image = np.array(rows).reshape(height, width, channels)
    if encoding == "bgr8":
        return image
    code = {"rgb8": cv2.COLOR_RGB2BGR, "rgba8": cv2.COLOR_RGBA2BGR,
            "bgra8": cv2.COLOR_BGRA2BGR}[encoding]
    return cv2.cvtColor(image, code)


def as_uint8(image: np.ndarray) -> np.ndarray:
    """A decoded image (any depth, 1/3/4 channels) as uint8 grey or BGR: 16-bit keeps its
    top byte (as ``base.to_grey``), alpha is dropped."""
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[..., 0]
    elif image.ndim == 3 and image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
    if image.dtype == np.uint16:
        image = (image >> 8).astype(np.uint8)
    elif image.dtype != np.uint8:
        image = cv2.convertScaleAbs(image)
    return image


def compressed_image(msg: Any) -> np.ndarray:
    """A ``sensor_msgs/CompressedImage`` (JPEG or PNG; ``format`` as image_transport
    writes it, e.g. ``jpeg`` or ``bayer_rggb8; png compressed bayer_rggb8``) as uint8
    grey or BGR."""
    fmt = str(msg.format)
    if "compresseddepth" in fmt.lower():
        raise DecodeError(f"CompressedImage format {fmt!r} (a depth image) is not supported; "
                          "give a camera image topic (JPEG or PNG)")
    image = cv2.imdecode(_buffer(msg.data), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise DecodeError(f"CompressedImage data (format {fmt!r}) is not a JPEG or PNG "
                          "image OpenCV decodes")
    image = as_uint8(image)
    raw = fmt.split(";")[0].strip().lower()
    if raw in _BAYER and image.ndim == 2:
        image = cv2.cvtColor(image, _BAYER[raw])
    return image


def image_of(msgtype: str, msg: Any) -> np.ndarray:
    """The image of a message of ``msgtype`` (one of ``IMAGE_TYPES``)."""
    return compressed_image(msg) if msgtype == COMPRESSED else raw_image(msg)


def encoding_label(msgtype: str, msg: Any) -> str:
    """What ``SourceInfo.encoding`` says: an Image's encoding, a CompressedImage's format."""
    return str(msg.format) if msgtype == COMPRESSED else str(msg.encoding)


def stamp_ns(msg: Any) -> int:
    """A message's ``header.stamp`` [ns since the epoch] (0: not stamped)."""
    stamp = msg.header.stamp
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def camera_info(msg: Any) -> CameraInfo:
    """A ``sensor_msgs/CameraInfo`` (ROS 2's ``k``/``d`` or ROS 1's ``K``/``D``)."""
    k = getattr(msg, "k", None)
    d = getattr(msg, "d", None)
    k = msg.K if k is None else k
    d = msg.D if d is None else d
    K = np.asarray(k, dtype=np.float64)
    if K.size != 9:
        raise DecodeError(f"CameraInfo K has {K.size} values, not 9")
    return CameraInfo(width_px=int(msg.width), height_px=int(msg.height),
                      K=K.reshape(3, 3), D=np.asarray(d, dtype=np.float64).reshape(-1),
                      distortion_model=str(msg.distortion_model))
