"""The parts every kind shares: decoding ROS image messages (``decode``), one pass over a
source (``stream``: range, stamp order, sizes) and the camera_info topic (``topics``)."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import cv2
import numpy as np
import pytest

from tests.tfalda_sim.sources.recordings import mosaic
from tfalda_sim.sources import FrameRange, SourceError, SourceInfo
from tfalda_sim.sources.decode import (
    ENCODINGS,
    DecodeError,
    camera_info,
    compressed_image,
    raw_image,
)
from tfalda_sim.sources.stream import Loader, StreamSource, median_rate_hz
from tfalda_sim.sources.topics import Topic, camera_info_topic

BAYER = [e for e in ENCODINGS if e.startswith("bayer_")]


def image_msg(data: np.ndarray | bytes, width: int, height: int, encoding: str,
              step: int, bigendian: bool = False) -> Any:
    return SimpleNamespace(data=data, width=width, height=height, encoding=encoding,
                           step=step, is_bigendian=int(bigendian))


# -- decode -------------------------------------------------------------------------------

def colour_ramp(h: int = 40, w: int = 60) -> np.ndarray:
    """A smooth BGR image whose three channels differ."""
    yy, xx = np.mgrid[0:h, 0:w]
    return np.stack([40 + 2 * xx, 60 + 3 * yy, np.full((h, w), 200)], 2).astype(np.uint8)


@pytest.mark.parametrize("encoding", BAYER)
def test_bayer_patterns_demosaic_to_the_scene(encoding: str) -> None:
    bgr = colour_ramp()
    raw = mosaic(bgr, encoding)
    out = raw_image(image_msg(raw.reshape(-1), 60, 40, encoding, 60))
    assert out.shape == (40, 60, 3)
    # Inside the border, bilinear demosaicing of a linear ramp is exact.
    inner = np.abs(out[2:-2, 2:-2].astype(int) - bgr[2:-2, 2:-2])
    assert inner.mean() < 1.0
    # Another pattern's decoding (red and blue swapped, green misplaced) is far off.
    for other in BAYER:
        if other != encoding:
            wrong = raw_image(image_msg(raw.reshape(-1), 60, 40, other, 60))
            assert np.abs(wrong[2:-2, 2:-2].astype(int) - bgr[2:-2, 2:-2]).mean() > 20


def test_an_unsupported_encoding_lists_the_supported() -> None:
    with pytest.raises(DecodeError, match=r"'yuv422' is not supported; supported: mono8, "
                                          r"mono16, rgb8, bgr8, rgba8, bgra8, bayer_rggb8, "
                                          r"bayer_bggr8, bayer_gbrg8, bayer_grbg8"):
        raw_image(image_msg(b"\x00" * 8, 2, 2, "yuv422", 4))


def test_opencv_type_names_are_read() -> None:
    data = np.arange(6, dtype=np.uint8)
    np.testing.assert_array_equal(raw_image(image_msg(data, 3, 2, "8UC1", 3)),
                                  data.reshape(2, 3))


@pytest.mark.parametrize(("width", "height", "step", "size", "match"), [
    (4, 2, 3, 8, r"step 3 B is less than a row of 4 px mono8 \(4 B\)"),
    (4, 3, 6, 12, r"12 B of data for a 4×3 mono8 image with a step of 6 B \(needs 16 B\)"),
    (0, 3, 6, 12, r"image of 0×3 px"),
])
def test_inconsistent_images_are_decode_errors(width: int, height: int, step: int, size: int,
                                               match: str) -> None:
    with pytest.raises(DecodeError, match=match):
        raw_image(image_msg(bytes(size), width, height, "mono8", step))


def test_the_last_rows_padding_may_be_left_out() -> None:
    rows = np.arange(12, dtype=np.uint8).reshape(3, 4)
    padded = np.concatenate([rows, np.full((3, 2), 99, np.uint8)], 1).reshape(-1)[:-2]
    np.testing.assert_array_equal(raw_image(image_msg(padded, 4, 3, "mono8", 6)), rows)


def test_mono16_byte_order() -> None:
    values = np.array([[0x1234, 0xABCD]], dtype=np.uint16)
    little = values.astype("<u2").view(np.uint8).reshape(-1)
    big = values.astype(">u2").view(np.uint8).reshape(-1)
    np.testing.assert_array_equal(raw_image(image_msg(little, 2, 1, "mono16", 4)),
                                  [[0x12, 0xAB]])
    np.testing.assert_array_equal(raw_image(image_msg(big, 2, 1, "mono16", 4, True)),
                                  [[0x12, 0xAB]])


def test_compressed_images() -> None:
    grey = np.arange(60, dtype=np.uint8).reshape(6, 10)
    ok, png = cv2.imencode(".png", grey)
    assert ok
    np.testing.assert_array_equal(
        compressed_image(SimpleNamespace(format="mono8; png compressed mono8", data=png)),
        grey)
    # A Bayer camera's frames compressed as PNG are demosaiced after decoding.
    bgr = colour_ramp()
    ok, png = cv2.imencode(".png", mosaic(bgr, "bayer_rggb8"))
    out = compressed_image(SimpleNamespace(format="bayer_rggb8; png compressed bayer_rggb8",
                                           data=png.tobytes()))
    assert np.abs(out[2:-2, 2:-2].astype(int) - bgr[2:-2, 2:-2]).mean() < 1.0
    with pytest.raises(DecodeError, match=r"format 'jpeg'\) is not a JPEG or PNG image"):
        compressed_image(SimpleNamespace(format="jpeg", data=b"\xff\xd8 broken"))
    with pytest.raises(DecodeError, match=r"depth image\) is not supported"):
        compressed_image(SimpleNamespace(format="16UC1; compressedDepth", data=png))


def test_camera_info_of_ros1_and_ros2_messages() -> None:
    k = [300.0, 0, 94, 0, 310.0, 60, 0, 0, 1]
    size = {"width": 188, "height": 120, "distortion_model": "plumb_bob"}
    for msg in (SimpleNamespace(k=k, d=[0.1, -0.2], **size),
                SimpleNamespace(K=k, D=[0.1, -0.2], **size)):
        info = camera_info(msg)
        assert info.K.shape == (3, 3)
        assert info.K[1, 1] == 310.0
        np.testing.assert_array_equal(info.D, [0.1, -0.2])
    with pytest.raises(DecodeError, match=r"K has 4 values, not 9"):
        camera_info(SimpleNamespace(width=1, height=1, k=[1, 2, 3, 4], d=[],
                                    distortion_model=""))


# -- stream -------------------------------------------------------------------------------

class Fake(StreamSource):
    """``images`` with ``times`` [s]; ``count`` of them declared (None: unknown)."""

    def __init__(self, images: list[np.ndarray], times: list[float],
                 frames: FrameRange | None = None, count: int | None = None) -> None:
        self.images, self.times, self.loaded = images, times, []
        h, w = images[0].shape[:2]
        super().__init__(SourceInfo(path=Path("fake"), kind="video", width_px=w, height_px=h,
                                    frame_count=count, rate_hz=None, notes=("opened",)),
                         frames or FrameRange())

    def _items(self) -> Iterator[tuple[int, Loader]]:
        for index in range(len(self.images)):
            def load(index: int = index) -> tuple[float, np.ndarray]:
                self.loaded.append(index)
                return self.times[index], self.images[index]

            yield index, load


def test_only_frames_in_the_range_are_loaded() -> None:
    images = [np.full((4, 6), k, np.uint8) for k in range(10)]
    source = Fake(images, [k / 10 for k in range(10)], FrameRange(3, 6))
    got = list(source.frames())
    assert [f.index for f in got] == [3, 4, 5]
    assert source.loaded == [3, 4, 5]
    assert got[0].image[0, 0] == 3


def test_a_range_after_the_last_frame_of_an_unknown_count() -> None:
    source = Fake([np.zeros((4, 6), np.uint8)] * 3, [0, 1, 2], FrameRange(3, 9))
    with pytest.raises(SourceError, match=r"fake has 3 frames; --frames 3:9 starts after"):
        list(source.frames())


def test_stamps_before_the_first_frame_go_backwards() -> None:
    source = Fake([np.zeros((4, 6), np.uint8)] * 4, [0.0, 0.5, -0.25, 1.0], FrameRange(2))
    with pytest.raises(SourceError, match=r"backwards at frame 2: it is stamped -0.250000 s, "
                                          r"before frame 0 at 0.000000 s"):
        list(source.frames())


def test_equal_and_unknown_stamps_are_not_backwards() -> None:
    nan = math.nan
    source = Fake([np.zeros((4, 6), np.uint8)] * 4, [0.0, 0.0, nan, 0.1])
    assert len(list(source.frames())) == 4


def test_notes_found_while_reading_are_kept_apart_from_the_opening_notes() -> None:
    images = [np.zeros((4, 6), np.uint8), np.zeros((8, 12), np.uint8),
              np.zeros((8, 12, 3), np.uint8), np.zeros((2, 3), np.uint8)]
    source = Fake(images, [0, 1, 2, 3])
    notes = source.notes
    got = list(source.frames())
    assert [f.image.shape[:2] for f in got] == [(4, 6)] * 4
    assert got[2].image.shape == (4, 6, 3)
    assert notes is source.notes  # updated in place
    assert source.notes == ["1 frame of 3×2 resized to 6×4", "2 frames of 12×8 resized to 6×4"]
    source.note("opened")  # an opening note is not repeated
    source.note("found")
    source.note("found")
    assert source.notes[0] == "found"
    assert len(source.notes) == 3


@pytest.mark.parametrize(("stamps", "rate"), [
    ([0, 40, 80, 120], 25.0),
    ([0, 40, 80, 200, 240], 25.0),  # a dropped frame
    ([0, 40, 40, 80], 25.0),  # a repeated stamp
    ([5, 5], None),
    ([7], None),
])
def test_the_rate_is_the_median_interval(stamps: list[int], rate: float | None) -> None:
    got = median_rate_hz([s * 1_000_000 for s in stamps])
    assert got == (None if rate is None else pytest.approx(rate))


# -- topics ---------------------------------------------------------------------------------

def test_the_camera_info_topic_in_the_image_topics_namespace() -> None:
    info = "sensor_msgs/msg/CameraInfo"
    topics = [Topic("/left/camera_info", info, 3), Topic("/right/camera_info", info, 3),
              Topic("/right/image_raw", "sensor_msgs/msg/Image", 9)]
    found = camera_info_topic("/right/image_raw/compressed", topics)
    assert found is not None and found.name == "/right/camera_info"
    assert camera_info_topic("/centre/image_raw", topics) is None  # two, neither beside it
    only = camera_info_topic("/centre/image_raw", topics[:1])
    assert only is not None and only.name == "/left/camera_info"
    assert camera_info_topic("/x/image", [Topic("/x/camera_info", info, 0)]) is None
