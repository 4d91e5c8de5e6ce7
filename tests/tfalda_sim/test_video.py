"""MP4 recording and the visualiser overlay."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from tfalda_sim.perception import TfaldaDetector
from tfalda_sim.rendering import Renderer, build_scene, frame_truth
from tfalda_sim.rendering.overlay import LANE_BGR, draw_observation
from tfalda_sim.tracks import load_named
from tfalda_sim.video import VideoWriter


def test_frames_round_trip_through_an_mp4(tmp_path: Path) -> None:
    path = tmp_path / "v.mp4"
    with VideoWriter(path, 25.0) as writer:
        for k in range(12):
            writer.write(np.full((48, 64), 20 * k, np.uint8))
    cap = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        frames.append(frame)
    assert len(frames) == 12 and frames[0].shape == (48, 64, 3)
    means = [float(f.mean()) for f in frames]
    assert abs(means[5] - 100) <= 8  # lossy codec, YUV round trip
    assert np.all(np.diff(means) > 10)  # the frames come back in order
    assert cap.get(cv2.CAP_PROP_FPS) == pytest.approx(25.0)


def test_bad_frames_and_paths_are_named(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"\.mp4"):
        VideoWriter(tmp_path / "v.avi", 25.0)
    with pytest.raises(ValueError, match="fps"):
        VideoWriter(tmp_path / "v.mp4", 0.0)
    with VideoWriter(tmp_path / "v.mp4", 25.0) as w:
        w.write(np.zeros((48, 64, 3), np.uint8))
        with pytest.raises(ValueError, match="differs"):
            w.write(np.zeros((40, 64, 3), np.uint8))
        with pytest.raises(ValueError, match="uint8"):
            w.write(np.zeros((48, 64), np.float32))


def test_an_interrupted_recording_keeps_the_existing_file(tmp_path: Path) -> None:
    path = tmp_path / "v.mp4"
    path.write_bytes(b"precious")
    with pytest.raises(KeyboardInterrupt), VideoWriter(path, 25.0) as w:
        w.write(np.zeros((48, 64), np.uint8))
        raise KeyboardInterrupt
    assert path.read_bytes() == b"precious"
    assert [p.name for p in tmp_path.iterdir()] == ["v.mp4"]


def test_overlay_draws_the_lanes_where_they_are() -> None:
    renderer = Renderer()
    track = load_named("straight")
    x, y, h = (float(v) for v in track.pose(2.0, -0.2))
    frame = renderer.render(build_scene(track), (x, y, h))
    obs = TfaldaDetector().process(frame)
    truth = frame_truth(track, renderer.camera, (x, y, h))
    image = draw_observation(frame, obs, truth=truth, text="test")
    assert image.shape == (480, 752, 3) and image.dtype == np.uint8
    for lane in obs.lanes:
        mid = np.rint((lane[:2] + lane[2:]) / 2).astype(int)
        patch = image[mid[1] - 2:mid[1] + 3, mid[0] - 2:mid[0] + 3].reshape(-1, 3)
        assert np.any(np.all(np.abs(patch.astype(int) - LANE_BGR) < 40, axis=1))
    with pytest.raises(ValueError, match="uint8"):
        draw_observation(frame.astype(np.float32), obs)
