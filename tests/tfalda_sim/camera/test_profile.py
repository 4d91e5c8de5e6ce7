"""Camera profiles: exact round trips, the named profiles, OpenCV and ROS calibration files,
and bad files refused naming the field."""

from __future__ import annotations

import math
import re
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from tfalda_sim.camera import (
    NAMED_CAMERAS,
    Bonnet,
    CameraFileError,
    CameraMount,
    FisheyeCamera,
    LensModel,
    PinholeCamera,
    load_camera,
    load_intrinsics,
    save_camera,
)
from tfalda_sim.camera.profile import named_camera_path, profile_dict

DATA = Path(__file__).parents[2] / "data" / "cameras"
MOUNT = CameraMount(height_m=0.113, forward_m=0.31, lateral_m=-0.012, pitch_rad=0.1234567,
                    roll_rad=-0.0123, yaw_rad=0.0345)


def same_camera(a: object, b: object) -> bool:
    return (type(a) is type(b) and np.array_equal(a.K, b.K) and np.array_equal(a.D, b.D)
            and (a.width, a.height, a.frame_rate_hz) == (b.width, b.height, b.frame_rate_hz)
            and a.mount == b.mount and a.bonnet.enabled == b.bonnet.enabled
            and (a.bonnet.top_row, a.bonnet.edge_drop_px) == (b.bonnet.top_row,
                                                              b.bonnet.edge_drop_px)
            and ((a.bonnet.polygon_px is None and b.bonnet.polygon_px is None)
                 or np.array_equal(a.bonnet.polygon_px, b.bonnet.polygon_px)))


CAMERAS = {
    "thesis": FisheyeCamera.default(),
    "fisheye-polygon": FisheyeCamera(
        np.array([[251.123456789, 0.31, 380.7], [0.0, 250.987654321, 236.1], [0, 0, 1]]),
        np.array([0.0213, -0.0087, 0.0031, -0.0006]), mount=MOUNT,
        bonnet=Bonnet.polygon([[0, 479], [0, 410.5], [376.25, 398], [751, 412], [751, 479]]),
        frame_rate_hz=30.0),
    "pinhole-none": PinholeCamera(
        np.array([[421.3, 0.0, 372.1], [0.0, 420.8, 241.6], [0.0, 0.0, 1.0]]),
        np.array([-0.281, 0.0862, 0.00091, -0.00043, -0.0119]), width=640, height=400,
        mount=MOUNT, bonnet=Bonnet.none()),
}


@pytest.mark.parametrize("name", list(CAMERAS))
def test_profiles_round_trip_exactly(tmp_path: Path, name: str) -> None:
    cam = CAMERAS[name]
    path = save_camera(cam, tmp_path / "cam.yaml", description="a test camera")
    back = load_camera(path)
    assert same_camera(cam, back)
    # and the file of the loaded camera is the same text
    assert save_camera(back, tmp_path / "again.yaml", "a test camera").read_text() == \
        path.read_text()


def test_named_profiles() -> None:
    assert set(NAMED_CAMERAS) == {"thesis", "reference-car"}
    assert same_camera(load_camera("thesis"), FisheyeCamera.default())
    ref = load_camera("reference-car")
    assert ref.bonnet.polygon_px is not None and (ref.width, ref.height) == (752, 480)
    cam = FisheyeCamera.default()
    assert load_camera(cam) is cam


def test_hand_written_profile_in_degrees(tmp_path: Path) -> None:
    data = profile_dict(CAMERAS["thesis"])
    m = data["mount"]
    for angle in ("pitch", "roll", "yaw"):
        m[f"{angle}_deg"] = math.degrees(m.pop(f"{angle}_rad"))
    m["pitch_deg"] = 5.5
    (tmp_path / "deg.yaml").write_text(yaml.safe_dump(data))
    cam = load_camera(tmp_path / "deg.yaml")
    assert cam.mount.pitch_rad == pytest.approx(math.radians(5.5), abs=1e-15)


def test_opencv_filestorage_yaml_and_xml(tmp_path: Path) -> None:
    """Files written by cv2.FileStorage as OpenCV's calibration sample does, after
    cv2.calibrateCamera (5 coefficients) and cv2.fisheye.calibrate (4, shape (4, 1))."""
    pin, fish = CAMERAS["pinhole-none"], CAMERAS["fisheye-polygon"]
    for suffix in (".yaml", ".xml"):
        for cam, D in ((pin, pin.D.reshape(1, 5)), (fish, fish.D.reshape(4, 1))):
            path = tmp_path / f"{cam.lens.value}{suffix}"
            fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
            fs.write("calibration_time", "Tue Dec  1 12:00:00 2026")
            fs.write("image_width", cam.width)
            fs.write("image_height", cam.height)
            fs.write("camera_matrix", cam.K)
            fs.write("distortion_coefficients", D)
            fs.write("avg_reprojection_error", 0.21)
            fs.release()
            intr = load_intrinsics(path)
            assert intr.lens is cam.lens and (intr.width, intr.height) == (cam.width, cam.height)
            assert np.array_equal(intr.K, cam.K) and np.array_equal(intr.D, cam.D)
            with pytest.raises(CameraFileError, match="carries no mount"):
                load_camera(path)
            placed = load_camera(path, mount=MOUNT)
            assert placed.mount == MOUNT and not placed.bonnet.enabled
            assert np.allclose(placed.project(np.array([[0.1, 0.05, 1.0]])),
                               cam.project(np.array([[0.1, 0.05, 1.0]])))
    # Four coefficients forced to the pinhole model: (k1, k2, p1, p2), k3 = 0.
    fs = cv2.FileStorage(str(tmp_path / "four.yaml"), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", pin.width)
    fs.write("image_height", pin.height)
    fs.write("camera_matrix", pin.K)
    fs.write("distortion_coefficients", pin.D[:4].reshape(1, 4))
    fs.release()
    assert load_intrinsics(tmp_path / "four.yaml").lens is LensModel.FISHEYE
    four = load_intrinsics(tmp_path / "four.yaml", lens=LensModel.PINHOLE)
    assert four.lens is LensModel.PINHOLE and np.array_equal(four.D, [*pin.D[:4], 0.0])


def test_intrinsics_of_a_profile_name_are_its_files() -> None:
    for name in NAMED_CAMERAS:
        by_name, by_file = load_intrinsics(name), load_intrinsics(named_camera_path(name))
        assert by_name.lens is by_file.lens and np.array_equal(by_name.K, by_file.K)
        assert np.array_equal(by_name.D, by_file.D)
    with pytest.raises(CameraFileError, match="unknown camera 'no-such-car'"):
        load_intrinsics("no-such-car")


@pytest.mark.parametrize("name,lens", [("ros-plumb-bob.yaml", LensModel.PINHOLE),
                                       ("ros-equidistant.yaml", LensModel.FISHEYE)])
def test_ros_camera_info(name: str, lens: LensModel) -> None:
    intr = load_intrinsics(DATA / name)
    raw = yaml.safe_load((DATA / name).read_text())
    assert intr.lens is lens and (intr.width, intr.height) == (752, 480)
    assert np.array_equal(intr.K.ravel(), raw["camera_matrix"]["data"])
    assert np.array_equal(intr.D, raw["distortion_coefficients"]["data"])
    cam = load_camera(DATA / name, mount=MOUNT)
    assert cam.lens is lens


def _profile(tmp_path: Path, **changes: object) -> Path:
    data = profile_dict(CAMERAS["fisheye-polygon"])
    for key, value in changes.items():
        target, *rest = key.split("__")
        if rest:
            if value is None:
                data[target].pop(rest[0])
            else:
                data[target][rest[0]] = value
        elif value is None:
            data.pop(target)
        else:
            data[target] = value
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.parametrize("changes,match", [
    ({"colour": "grey"}, "unknown key 'colour' in the profile"),
    ({"mount__tilt_deg": 3.0}, "unknown key 'tilt_deg' in mount"),
    ({"mount__height_m": None}, r"mount.height_m is missing"),
    ({"mount__pitch_deg": 5.0}, "both pitch_rad and pitch_deg"),
    ({"mount__height_m": -0.2}, "height_m must be in"),
    ({"mount__pitch_rad": 2.0}, "pitch_rad must lie within"),
    ({"lens": "kannala"}, "lens must be one of fisheye, pinhole"),
    ({"distortion": [0.1, 0.2]}, r"distortion of a fisheye lens must be a list of 4 numbers"),
    ({"camera_matrix": [[1, 0], [0, 1]]}, "camera_matrix must be a list of 3 rows"),
    ({"camera_matrix": [[-250.0, 0, 376], [0, 250, 240], [0, 0, 1]]}, "positive focal"),
    ({"image_width_px": 752.5}, "image_width_px must be an integer"),
    ({"image_width_px": 200},
     r"\(cx\) must be in \[-0.5, 199.5\] px \(the principal point lies in the 200×480"),
    ({"frame_rate_hz": -1.0}, "frame_rate_hz must be in"),
    ({"frame_rate_hz": ".nan"}, "frame_rate_hz must be a number"),
    ({"bonnet": {"circle": 3}}, "bonnet must be one of"),
    ({"bonnet": {"polygon_px": [[1, 2], [3, 4]]}}, "needs 3–1000 vertices"),
    ({"bonnet": {"none": False}}, "bonnet.none must be true"),
    ({"bonnet": {"parabola": {"top_row_px": 440}}}, "edge_drop_px is missing"),
    ({"format": "tfalda-sim-camera/9"}, "is not 'tfalda-sim-camera/1'"),
    ({"frame_rate_hz": None}, "frame_rate_hz is missing"),
])
def test_bad_profiles_are_refused_naming_the_field(tmp_path: Path, changes: dict,
                                                   match: str) -> None:
    with pytest.raises(CameraFileError, match=match):
        load_camera(_profile(tmp_path, **changes))


def test_nan_in_the_file(tmp_path: Path) -> None:
    path = _profile(tmp_path)
    path.write_text(path.read_text().replace("frame_rate_hz: 30.0", "frame_rate_hz: .nan"))
    with pytest.raises(CameraFileError, match="frame_rate_hz must be finite"):
        load_camera(path)


@pytest.mark.parametrize("content,match", [
    (b"format: tfalda-sim-camera/1\nlens: [unclosed\n", r"not valid YAML \(line"),
    (b"format: a\nformat: b\n", "key 'format' is given twice"),
    (b"\xff\xfe\x00binary", "not a text file"),
    (b"- 1\n- 2\n", "not a camera file"),
    (b"width: 752\n", "neither 'format: tfalda-sim-camera/1'"),
    (b"%YAML:1.0\n---\nimage_width: 752\n", "no camera_matrix"),
    (b"image_width: 752\nimage_height: 480\ndistortion_model: rational_polynomial\n",
     "distortion_model 'rational_polynomial' is not supported"),
])
def test_corrupt_and_foreign_files(tmp_path: Path, content: bytes, match: str) -> None:
    path = tmp_path / "cam.yaml"
    path.write_bytes(content)
    with pytest.raises(CameraFileError, match=match):
        load_camera(path, mount=MOUNT)


def test_missing_file_unknown_name_and_folder(tmp_path: Path) -> None:
    with pytest.raises(CameraFileError, match=r"unknown camera 'sony'.*thesis, reference-car"):
        load_camera("sony")
    with pytest.raises(CameraFileError, match="no such file"):
        load_camera(tmp_path / "nothing.yaml")
    with pytest.raises(CameraFileError, match="is a folder"):
        load_camera(tmp_path)
    with pytest.raises(TypeError, match="profile name, a path or a Camera"):
        load_camera(3)  # type: ignore[arg-type]


@pytest.mark.parametrize("content,match", [
    (b"? [a, b]\n: 1\n", "a key that is a list"),
    (b"image_width: 752\nimage_height: 480\ndistortion_model: [equidistant]\n",
     "is not supported"),
    (b"%YAML 1.1\n---\nwidth: 752\n", "neither 'format"),  # plain YAML, not OpenCV's
    (b"%YAML:1.0\n---\nimage_width: .Nan\nimage_height: 480\ncamera_matrix: !!opencv-matrix\n"
     b"   rows: 3\n   cols: 3\n   dt: d\n   data: [1., 0., 2., 0., 1., 2., 0., 0., 1.]\n"
     b"distortion_coefficients: !!opencv-matrix\n   rows: 1\n   cols: 4\n   dt: d\n"
     b"   data: [0., 0., 0., 0.]\n", r"image_width must be an integer in \[64, 8192\], got nan"),
    (b"%YAML:1.0\n---\ncamera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n"
     b"   data: [1., 0., 2., 0., 1., 2., 0., 0., 1.]\n", "camera_matrix.dt is missing"),
])
def test_hostile_camera_files(tmp_path: Path, content: bytes, match: str) -> None:
    path = tmp_path / "cam.yaml"
    path.write_bytes(content)
    with pytest.raises(CameraFileError, match=match):
        load_camera(path, mount=MOUNT)


def test_a_huge_integer(tmp_path: Path) -> None:
    path = _profile(tmp_path)
    path.write_text(path.read_text().replace("frame_rate_hz: 30.0", "frame_rate_hz: " + "9" * 400))
    with pytest.raises(CameraFileError, match="frame_rate_hz is too large"):
        load_camera(path)


def test_devices_are_not_read(tmp_path: Path) -> None:
    with pytest.raises(CameraFileError, match="not a regular file"):
        load_camera("/dev/zero")


def test_pickled_cameras_stay_read_only_and_the_default_bonnet_follows_the_size() -> None:
    import pickle

    ref = pickle.loads(pickle.dumps(load_camera("reference-car")))
    assert not ref.K.flags.writeable and not ref.bonnet.polygon_px.flags.writeable
    K = np.array([[600.0, 0.0, 639.5], [0.0, 600.0, 399.5], [0.0, 0.0, 1.0]])
    assert not FisheyeCamera(K, np.zeros(4), width=1280, height=800).bonnet.enabled
    assert FisheyeCamera(FisheyeCamera.default().K, np.zeros(4)).bonnet.enabled
    with pytest.raises(ValueError, match="top_row"):
        FisheyeCamera(K, np.zeros(4), width=1280, height=800, bonnet=Bonnet(top_row=900.0))


@pytest.mark.parametrize("written,field,fix", [
    ("3e1", "frame_rate_hz", "write 30.0"),
    ("1e9", "frame_rate_hz", "write 1000000000.0"),
    ("1.0e9", "frame_rate_hz", "write 1000000000.0"),
    ("2E-1", "mount.height_m", "write 0.2"),
    ("1e20", "mount.forward_m", "write 1.0e+20"),
])
def test_an_exponent_yaml_reads_as_text_is_explained(tmp_path: Path, written: str, field: str,
                                                     fix: str) -> None:
    """PyYAML (YAML 1.1) reads 1e9 as a string: the error says so and how to write it."""
    path = _profile(tmp_path)
    key = field.split(".")[-1]
    lines = [f"{ln.split(':')[0]}: {written}" if ln.strip().startswith(f"{key}:") else ln
             for ln in path.read_text().splitlines()]
    path.write_text("\n".join(lines) + "\n")
    assert yaml.safe_load(path.read_text())  # still YAML, the number now text
    with pytest.raises(CameraFileError, match=rf"{field} must be a number, got '{written}': "
                       r"YAML 1\.1 \(PyYAML.*reads .* as text.*" + re.escape(fix)):
        load_camera(path)
    if written == "1e9":
        from tests.cli_helpers import tfalda

        run = tfalda("camera", "show", path, cwd=tmp_path, code=2)
        assert "got '1e9': YAML 1.1" in run.err and "write 1000000000.0" in run.err


@pytest.mark.parametrize("name", ["thesis", "reference-car"])
def test_a_camera_as_camera_info_and_back_is_the_same_lens(name: str) -> None:
    """What a recording's /camera/camera_info carries is the camera's calibration."""
    from tfalda_sim.camera.profile import intrinsics_from_camera_info
    from tfalda_sim.camera.ros_info import camera_info_of

    cam = load_camera(name)
    info = camera_info_of(cam)
    assert info.distortion_model == {"fisheye": "equidistant", "pinhole": "plumb_bob"}[
        cam.lens.value]
    back = intrinsics_from_camera_info("topic", info.width_px, info.height_px, info.K, info.D,
                                       info.distortion_model).camera(cam.mount)
    assert back.lens is cam.lens and (back.width, back.height) == (cam.width, cam.height)
    np.testing.assert_array_equal(back.K, cam.K)
    np.testing.assert_array_equal(back.D, cam.D)
