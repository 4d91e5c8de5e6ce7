"""Image folders and glob patterns: natural order, time stamps from --rate or from the
file names, frames of another size or depth, and unusable folders and files."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.tfalda_sim.sources.recordings import write_image_folder
from tfalda_sim.sources import FrameRange, SourceError, open_source
from tfalda_sim.sources.images import DEEP_NOTE, NO_STAMPS, name_stamp_ns


def test_a_folder_reads_in_natural_order(tmp_path: Path, small: list[np.ndarray]) -> None:
    # Written out of order; "frame_10" sorts after "frame_9" only in natural order.
    names = ["frame_10.png", "frame_9.png", "frame_1.png", "frame_100.png", "frame_2.png"]
    write_image_folder(tmp_path / "clip", small, names=names)
    source = open_source(tmp_path / "clip")
    info = source.info
    assert (info.kind, info.width_px, info.height_px, info.frame_count) == \
        ("images", 188, 120, 5)
    got = list(source.frames())
    order = [2, 4, 1, 0, 3]  # frame_1, frame_2, frame_9, frame_10, frame_100
    assert [f.index for f in got] == [0, 1, 2, 3, 4]
    for f, k in zip(got, order, strict=True):
        np.testing.assert_array_equal(f.image, small[k])


def test_no_time_stamps_without_a_rate(tmp_path: Path, small: list[np.ndarray]) -> None:
    write_image_folder(tmp_path, small)
    source = open_source(tmp_path)
    assert source.info.rate_hz is None
    assert NO_STAMPS in source.info.notes
    assert "give --rate HZ" in NO_STAMPS
    assert all(math.isnan(f.t_s) for f in source.frames())


def test_a_rate_times_the_frames_by_their_index(tmp_path: Path,
                                                small: list[np.ndarray]) -> None:
    write_image_folder(tmp_path, small)
    source = open_source(tmp_path, rate_hz=20.0, frames=FrameRange(1, 3))
    assert source.info.rate_hz == 20.0
    assert [(f.index, f.t_s) for f in source.frames()] == [(1, 0.05), (2, 0.1)]
    assert NO_STAMPS not in source.info.notes


@pytest.mark.parametrize(("name", "ns"), [
    ("frame_1712345678123456789", 1712345678123456789),  # ns
    ("frame_1712345678123456", 1712345678123456000),  # µs
    ("cam0_1712345678123", 1712345678123000000),  # ms
    ("1712345678", 1712345678000000000),  # s
    ("1712345678.123", 1712345678123000000),  # s with a fraction
    ("t_0.040", 40_000_000),  # relative seconds
    ("frame_000123", None),  # a frame number
    ("frame_12", None),
    ("img", None),
])
def test_time_stamps_in_file_names(name: str, ns: int | None) -> None:
    assert name_stamp_ns(name) == ns


@pytest.mark.parametrize("unit_ns", [1, 1000, 1_000_000])
def test_file_names_with_time_stamps_time_the_frames(tmp_path: Path, small: list[np.ndarray],
                                                     unit_ns: int) -> None:
    stamps = [1_712_345_678_000_000_000 + k * 50_000_000 for k in range(5)]
    names = [f"frame_{s // unit_ns}.png" for s in stamps]
    write_image_folder(tmp_path, small, names=names)
    source = open_source(tmp_path)
    assert source.info.rate_hz == pytest.approx(20.0)
    assert [f.t_s for f in source.frames()] == pytest.approx([0, 0.05, 0.1, 0.15, 0.2])
    # --rate takes precedence over the names.
    assert open_source(tmp_path, rate_hz=10).info.rate_hz == 10


def test_decimal_second_names(tmp_path: Path, small: list[np.ndarray]) -> None:
    write_image_folder(tmp_path, small[:3], names=["1712345678.000.png", "1712345678.040.png",
                                                   "1712345678.080.png"])
    assert [f.t_s for f in open_source(tmp_path).frames()] == pytest.approx([0, 0.04, 0.08])


def test_a_number_all_names_share_is_no_time_stamp(tmp_path: Path,
                                                   small: list[np.ndarray]) -> None:
    write_image_folder(tmp_path, small[:3],
                       names=[f"run_1712345678_frame_{k}.png" for k in range(3)])
    assert NO_STAMPS in open_source(tmp_path).info.notes


def test_name_stamps_going_backwards_are_an_error(tmp_path: Path,
                                                  small: list[np.ndarray]) -> None:
    # Natural order puts .5 (5) before .25 (25): the stamps go backwards.
    write_image_folder(tmp_path, small[:2], names=["1712345678.5.png", "1712345678.25.png"])
    with pytest.raises(SourceError, match=r"go backwards at frame 1: 1712345678.25.png "
                                          r"\(1712345678250000000 ns\) comes after "
                                          r"1712345678.5.png \(1712345678500000000 ns\)"):
        open_source(tmp_path)
    assert open_source(tmp_path, rate_hz=10).info.frame_count == 2


def test_a_glob_pattern(tmp_path: Path, small: list[np.ndarray]) -> None:
    write_image_folder(tmp_path, small[:3], names=["a_2.png", "a_10.png", "a_1.png"])
    write_image_folder(tmp_path, small[3:4], names=["b_1.jpg"])
    source = open_source(str(tmp_path / "a_*.png"))
    assert source.info.frame_count == 3
    got = [f.image for f in source.frames()]
    for image, k in zip(got, [2, 0, 1], strict=True):
        np.testing.assert_array_equal(image, small[k])
    with pytest.raises(SourceError, match=r"the pattern .*\*\.tif' matches no file"):
        open_source(str(tmp_path / "*.tif"))


def test_an_empty_folder_is_an_error(tmp_path: Path) -> None:
    with pytest.raises(SourceError, match=r"holds no images .*\(it is empty\)"):
        open_source(tmp_path)
    (tmp_path / "notes.txt").write_text("x")
    (tmp_path / "run.bag").write_bytes(b"x")
    with pytest.raises(SourceError, match=r"holds no images .*\(it holds notes.txt, run.bag\)"):
        open_source(tmp_path)


def test_an_unreadable_image_is_named(tmp_path: Path, small: list[np.ndarray]) -> None:
    files = write_image_folder(tmp_path, small)
    files[2].write_bytes(b"not a png")
    source = open_source(tmp_path)
    frames = source.frames()
    assert next(frames).index == 0
    assert next(frames).index == 1
    with pytest.raises(SourceError, match=r"frame_0002.png: not an image OpenCV can read"):
        next(frames)
    # A range without it reads; the first file unreadable fails at opening.
    assert [f.index for f in open_source(tmp_path, frames=FrameRange(3)).frames()] == [3, 4]
    files[0].write_bytes(b"")
    with pytest.raises(SourceError, match=r"frame_0000.png: not an image"):
        open_source(tmp_path)


def test_hidden_files_are_left_out(tmp_path: Path, small: list[np.ndarray]) -> None:
    write_image_folder(tmp_path, small[:2])
    (tmp_path / "._frame_0000.png").write_bytes(b"\x00\x05\x16\x07")  # macOS AppleDouble
    assert open_source(tmp_path).info.frame_count == 2


def test_frames_of_another_size_are_resized_and_counted(tmp_path: Path,
                                                        small: list[np.ndarray]) -> None:
    frames = [small[0], cv2.resize(small[1], (94, 60)), cv2.resize(small[2], (94, 60)),
              small[3]]
    write_image_folder(tmp_path, frames)
    source = open_source(tmp_path)
    got = list(source.frames())
    assert [f.image.shape for f in got] == [(120, 188)] * 4
    np.testing.assert_array_equal(
        got[1].image, cv2.resize(frames[1], (188, 120), interpolation=cv2.INTER_AREA))
    assert source.notes == ["2 frames of 94×60 resized to 188×120"]
    assert source.info.notes == (NO_STAMPS,)


def test_16_bit_and_alpha_images_come_out_8_bit(tmp_path: Path,
                                                small: list[np.ndarray]) -> None:
    wide = small[0].astype(np.uint16) * 257
    bgra = np.dstack([np.repeat(small[1][..., None], 3, 2),
                      np.full(small[1].shape, 7, np.uint8)])
    cv2.imwrite(str(tmp_path / "a_1.png"), wide)
    cv2.imwrite(str(tmp_path / "a_2.png"), bgra)
    source = open_source(tmp_path)
    got = list(source.frames())
    assert DEEP_NOTE in source.info.notes
    np.testing.assert_array_equal(got[0].image, small[0])
    assert got[1].image.shape == (120, 188, 3)
    np.testing.assert_array_equal(got[1].image[..., 1], small[1])


def test_a_range_after_the_last_image(tmp_path: Path, small: list[np.ndarray]) -> None:
    write_image_folder(tmp_path, small)
    with pytest.raises(SourceError, match=r"has 5 frames; --frames 7: starts after the last"):
        open_source(tmp_path, frames=FrameRange(7))


def test_a_deep_image_later_in_the_folder_is_noted_while_reading(
        tmp_path: Path, small: list[np.ndarray]) -> None:
    write_image_folder(tmp_path, small[:1], names=["a_1.png"])
    cv2.imwrite(str(tmp_path / "a_2.png"), small[1].astype(np.uint16) * 257)
    source = open_source(tmp_path)
    assert DEEP_NOTE not in source.info.notes
    got = list(source.frames())
    np.testing.assert_array_equal(got[1].image, small[1])
    assert source.notes == [DEEP_NOTE]
