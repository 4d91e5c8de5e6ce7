"""MP4 recording and the visualiser overlay."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.cli_helpers import SCRIPT, child_env, default_sigint, tfalda
from tfalda_sim import video
from tfalda_sim.perception import TfaldaDetector
from tfalda_sim.rendering import Renderer, build_scene, frame_truth
from tfalda_sim.rendering.overlay import LANE_BGR, draw_observation
from tfalda_sim.sources import open_source
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


def read_back(path: Path) -> tuple[int, int, str]:
    """(frames decoded, frames the container declares, codec FOURCC) as OpenCV sees them."""
    cap = cv2.VideoCapture(str(path))
    assert cap.isOpened(), path
    fourcc = int(cap.get(cv2.CAP_PROP_FOURCC)).to_bytes(4, "little").decode()
    declared = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    frames = 0
    while cap.read()[0]:
        frames += 1
    cap.release()
    return frames, declared, fourcc


def ffmpeg_codec(path: Path) -> str:
    """The video stream's codec as ``ffmpeg -i`` names it (h264, mpeg4)."""
    import imageio_ffmpeg

    info = subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-hide_banner", "-i", str(path)],
                          capture_output=True, text=True, check=False).stderr
    match = re.search(r"Video: (\w+)", info)
    assert match, info
    return match.group(1)


@pytest.mark.parametrize("size", [(64, 48), (65, 49)])
def test_videos_are_h264_and_every_frame_reads_back(tmp_path: Path, size: tuple[int, int]
                                                    ) -> None:
    """Browsers play H.264, not MPEG-4 Part 2; odd sides are padded (yuv420p needs even)."""
    path = tmp_path / "v.mp4"
    rng = np.random.default_rng(1)
    with VideoWriter(path, 12.5) as writer:
        for _ in range(37):
            writer.write(rng.integers(0, 256, (size[1], size[0], 3), dtype=np.uint8))
    assert writer.codec == "h264"
    assert read_back(path) == (37, 37, "h264")
    assert ffmpeg_codec(path) == "h264"
    cap = cv2.VideoCapture(str(path))
    assert cap.get(cv2.CAP_PROP_FPS) == pytest.approx(12.5)
    assert cap.read()[1].shape[:2] == (size[1] + size[1] % 2, size[0] + size[0] % 2)
    cap.release()
    source = open_source(path)
    assert source.info.encoding == "h264" and sum(1 for _ in source.frames()) == 37


@pytest.mark.parametrize("ffmpeg", [False, True], ids=["no ffmpeg", "ffmpeg without x264"])
def test_without_h264_the_writer_falls_back_to_mp4v_and_says_so_once(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
        ffmpeg: bool) -> None:
    exe = video.encoder().ffmpeg if ffmpeg else None
    monkeypatch.setattr(video, "encoder", lambda: video.Encoder(exe, "mp4v", "a test"))
    monkeypatch.setattr(video, "_noted", set())
    for name in ("a.mp4", "b.mp4"):
        with VideoWriter(tmp_path / name, 25.0) as writer:
            for k in range(9):
                writer.write(np.full((48, 64), 20 * k, np.uint8))
        # OpenCV names MPEG-4 Part 2 by its decoder's tag, FMP4.
        assert read_back(tmp_path / name) == (9, 9, "FMP4")
        assert ffmpeg_codec(tmp_path / name) == "mpeg4"
    notes = capsys.readouterr().err.strip().splitlines()
    assert len(notes) == 1 and notes[0].startswith("note: writing MP4 videos as MPEG-4 Part 2 ")
    assert "a test" in notes[0]


def test_the_opencv_fallback_also_refuses_a_full_disk(tmp_path: Path) -> None:
    """OpenCV's writer only warns when a frame is lost: its file is checked when closed."""
    code = f"""
import resource, signal, numpy as np
from tfalda_sim import video
from tfalda_sim.fileio import WriteError
video.encoder = lambda: video.Encoder(None, "mp4v", "a test")
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
resource.setrlimit(resource.RLIMIT_FSIZE, (200_000, 200_000))
rng = np.random.default_rng(0)
try:
    with video.VideoWriter({str(tmp_path / "v.mp4")!r}, 25.0) as w:
        for _ in range(60):
            w.write(rng.integers(0, 256, (240, 320, 3), dtype=np.uint8))
except WriteError as exc:
    print(exc)
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=False, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith(f"cannot write {tmp_path / 'v.mp4'}: "), proc.stdout
    assert list(tmp_path.iterdir()) == []


def test_drive_writes_h264_videos_that_read_back_frame_for_frame(tmp_path: Path) -> None:
    result = tfalda("drive", "--track", "oval", "--laps", "1", "--video", "d.mp4",
                    "--camera-video", "c.mp4", "--json", cwd=tmp_path).json()
    for name in ("d.mp4", "c.mp4"):
        assert read_back(tmp_path / name) == (result["steps"], result["steps"], "h264")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.mp4", "d.mp4"]


def test_a_terminal_ctrl_c_keeps_a_playable_video(tmp_path: Path) -> None:
    """A terminal's Ctrl-C reaches the whole process group: the encoder must not be cut
    by it — the command finishes the video of the frames so far."""
    assert SCRIPT is not None
    with open(tmp_path / "err.txt", "w") as err:
        proc = subprocess.Popen(
            [SCRIPT, "drive", "--track", "oval", "--laps", "1000000000", "--video", "d.mp4"],
            cwd=tmp_path, env=child_env(), stdout=subprocess.DEVNULL, stderr=err,
            preexec_fn=lambda: (default_sigint(), os.setpgid(0, 0)))
        try:
            deadline = time.monotonic() + 120
            # The drive runs once its progress bar has shown a few frames' time.
            while not any(tmp_path.glob(".tfalda-sim-*.mp4")) or \
                    max(p.stat().st_size for p in tmp_path.glob(".tfalda-sim-*.mp4")) < 50_000:
                assert proc.poll() is None and time.monotonic() < deadline
                time.sleep(0.2)
            os.killpg(proc.pid, signal.SIGINT)
            assert proc.wait(timeout=120) == 130
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    err_text = (tmp_path / "err.txt").read_text()
    assert "Traceback" not in err_text and "kept d.mp4 up to that frame" in err_text, err_text
    frames, declared, codec = read_back(tmp_path / "d.mp4")
    assert frames == declared > 0 and codec == "h264"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.mp4", "err.txt"]
