"""open_source: the kind found from the content, not the name, and paths it cannot read."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.tfalda_sim.sources.recordings import write_image_folder, write_ros2_bag
from tfalda_sim.sources import KINDS, FrameSource, SourceError, open_source


def test_a_missing_path_names_what_is_accepted(tmp_path: Path) -> None:
    with pytest.raises(SourceError) as err:
        open_source(tmp_path / "nope.bag")
    text = str(err.value)
    assert text.startswith(f"{tmp_path / 'nope.bag'}: no such file or folder; give ")
    for kind in ("video file", "folder of images", "glob pattern", "ROS 1 bag",
                 "ROS 2 bag folder", "MCAP file"):
        assert kind in text
    assert KINDS in text


def test_a_file_of_no_known_kind(tmp_path: Path) -> None:
    path = tmp_path / "notes.txt"
    path.write_text("lap times\n" * 50)
    with pytest.raises(SourceError, match=r"notes.txt: not a kind of recording this reads; "
                                          r"give a video file"):
        open_source(path)


@pytest.mark.parametrize(("name", "kind"), [("x.bag", "ROS 1 bag"), ("x.mcap", "MCAP file"),
                                            ("x.db3", "ROS 2 bag database")])
def test_a_recording_name_without_its_content(tmp_path: Path, name: str, kind: str) -> None:
    path = tmp_path / name
    path.write_bytes(np.random.default_rng(2).integers(0, 256, 300, np.uint8).tobytes())
    with pytest.raises(SourceError, match=rf"{name} is not an? {kind} .*damaged or another kind"):
        open_source(path)


def test_a_ros2_database_without_its_metadata(tmp_path: Path, small: list[np.ndarray],
                                              stamps: list[int]) -> None:
    bag = write_ros2_bag(tmp_path / "bag", small[:1], stamps[:1])
    (bag / "metadata.yaml").unlink()
    with pytest.raises(SourceError, match=r"bag.db3 is a ROS 2 bag's database without the "
                                          r"bag's metadata.yaml"):
        open_source(bag / "bag.db3")


def test_a_single_image_without_a_suffix(tmp_path: Path, small: list[np.ndarray]) -> None:
    path = tmp_path / "snapshot"
    ok, data = cv2.imencode(".png", small[0])
    assert ok
    path.write_bytes(data.tobytes())
    source = open_source(path)
    assert (source.info.kind, source.info.frame_count) == ("images", 1)
    np.testing.assert_array_equal(next(source.frames()).image, small[0])


def test_a_topic_for_a_source_without_topics(tmp_path: Path, small: list[np.ndarray]) -> None:
    write_image_folder(tmp_path, small[:1])
    with pytest.raises(SourceError, match=r"is a folder of images, which has no topics; leave "
                                          r"out --topic"):
        open_source(tmp_path, topic="/camera/image_raw")


@pytest.mark.parametrize("rate", [0.0, -5.0, float("nan"), float("inf")])
def test_a_rate_must_be_positive(tmp_path: Path, small: list[np.ndarray], rate: float) -> None:
    write_image_folder(tmp_path, small[:1])
    with pytest.raises(SourceError, match=r"--rate .*: give a frame rate > 0"):
        open_source(tmp_path, rate_hz=rate)


def test_every_kind_is_a_frame_source(tmp_path: Path, small: list[np.ndarray],
                                      stamps: list[int]) -> None:
    write_image_folder(tmp_path / "images", small[:2])
    bag = write_ros2_bag(tmp_path / "bag", small[:2], stamps[:2])
    for path in (tmp_path / "images", bag):
        source: FrameSource = open_source(path)
        assert isinstance(source.notes, list)
        assert source.info.path == path
