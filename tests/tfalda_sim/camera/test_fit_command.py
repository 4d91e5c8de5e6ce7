"""``tfalda-sim camera fit SOURCE`` as a user runs it: a video and a ROS bag of a weaving
car, the recording's frame rate and camera_info, refusals with their overlay, two marked
lines on the reference frame, and bad input as one line."""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.cli_helpers import tfalda
from tests.tfalda_sim.camera.test_clip import clips, render_clip
from tests.tfalda_sim.sources.recordings import write_ros1_bag
from tfalda_sim.camera import CameraMount, load_camera, save_camera
from tfalda_sim.sources import CameraInfo
from tfalda_sim.video import VideoWriter

REFERENCE = Path(__file__).parents[2] / "data" / "reference"


def _check_mount(doc: dict, truth: CameraMount, *, angle_deg: float = 0.5,
                 height_m: float = 0.005) -> None:
    assert abs(doc["pitch_deg"] - math.degrees(truth.pitch_rad)) < angle_deg, doc
    assert abs(doc["roll_deg"] - math.degrees(truth.roll_rad)) < angle_deg, doc
    assert abs(doc["yaw_deg"] - math.degrees(truth.yaw_rad)) < angle_deg, doc
    assert abs(doc["height_m"] - truth.height_m) < height_m, doc


def test_a_video_of_a_weaving_car(tmp_path: Path) -> None:
    """An H.264 video at 30 frames/s: the mount, the video's rate in the profile, the
    spreads in strict JSON, the overlay; the text output names the assumption's figures."""
    clip = clips()[6]  # 752×480 fisheye
    with VideoWriter(tmp_path / "clip.mp4", 30.0) as video:
        for f in clip.frames:
            video.write(f.image)
    save_camera(clip.camera.replace(mount=CameraMount()), tmp_path / "lens.yaml")
    run = tfalda("camera", "fit", "clip.mp4", "--intrinsics", "lens.yaml", "--out",
                 "car.yaml", "--json", cwd=tmp_path)
    doc = run.json()
    _check_mount(doc, clip.camera.mount)
    assert doc["frame_rate_hz"] == pytest.approx(30.0) and doc["frame_rate_from"] == \
        "the recording"
    assert doc["frames"]["used"] == len(clip.frames) == doc["frames"]["source"]
    assert doc["lateral_m"] == 0.0 and doc["roll_fitted"]
    spread = doc["spread"]
    assert {"pitch_deg", "roll_deg", "height_m", "heading_deg", "car_offset_m",
            "residual_px"} <= set(spread)
    assert spread["heading_deg"]["sigma"] > 3.0 and spread["pitch_deg"]["sigma"] < 0.3
    assert doc["residual_px"] < 1.0
    profile = load_camera(tmp_path / "car.yaml")
    assert profile.frame_rate_hz == pytest.approx(30.0)
    assert cv2.imread(str(tmp_path / "car-fit.png")).shape == (480, 752, 3)
    text = tfalda("camera", "fit", "clip.mp4", "--intrinsics", "lens.yaml", "--out",
                  "car.yaml", "--force", cwd=tmp_path).out
    assert "spread (σ)" in text and "heading ±" in text and "30 Hz (the recording)" in text


def test_a_bag_gives_the_lens_and_the_rate(tmp_path: Path) -> None:
    """A ROS 1 bag with a camera_info topic and 20 frames/s stamps: no --intrinsics needed,
    the rate from the stamps; a pinhole lens (ROS plumb_bob)."""
    clip = clips()[7]  # 752×480 pinhole
    stamps = [int(1e9 + k * 5e7) for k in range(len(clip.frames))]
    lens = CameraInfo(clip.camera.width, clip.camera.height, np.array(clip.camera.K),
                      np.array(clip.camera.D), "plumb_bob")
    write_ros1_bag(tmp_path / "drive.bag", [f.image for f in clip.frames], stamps,
                   camera_info=lens)
    doc = tfalda("camera", "fit", "drive.bag", "--out", "car.yaml", "--json",
                 cwd=tmp_path).json()
    _check_mount(doc, clip.camera.mount)
    assert doc["intrinsics_from"] == "the recording's camera_info" and doc["lens"] == "pinhole"
    assert doc["frame_rate_hz"] == pytest.approx(20.0)
    no_lens = tmp_path / "bare.bag"
    write_ros1_bag(no_lens, [f.image for f in clip.frames], stamps)
    run = tfalda("camera", "fit", no_lens, "--out", "b.yaml", cwd=tmp_path, code=2)
    assert "has no camera_info" in run.err and "--intrinsics" in run.err
    assert len(run.err.strip().splitlines()) == 1


def test_frames_that_disagree_are_refused_with_an_overlay(tmp_path: Path) -> None:
    """A folder with frames of two mounts 6 cm apart: exit 2, one line naming the
    parameter and the overlay, which is written; no profile."""
    a = clips()[6]
    b = render_clip(a.camera.with_mount(height_m=a.camera.mount.height_m + 0.06),
                    np.random.default_rng(5))
    (tmp_path / "mixed").mkdir()
    for k, f in enumerate(a.frames + b.frames):
        cv2.imwrite(str(tmp_path / "mixed" / f"f{k:03d}.png"), f.image)
    save_camera(a.camera.replace(mount=CameraMount()), tmp_path / "lens.yaml")
    run = tfalda("camera", "fit", "mixed", "--intrinsics", "lens.yaml", "--rate", "30",
                 "--out", "car.yaml", cwd=tmp_path, code=2)
    assert "disagree on the" in run.err and "car-fit.png" in run.err, run.err
    assert len(run.err.strip().splitlines()) == 1
    assert (tmp_path / "car-fit.png").exists() and not (tmp_path / "car.yaml").exists()


def test_an_implausible_single_frame_is_refused_naming_the_height(tmp_path: Path) -> None:
    """Three marked lines a few pixels apart on the reference frame: the camera would be
    metres high: refused naming the height, the overlay written for inspection."""
    labels = json.loads((REFERENCE / "straight-road.labels.json").read_text())
    centre = [p[:2] for p in next(m["points"] for m in labels["markings"]
                                  if m["kind"] == "centre_line")]
    shifted = {"centre": centre, "left": [[u - 3, v] for u, v in centre],
               "right": [[u + 3, v] for u, v in centre]}
    (tmp_path / "pts.json").write_text(json.dumps(shifted))
    run = tfalda("camera", "fit", REFERENCE / "straight-road.png", "--intrinsics",
                 "reference-car", "--points", "pts.json", "--out", "c.yaml", cwd=tmp_path,
                 code=2)
    assert "height" in run.err and "outside 0.03–1 m" in run.err and "c-fit.png" in run.err
    assert (tmp_path / "c-fit.png").exists() and not (tmp_path / "c.yaml").exists()


def test_two_marked_lines_on_the_reference_frame(tmp_path: Path) -> None:
    """--points with the centre line and one neighbour fits (roll taken as 0) within a few
    millimetres of reference-car."""
    labels = json.loads((REFERENCE / "straight-road.labels.json").read_text())
    by_kind = {m["kind"]: [p[:2] for p in m["points"]] for m in labels["markings"]
               if m["road"] == "ego"}
    ref = load_camera("reference-car").mount
    for side, kind in (("right", "right_line"), ("left", "left_line")):
        (tmp_path / "pts.json").write_text(json.dumps({"centre": by_kind["centre_line"],
                                                       side: by_kind[kind]}))
        doc = tfalda("camera", "fit", REFERENCE / "straight-road.png", "--intrinsics",
                     "reference-car", "--points", "pts.json", "--out", f"{side}.yaml",
                     "--json", cwd=tmp_path).json()
        assert not doc["roll_fitted"] and doc["roll_deg"] == 0.0
        assert abs(doc["height_m"] - ref.height_m) < 0.006, doc
        assert abs(doc["pitch_deg"] - math.degrees(ref.pitch_rad)) < 1.0, doc


@pytest.mark.parametrize("argv,says", [
    (["nothing-here.mp4", "--fit-focal"], "no such file"),
    (["clip", "--fit-focal", "--frames", "5:2"], "frame range '5:2' is empty"),
    (["clip", "--fit-focal", "--lane-width", "3"], "--lane-width"),
    (["clip", "--fit-focal", "--rate", "0.5"], "--rate"),
    (["clip", "--intrinsics", "reference-car", "--points", "p.json"],
     "--points marks the lines of one image"),
    (["clip", "--intrinsics", "reference-car", "--lateral-m", "7"], "--lateral-m"),
])
def test_bad_input_is_one_line(tmp_path: Path, argv: list[str], says: str) -> None:
    (tmp_path / "clip").mkdir()
    for k in range(3):
        cv2.imwrite(str(tmp_path / "clip" / f"{k}.png"), np.full((480, 752), 40, np.uint8))
    (tmp_path / "p.json").write_text('{"centre": [[1, 2], [3, 4]], "left": [[5, 6], [7, 8]]}')
    run = tfalda("camera", "fit", *argv, "--out", "c.yaml", cwd=tmp_path, code=2)
    assert says in run.err, run.err
    assert len(run.err.strip().splitlines()) == 1 or run.err.startswith("usage:")
    assert not (tmp_path / "c.yaml").exists()
