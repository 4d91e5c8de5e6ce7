"""ROS 1 bags, ROS 2 bags (sqlite3 and mcap storage) and plain MCAP files: the frames read
back are the frames written, with their stamps; ranges, topic choice, camera_info, the
image encodings, and every damaged or unusable recording as a plain SourceError."""

from __future__ import annotations

import functools
import shutil
import tracemalloc
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from tests.tfalda_sim.sources.conftest import EPOCH_NS
from tests.tfalda_sim.sources.recordings import (
    IMAGE,
    ROS1_STORE,
    ROS2_STORE,
    TOPIC,
    image_message,
    write_mcap,
    write_ros1_bag,
    write_ros2_bag,
)
from tfalda_sim.sources import (
    CameraInfo,
    FrameRange,
    SourceError,
    mcap_file,
    messages,
    open_source,
    ros,
    to_grey,
)
from tfalda_sim.sources.decode import DecodeError

KINDS = ["ros1", "ros2-sqlite3", "ros2-mcap", "mcap"]
ROS2_KINDS = ["ros2-sqlite3", "ros2-mcap"]
COMPRESSED_TOPIC = "/front/image_raw/compressed"


def record(kind: str, folder: Path, frames: list[np.ndarray], stamps: list[int],
           **options: Any) -> Path:
    """``frames`` written as a recording of ``kind`` in ``folder``; the path to open."""
    writers: dict[str, tuple[Callable[..., Path], str]] = {
        "ros1": (write_ros1_bag, "cam.bag"),
        "ros2-sqlite3": (functools.partial(write_ros2_bag, storage="sqlite3"), "bag"),
        "ros2-mcap": (functools.partial(write_ros2_bag, storage="mcap"), "bag"),
        "mcap": (write_mcap, "cam.mcap"),
    }
    write, name = writers[kind]
    return write(folder / name, frames, stamps, **options)


def storage_file(kind: str, path: Path) -> Path:
    """The file holding the messages (a ROS 2 bag's .db3 or .mcap)."""
    if kind in ROS2_KINDS:
        return next(p for p in path.iterdir() if p.suffix in (".db3", ".mcap"))
    return path


def grey(image: np.ndarray) -> np.ndarray:
    return to_grey(image, (image.shape[1], image.shape[0]))


# -- round trips ---------------------------------------------------------------------------

@pytest.mark.parametrize("kind", KINDS)
def test_frames_and_stamps_round_trip(kind: str, tmp_path: Path, small: list[np.ndarray],
                                      stamps: list[int]) -> None:
    # Received a little after their stamps, unevenly: the times must be the stamps.
    logs = [s + 7_000_000 + k * 2_000_000 for k, s in enumerate(stamps)]
    path = record(kind, tmp_path, small, stamps, log_times_ns=logs)
    source = open_source(path)
    info = source.info
    assert (info.kind, info.topic, info.encoding) == (kind, TOPIC, "mono8")
    assert info.message_type == ("sensor_msgs/Image" if kind == "ros1" else IMAGE)
    assert (info.width_px, info.height_px, info.frame_count) == (188, 120, 5)
    assert info.rate_hz == pytest.approx(30.0, rel=1e-6)
    got = list(source.frames())
    assert [f.index for f in got] == [0, 1, 2, 3, 4]
    for f, frame, stamp in zip(got, small, stamps, strict=True):
        assert f.image.dtype == np.uint8
        np.testing.assert_array_equal(f.image, frame)
        assert f.t_s == pytest.approx((stamp - stamps[0]) / 1e9, abs=1e-9)
    assert source.notes == []
    # Another pass (replay --loops) gives the same frames.
    again = list(source.frames())
    assert [f.index for f in again] == [0, 1, 2, 3, 4]
    np.testing.assert_array_equal(again[4].image, small[4])


@pytest.mark.parametrize("kind", KINDS)
def test_a_range_keeps_the_source_index_and_time(kind: str, tmp_path: Path,
                                                 small: list[np.ndarray],
                                                 stamps: list[int]) -> None:
    path = record(kind, tmp_path, small, stamps)
    source = open_source(path, frames=FrameRange(2, 4))
    assert source.info.frame_count == 2
    got = list(source.frames())
    assert [f.index for f in got] == [2, 3]
    # Times from the source's first frame, not the range's.
    assert got[0].t_s == pytest.approx((stamps[2] - stamps[0]) / 1e9, abs=1e-9)
    np.testing.assert_array_equal(got[1].image, small[3])
    assert open_source(path, frames=FrameRange(3)).info.frame_count == 2
    huge = open_source(path, frames=FrameRange(0, 100_000_000))
    assert huge.info.frame_count == 5
    assert len(list(huge.frames())) == 5
    with pytest.raises(SourceError, match=r"has 5 frames; --frames 5:9 starts after the last"):
        open_source(path, frames=FrameRange(5, 9))


@pytest.mark.parametrize("kind", ["ros1", "mcap"])
def test_frames_outside_the_range_are_not_decoded(kind: str, tmp_path: Path,
                                                  small: list[np.ndarray],
                                                  stamps: list[int],
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    path = record(kind, tmp_path, small, stamps)
    source = open_source(path, frames=FrameRange(3, 4))
    decoded = []

    def counting(msgtype: str, msg: Any) -> np.ndarray:
        decoded.append(msgtype)
        return np.zeros((120, 188), np.uint8)

    monkeypatch.setattr(messages, "image_of", counting)  # a pass's decoding
    assert [f.index for f in source.frames()] == [3]
    assert len(decoded) == 1


@pytest.mark.parametrize("kind", KINDS)
def test_a_pass_does_not_hold_the_recording(kind: str, tmp_path: Path,
                                           rendered: list[np.ndarray]) -> None:
    """40 full frames (14 MB): reading them all holds a few (a storage chunk) at a time."""
    frames = [rendered[k % len(rendered)] for k in range(40)]
    stamps = [EPOCH_NS + k * 40_000_000 for k in range(40)]
    source = open_source(record(kind, tmp_path, frames, stamps))
    tracemalloc.start()
    try:
        count = sum(1 for _ in source.frames())
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert count == 40
    assert peak < 40 * rendered[0].nbytes / 3, f"peak {peak / 1e6:.1f} MB"


# -- image encodings ------------------------------------------------------------------------

@pytest.mark.parametrize("kind", ["ros1", "mcap"])
@pytest.mark.parametrize("encoding", ["bgr8", "rgb8", "bgra8", "rgba8"])
def test_colour_encodings_of_a_grey_frame_are_that_grey(kind: str, encoding: str,
                                                        tmp_path: Path,
                                                        small: list[np.ndarray],
                                                        stamps: list[int]) -> None:
    source = open_source(record(kind, tmp_path, small[:2], stamps[:2], encoding=encoding))
    assert source.info.encoding == encoding
    for f, frame in zip(source.frames(), small, strict=False):
        assert f.image.shape == (120, 188, 3)
        np.testing.assert_array_equal(grey(f.image), frame)


@pytest.mark.parametrize("kind", KINDS)
def test_rgb8_comes_out_as_bgr(kind: str, tmp_path: Path, stamps: list[int]) -> None:
    bgr = np.zeros((8, 10, 3), np.uint8)
    bgr[..., 0], bgr[..., 1], bgr[..., 2] = 10, 120, 250
    source = open_source(record(kind, tmp_path, [bgr], stamps[:1], encoding="rgb8"))
    np.testing.assert_array_equal(next(source.frames()).image, bgr)


@pytest.mark.parametrize("kind", KINDS)
def test_png_compressed_frames_are_exact(kind: str, tmp_path: Path, small: list[np.ndarray],
                                         stamps: list[int]) -> None:
    source = open_source(record(kind, tmp_path, small, stamps, compressed="png",
                                topic="/cam/image_raw/compressed"))
    assert source.info.message_type.endswith("CompressedImage")
    assert source.info.encoding == "png"
    for f, frame in zip(source.frames(), small, strict=True):
        np.testing.assert_array_equal(f.image, frame)


def test_jpeg_compressed_frames_are_close(tmp_path: Path, small: list[np.ndarray],
                                          stamps: list[int]) -> None:
    source = open_source(record("ros2-sqlite3", tmp_path, small, stamps, compressed="jpeg"))
    for f, frame in zip(source.frames(), small, strict=True):
        assert np.abs(grey(f.image).astype(int) - frame).mean() < 3.0


@pytest.mark.parametrize("kind", ["ros1", "ros2-mcap", "mcap"])
@pytest.mark.parametrize("bigendian", [False, True])
def test_mono16_keeps_its_top_byte_in_either_byte_order(kind: str, bigendian: bool,
                                                         tmp_path: Path,
                                                         small: list[np.ndarray],
                                                         stamps: list[int]) -> None:
    source = open_source(record(kind, tmp_path, small[:2], stamps[:2], encoding="mono16",
                                bigendian=bigendian))
    assert any("mono16" in n for n in source.info.notes)
    for f, frame in zip(source.frames(), small, strict=False):
        np.testing.assert_array_equal(f.image, frame)


@pytest.mark.parametrize("kind", ["ros1", "ros2-sqlite3", "mcap"])
@pytest.mark.parametrize("encoding", ["mono8", "bgr8", "mono16"])
def test_row_padding_is_dropped(kind: str, encoding: str, tmp_path: Path,
                                small: list[np.ndarray], stamps: list[int]) -> None:
    source = open_source(record(kind, tmp_path, small[:2], stamps[:2], encoding=encoding,
                                step_padding=5))
    for f, frame in zip(source.frames(), small, strict=False):
        np.testing.assert_array_equal(grey(f.image), frame)


@pytest.mark.parametrize("kind", ["ros1", "ros2-mcap"])
def test_bayer_frames_are_demosaiced_close_to_the_scene(kind: str, tmp_path: Path,
                                                        small: list[np.ndarray],
                                                        stamps: list[int]) -> None:
    source = open_source(record(kind, tmp_path, small[:2], stamps[:2],
                                encoding="bayer_grbg8"))
    assert "Bayer GRBG demosaiced (OpenCV, bilinear)" in source.info.notes
    for f, frame in zip(source.frames(), small, strict=False):
        assert f.image.shape == (120, 188, 3)
        assert np.abs(grey(f.image).astype(int) - frame).mean() < 2.5


@pytest.mark.parametrize("kind", ["ros1", "mcap"])
def test_an_unsupported_encoding_is_named_with_the_supported_ones(
        kind: str, tmp_path: Path, small: list[np.ndarray], stamps: list[int],
        monkeypatch: pytest.MonkeyPatch) -> None:
    from tests.tfalda_sim.sources import recordings

    real = recordings.pixels
    monkeypatch.setattr(recordings, "pixels",
                        lambda frame, encoding, **kw: real(frame, "mono8", **kw))
    path = record(kind, tmp_path, small[:1], stamps[:1], encoding="yuv422")
    with pytest.raises(SourceError, match=r"'yuv422' is not supported; supported: mono8, "
                                          r"mono16, rgb8, bgr8.*bayer_grbg8") as err:
        open_source(path)
    assert str(path) in str(err.value)


# -- time stamps ----------------------------------------------------------------------------

@pytest.mark.parametrize("kind", KINDS)
def test_unstamped_frames_take_the_log_time(kind: str, tmp_path: Path,
                                            small: list[np.ndarray]) -> None:
    logs = [EPOCH_NS + k * 50_000_000 for k in range(5)]
    source = open_source(record(kind, tmp_path, small, [0] * 5, log_times_ns=logs))
    assert [f.t_s for f in source.frames()] == pytest.approx([0.0, 0.05, 0.1, 0.15, 0.2])
    assert source.info.rate_hz == pytest.approx(20.0)
    assert any("no header stamp" in n for n in source.info.notes)


@pytest.mark.parametrize("kind", KINDS)
def test_stamps_going_backwards_name_the_frame_and_both_stamps(
        kind: str, tmp_path: Path, small: list[np.ndarray]) -> None:
    stamps = [EPOCH_NS + k * 40_000_000 for k in (0, 1, 2, 1, 4)]
    logs = [EPOCH_NS + k * 40_000_000 for k in range(5)]
    path = record(kind, tmp_path, small, stamps, log_times_ns=logs)
    source = open_source(path)
    with pytest.raises(SourceError, match=r"go backwards at frame 3: it is stamped 0\.040000 "
                                          r"s, before frame 2 at 0\.080000 s") as err:
        list(source.frames())
    assert str(path) in str(err.value)
    # The frames before it read.
    assert [f.index for f in open_source(path, frames=FrameRange(0, 3)).frames()] == [0, 1, 2]


# -- topics ---------------------------------------------------------------------------------

@pytest.mark.parametrize("kind", KINDS)
def test_several_image_topics_need_a_topic(kind: str, tmp_path: Path,
                                           small: list[np.ndarray],
                                           stamps: list[int]) -> None:
    info = CameraInfo(188, 120, np.eye(3), np.zeros(5), "plumb_bob")
    path = record(kind, tmp_path, small, stamps, extra_topics=[COMPRESSED_TOPIC],
                  camera_info=info)
    image_type = "sensor_msgs/Image" if kind == "ros1" else IMAGE
    with pytest.raises(SourceError) as err:
        open_source(path)
    text = str(err.value)
    assert f"{path} has 2 image topics" in text
    assert f"{COMPRESSED_TOPIC} (sensor_msgs{'' if kind == 'ros1' else '/msg'}/CompressedImage, "\
           "5 messages)" in text
    assert f"{TOPIC} ({image_type}, 5 messages)" in text
    assert "--topic NAME" in text
    chosen = open_source(path, topic=COMPRESSED_TOPIC)
    assert chosen.info.topic == COMPRESSED_TOPIC
    np.testing.assert_array_equal(list(chosen.frames())[2].image, small[2])
    with pytest.raises(SourceError, match=r"has no topic '/nope'; its image topics: "
                                          r"/camera/image_raw .*--topic NAME"):
        open_source(path, topic="/nope")
    with pytest.raises(SourceError, match=r"topic '/camera/camera_info' is a sensor_msgs/"
                                          r"(msg/)?CameraInfo, not an image"):
        open_source(path, topic="/camera/camera_info")


@pytest.mark.parametrize("kind", [*ROS2_KINDS, "mcap"])
def test_the_camera_topic_the_recording_names_is_taken(kind: str, tmp_path: Path,
                                                       small: list[np.ndarray],
                                                       stamps: list[int]) -> None:
    path = record(kind, tmp_path, small, stamps, extra_topics=[COMPRESSED_TOPIC],
                  camera_topic=COMPRESSED_TOPIC)
    assert open_source(path).info.topic == COMPRESSED_TOPIC
    assert open_source(path, topic=TOPIC).info.topic == TOPIC  # --topic wins
    named = record(kind, tmp_path / "named", small, stamps, camera_topic="/gone/image")
    with pytest.raises(SourceError, match=r"names '/gone/image' as its camera topic .* has no "
                                          r"such topic; its image topics: /camera/image_raw"):
        open_source(named)


@pytest.mark.parametrize("kind", KINDS)
def test_an_empty_topic_is_an_error(kind: str, tmp_path: Path) -> None:
    path = record(kind, tmp_path, [], [])
    with pytest.raises(SourceError, match=r"topic /camera/image_raw has no messages") as err:
        open_source(path)
    assert str(path) in str(err.value)


@pytest.mark.parametrize("kind", KINDS)
def test_camera_info_beside_the_image_topic(kind: str, tmp_path: Path,
                                            small: list[np.ndarray],
                                            stamps: list[int]) -> None:
    K = np.array([[301.5, 0.0, 94.2], [0.0, 299.0, 60.7], [0.0, 0.0, 1.0]])
    D = np.array([-0.21, 0.04, 0.001, -0.002])
    written = CameraInfo(188, 120, K, D, "equidistant")
    path = record(kind, tmp_path, small, stamps, camera_info=written)
    cam = open_source(path).info.camera_info
    assert cam is not None
    assert (cam.width_px, cam.height_px, cam.distortion_model) == (188, 120, "equidistant")
    np.testing.assert_array_equal(cam.K, K)
    np.testing.assert_array_equal(cam.D, D)
    # The only CameraInfo topic, though not in the image topic's namespace.
    other = record(kind, tmp_path / "other", small, stamps, camera_info=written,
                   camera_info_topic="/calib/camera_info")
    assert open_source(other).info.camera_info is not None
    assert open_source(record(kind, tmp_path / "none", small, stamps)).info.camera_info is None


# -- ROS 2 bags: the paths accepted ---------------------------------------------------------

@pytest.mark.parametrize("kind", ROS2_KINDS)
def test_a_ros2_bag_opens_from_its_storage_file_or_metadata(kind: str, tmp_path: Path,
                                                            small: list[np.ndarray],
                                                            stamps: list[int]) -> None:
    path = record(kind, tmp_path, small, stamps)
    for given in (storage_file(kind, path), path / "metadata.yaml"):
        source = open_source(given)
        assert source.info.kind == kind
        assert source.info.path == path
        assert len(list(source.frames())) == 5


# -- damaged and unusable recordings -------------------------------------------------------

@pytest.mark.parametrize("kind", KINDS)
def test_a_recording_cut_in_half_is_named(kind: str, tmp_path: Path,
                                          rendered: list[np.ndarray],
                                          stamps: list[int]) -> None:
    path = record(kind, tmp_path, rendered, stamps)
    file = storage_file(kind, path)
    data = file.read_bytes()
    file.write_bytes(data[: len(data) // 2])
    with pytest.raises(SourceError, match=r"cut short or damaged") as err:
        list(open_source(path).frames())
    assert str(path) in str(err.value)


@pytest.mark.parametrize("kind", KINDS)
def test_garbage_bytes_are_named(kind: str, tmp_path: Path, small: list[np.ndarray],
                                 stamps: list[int]) -> None:
    path = record(kind, tmp_path, small, stamps)
    file = storage_file(kind, path)
    file.write_bytes(np.random.default_rng(1).integers(0, 256, 5000, np.uint8).tobytes())
    with pytest.raises(SourceError) as err:
        list(open_source(path).frames())
    assert str(path) in str(err.value)


@pytest.mark.parametrize("kind", ["ros1", "mcap"])
def test_garbage_inside_the_magic_bytes_is_named(kind: str, tmp_path: Path,
                                                 small: list[np.ndarray],
                                                 stamps: list[int]) -> None:
    """A file that begins as a bag or an MCAP but holds garbage after."""
    path = record(kind, tmp_path, small, stamps)
    data = path.read_bytes()
    path.write_bytes(data[:16] + bytes(len(data) - 16))
    with pytest.raises(SourceError, match=r"cut short or damaged") as err:
        list(open_source(path).frames())
    assert str(path) in str(err.value)


def test_an_unknown_storage_is_named(tmp_path: Path, small: list[np.ndarray],
                                     stamps: list[int]) -> None:
    path = record("ros2-sqlite3", tmp_path, small, stamps)
    meta = path / "metadata.yaml"
    meta.write_text(meta.read_text().replace("storage_identifier: sqlite3",
                                             "storage_identifier: foo"))
    with pytest.raises(SourceError, match=r"storage 'foo' is not one this reads \(sqlite3, "
                                          r"mcap\); convert it") as err:
        open_source(path)
    assert str(path) in str(err.value)


@pytest.mark.parametrize("text", ["rosbag2_bagfile_information: [unclosed",
                                  "just: a mapping\n", ""])
def test_a_broken_metadata_yaml_is_named(text: str, tmp_path: Path, small: list[np.ndarray],
                                         stamps: list[int]) -> None:
    path = record("ros2-sqlite3", tmp_path, small, stamps)
    (path / "metadata.yaml").write_text(text)
    with pytest.raises(SourceError, match=r"cannot open the ROS 2 bag") as err:
        open_source(path)
    assert str(path) in str(err.value)


def test_a_missing_storage_file_is_named(tmp_path: Path, small: list[np.ndarray],
                                         stamps: list[int]) -> None:
    path = record("ros2-mcap", tmp_path, small, stamps)
    storage_file("ros2-mcap", path).unlink()
    with pytest.raises(SourceError, match=r"cannot open the ROS 2 bag .*missing"):
        open_source(path)


def _short_image(store: Any, frame: np.ndarray, stamp: int, ros1: bool) -> Any:
    """An Image message that declares more rows than its data holds."""
    _, msg = image_message(store, frame, stamp, encoding="mono8", ros1=ros1)
    msg.height = frame.shape[0] * 2
    return msg


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("damage", ["garbage", "short data"])
def test_a_corrupt_message_in_the_middle_names_its_frame(kind: str, damage: str,
                                                         tmp_path: Path,
                                                         small: list[np.ndarray],
                                                         stamps: list[int]) -> None:
    ros1 = kind == "ros1"
    if damage == "garbage":
        raw = b"\x00\x01\x00\x00\xff\xff\xff\x7f garbage"
    else:
        msg = _short_image(ROS1_STORE if ros1 else ROS2_STORE, small[2], stamps[2], ros1)
        raw = (ROS1_STORE.serialize_ros1(msg, IMAGE) if ros1 else
               ROS2_STORE.serialize_cdr(msg, IMAGE)).tobytes()
    path = record(kind, tmp_path, small, stamps, raw={2: raw})
    source = open_source(path)
    frames = source.frames()
    assert [next(frames).index for _ in range(2)] == [0, 1]
    with pytest.raises(SourceError, match=r"frame 2 of /camera/image_raw") as err:
        next(frames)
    assert str(path) in str(err.value)
    assert "--frames A:B" in str(err.value)
    # The frames after it read.
    after = list(open_source(path, frames=FrameRange(3)).frames())
    np.testing.assert_array_equal(after[-1].image, small[4])


def test_a_corrupt_first_message_fails_at_opening(tmp_path: Path, small: list[np.ndarray],
                                                  stamps: list[int]) -> None:
    path = record("ros2-sqlite3", tmp_path, small, stamps, raw={0: b"\x00\x01\x00\x00xx"})
    with pytest.raises(SourceError, match=r"frame 0 of /camera/image_raw is corrupt"):
        open_source(path)


@pytest.mark.parametrize("kind", ["ros1", "mcap"])
def test_a_recording_renamed_still_opens_by_its_content(kind: str, tmp_path: Path,
                                                       small: list[np.ndarray],
                                                       stamps: list[int]) -> None:
    path = record(kind, tmp_path, small, stamps)
    renamed = tmp_path / "recording.dat"
    shutil.move(path, renamed)
    source = open_source(renamed)
    assert source.info.kind == kind
    np.testing.assert_array_equal(next(source.frames()).image, small[0])


def test_frames_of_a_changing_size_are_resized_and_counted(tmp_path: Path,
                                                           small: list[np.ndarray],
                                                           stamps: list[int]) -> None:
    frames = [small[0], cv2.resize(small[1], (94, 60)), small[2],
              cv2.resize(small[3], (94, 60)), cv2.resize(small[4], (376, 240))]
    source = open_source(record("mcap", tmp_path, frames, stamps))
    got = list(source.frames())
    assert {f.image.shape for f in got} == {(120, 188)}
    assert source.notes == ["2 frames of 94×60 resized to 188×120",
                            "1 frame of 376×240 resized to 188×120"]
    list(source.frames())  # counts per pass, not summed over passes
    assert source.notes[0].startswith("2 frames")



@pytest.mark.parametrize("kind", ["ros1", "mcap"])
def test_a_camera_info_that_does_not_decode_is_noted_and_left_out(
        kind: str, tmp_path: Path, small: list[np.ndarray], stamps: list[int],
        monkeypatch: pytest.MonkeyPatch) -> None:
    written = CameraInfo(188, 120, np.eye(3), np.zeros(5), "plumb_bob")
    path = record(kind, tmp_path, small, stamps, camera_info=written)

    def broken(msg: Any) -> CameraInfo:
        raise DecodeError("CameraInfo K has 4 values, not 9")

    monkeypatch.setattr(ros if kind == "ros1" else mcap_file, "camera_info", broken)
    source = open_source(path)
    assert source.info.camera_info is None
    assert any(n.startswith("camera_info not used: ") and "K has 4 values" in n
               for n in source.info.notes)
    assert len(list(source.frames())) == 5
