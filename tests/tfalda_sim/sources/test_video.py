"""Video files as frame sources: a lossless video reads back exactly, time stamps come
from the container, ranges, and a video that decodes no frame."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from tfalda_sim.sources import FrameRange, SourceError, open_source, to_grey
from tfalda_sim.video import VideoWriter


def lossless_video(path: Path, frames: list[np.ndarray], fps: float) -> Path:
    """``frames`` as an FFV1 (lossless) video."""
    h, w = frames[0].shape
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), fps, (w, h))
    if not writer.isOpened():
        pytest.skip("this OpenCV build writes no FFV1 video")
    for frame in frames:
        writer.write(cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR))
    writer.release()
    return path


def test_a_lossless_video_reads_back_exactly(tmp_path: Path,
                                             small: list[np.ndarray]) -> None:
    path = lossless_video(tmp_path / "clip.mkv", small, 10.0)
    source = open_source(path)
    info = source.info
    assert (info.kind, info.width_px, info.height_px) == ("video", 188, 120)
    assert (info.frame_count, info.rate_hz, info.encoding) == (5, 10.0, "ffv1")
    got = list(source.frames())
    assert [f.index for f in got] == [0, 1, 2, 3, 4]
    assert [f.t_s for f in got] == pytest.approx([0.0, 0.1, 0.2, 0.3, 0.4])
    for f, frame in zip(got, small, strict=True):
        np.testing.assert_array_equal(to_grey(f.image, (188, 120)), frame)
    assert len(list(source.frames())) == 5  # another pass


def test_an_mp4_of_the_camera(tmp_path: Path, rendered: list[np.ndarray]) -> None:
    path = tmp_path / "drive.mp4"
    with VideoWriter(path, 25.0) as writer:
        for frame in rendered:
            writer.write(frame)
    source = open_source(path, frames=FrameRange(2, 4))
    assert (source.info.rate_hz, source.info.frame_count) == (25.0, 2)
    got = list(source.frames())
    assert [(f.index, f.t_s) for f in got] == [(2, pytest.approx(0.08)),
                                               (3, pytest.approx(0.12))]
    for f in got:
        diff = to_grey(f.image, (752, 480)).astype(int) - rendered[f.index]
        assert np.abs(diff).mean() < 4.0  # H.264 of the camera's noise


def test_a_rate_replaces_the_container_times(tmp_path: Path,
                                             small: list[np.ndarray]) -> None:
    path = lossless_video(tmp_path / "clip.avi", small, 10.0)
    source = open_source(path, rate_hz=50.0)
    assert source.info.rate_hz == 50.0
    assert [f.t_s for f in source.frames()] == pytest.approx([0, 0.02, 0.04, 0.06, 0.08])
    assert any("--rate 50 Hz" in n for n in source.info.notes)


def test_a_range_after_the_last_frame(tmp_path: Path, small: list[np.ndarray]) -> None:
    path = lossless_video(tmp_path / "clip.mkv", small, 10.0)
    with pytest.raises(SourceError, match=r"clip.mkv has 5 frames; --frames 5:8 starts after"):
        open_source(path, frames=FrameRange(5, 8))


def test_a_video_that_decodes_no_frame_says_to_re_encode(tmp_path: Path,
                                                         small: list[np.ndarray]) -> None:
    path = tmp_path / "cut.mp4"
    with VideoWriter(path, 25.0) as writer:
        for frame in small:
            writer.write(frame)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])  # the index at the start, half the frames' data
    with pytest.raises(SourceError, match=r"cut.mp4: no frame decodes .*re-encode it"):
        open_source(path)
