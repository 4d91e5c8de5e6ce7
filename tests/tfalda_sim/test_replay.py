"""The endless-loop replay of videos (tfalda-sim replay); other sources:
test_replay_sources.py."""

from __future__ import annotations

import json
import os
import re
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.cli_helpers import tfalda
from tfalda_sim import replay as replay_module
from tfalda_sim.cli import main
from tfalda_sim.perception import HoughDetector
from tfalda_sim.replay import Detector, replay
from tfalda_sim.sources import SourceError, open_source, to_grey
from tfalda_sim.video import VideoWriter

FRAMES = 6


def _road(k: int, size: tuple[int, int] = (752, 480), colour: bool = False) -> np.ndarray:
    """A dark frame with two bright lane lines in perspective (moving a little with k)."""
    w, h = size
    img = np.full((h, w, 3) if colour else (h, w), 35, np.uint8)
    white = (250, 240, 255) if colour else 250
    sx, sy = w / 752, h / 480
    for x_top, x_bottom in ((330 + k, 60 + k), (430 + k, 700 + k)):
        cv2.line(img, (int(x_top * sx), int(250 * sy)), (int(x_bottom * sx), int(470 * sy)),
                 white, max(2, int(14 * sx)))
    return img


def _grey_frames(path: Path, size: tuple[int, int] = (752, 480)) -> list[np.ndarray]:
    """A video's frames as grey frames of ``size`` (as replay reads them)."""
    return [to_grey(f.image, size) for f in open_source(path).frames()]


def _write(path: Path, n: int = FRAMES, **kw) -> Path:
    with VideoWriter(path, 25.0) as writer:
        for k in range(n):
            writer.write(_road(k, **kw))
    return path


@pytest.fixture
def video(tmp_path: Path) -> Path:
    return _write(tmp_path / "drive.mp4")


def test_a_video_source_gives_the_frames_in_order(video: Path) -> None:
    source = open_source(video)
    frames = [to_grey(f.image, (752, 480)) for f in source.frames()]
    assert len(frames) == FRAMES and source.info.kind == "video"
    assert all(f.shape == (480, 752) and f.dtype == np.uint8 for f in frames)
    assert source.info.rate_hz == pytest.approx(25.0)
    # The lines move right by a pixel a frame: the frames come back in order.
    cols = [int(np.argmax(f[465, 400:] > 150)) for f in frames]
    assert cols == sorted(cols) and cols[-1] > cols[0]
    again = [to_grey(f.image, (752, 480)) for f in source.frames()]  # another pass
    assert all(np.array_equal(a, b) for a, b in zip(frames, again, strict=True))


def test_colour_and_other_sizes_are_converted(tmp_path: Path) -> None:
    path = _write(tmp_path / "small.mp4", size=(376, 240), colour=True)
    result = replay(path, Detector.HOUGH, loops=1)
    assert result["frames"] == FRAMES and result["detections_per_frame"] >= 2
    assert result["source_size_px"] == [376, 240]
    assert result["conversions"] == ["colour → grey", "376×240 → 752×480 px"]
    wide = replay(_write(tmp_path / "wide.mp4", size=(640, 240)), Detector.HOUGH)
    assert "aspect ratio changed" in wide["conversions"]
    assert "colour → grey" not in wide["conversions"]


def test_unreadable_files_get_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(SourceError, match="no such file"):
        replay(tmp_path / "missing.mp4", Detector.HOUGH)
    text = tmp_path / "notes.mp4"
    text.write_text("not a video")
    with pytest.raises(SourceError):
        replay(text, Detector.HOUGH)
    # A real AVI whose codec no decoder knows (its FOURCC rewritten).
    avi = tmp_path / "mj.avi"
    writer = cv2.VideoWriter(str(avi), cv2.VideoWriter_fourcc(*"MJPG"), 25, (64, 48))
    for _ in range(3):
        writer.write(np.full((48, 64, 3), 90, np.uint8))
    writer.release()
    unknown = tmp_path / "unknown.avi"
    unknown.write_bytes(avi.read_bytes().replace(b"MJPG", b"QQQQ"))
    with pytest.raises(SourceError, match="re-encode"):
        replay(unknown, Detector.HOUGH)
    cut = tmp_path / "cut.mp4"
    cut.write_bytes(_write(tmp_path / "whole.mp4").read_bytes()[:2000])
    with pytest.raises(SourceError, match="re-encode"):
        replay(cut, Detector.HOUGH)


@pytest.fixture(scope="module")
def camera_video(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Six camera frames of the simulator on the oval's straight (env.camera_frame)."""
    from tfalda_sim.envs import TfaldaTrackEnv

    env = TfaldaTrackEnv(track="oval")
    env.reset(seed=0, options={"start": (0.5, -0.2, 0.0)})
    path = tmp_path_factory.mktemp("camera") / "camera.mp4"
    with VideoWriter(path, 50.0) as writer:
        for _ in range(FRAMES):
            env.step(np.zeros(1, np.float32))
            writer.write(env.camera_frame())
    return path


@pytest.mark.parametrize("detector", list(Detector))
def test_replay_runs_n_loops_and_annotates(camera_video: Path, tmp_path: Path,
                                           detector: Detector) -> None:
    out = tmp_path / "annotated.mp4"
    result = replay(camera_video, detector, loops=3, out=out)
    assert result["frames"] == 3 * FRAMES and result["loops_completed"] == 3
    assert result["stopped"] == "loops" and result["detector_ms_median"] > 0
    # Both lines of the ego lane (Hough: segments; TFALDA: lanes the LIS kept).
    assert result["detections_per_frame"] >= (2 if detector is Detector.HOUGH else 3)
    annotated = _grey_frames(out)
    assert len(annotated) == 3 * FRAMES
    if detector is Detector.HOUGH:  # the red segments drawn on the grey frame
        bgr = next(iter(cv2.VideoCapture(str(out)).read()[1:]))
        assert (bgr[..., 2].astype(int) - bgr[..., 1] > 100).sum() > 100


def _interrupt_on_call(monkeypatch: pytest.MonkeyPatch, n: int,
                       exc: type[BaseException] = KeyboardInterrupt) -> None:
    """HoughDetector.detect raises ``exc`` on its n-th call."""
    calls = {"n": 0}
    real = HoughDetector.detect

    def detect(self, frame):
        calls["n"] += 1
        if calls["n"] == n:
            raise exc
        return real(self, frame)

    monkeypatch.setattr(HoughDetector, "detect", detect)


@pytest.mark.parametrize("at, frames, loops", [(2 * FRAMES + 3, 2 * FRAMES + 2, 2),
                                               (2 * FRAMES + 1, 2 * FRAMES, 2),
                                               (1, 0, 0)])
def test_ctrl_c_stops_cleanly_and_keeps_the_annotated_video(
        video: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        at: int, frames: int, loops: int) -> None:
    _interrupt_on_call(monkeypatch, at)
    out = tmp_path / "partial.mp4"
    result = replay(video, Detector.HOUGH, loops=None, out=out)
    assert result["stopped"] == "interrupted"
    assert result["frames"] == frames and result["loops_completed"] == loops
    if frames:
        assert len(_grey_frames(out)) == frames
    else:
        assert not out.exists() and list(tmp_path.glob(".partial*")) == []


def test_an_error_mid_replay_leaves_an_existing_out_untouched(
        video: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "old.mp4"
    out.write_bytes(b"the user's video")
    _interrupt_on_call(monkeypatch, 4, RuntimeError)
    with pytest.raises(RuntimeError):
        replay(video, Detector.HOUGH, loops=2, out=out)
    assert out.read_bytes() == b"the user's video"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["drive.mp4", "old.mp4"]


def test_ctrl_c_exit_codes(video: Path, monkeypatch: pytest.MonkeyPatch, capsys) -> None:
    _interrupt_on_call(monkeypatch, 3)
    assert main(["replay", str(video), "--detector", "hough", "--loops", "3"]) == 130
    assert "(interrupted)" in capsys.readouterr().out
    _interrupt_on_call(monkeypatch, 3)
    assert main(["replay", str(video), "--detector", "hough", "--forever", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["stopped"] == "interrupted"


def test_forever_stops_on_sigint_from_the_command_line(video: Path) -> None:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    # A shell starts background jobs with SIGINT ignored, and Python keeps an ignored
    # SIGINT: give the child the default disposition, as a terminal would.
    proc = subprocess.Popen([sys.executable, "-m", "tfalda_sim", "replay", str(video),
                             "--detector", "hough", "--forever"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        # Wait until frames flow: the progress bar on stderr counts one or more.
        deadline = time.monotonic() + 120
        seen = b""
        while not re.search(rb"[1-9]\d*frame", seen) and time.monotonic() < deadline:
            ready, _, _ = select.select([proc.stderr], [], [], 1.0)
            if ready:
                chunk = os.read(proc.stderr.fileno(), 4096)
                if not chunk:
                    break  # the replay ended by itself: it must not
                seen += chunk
        assert re.search(rb"[1-9]\d*frame", seen), seen[-500:]
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 0, out
    frames = int(re.search(rb": (\d+) frames", out).group(1))
    assert frames > 0 and b"(interrupted)" in out


def test_replay_cli_json_and_bad_options(video: Path, tmp_path: Path, capsys) -> None:
    assert main(["replay", str(video), "--detector", "hough", "--loops", "2", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["frames"] == 2 * FRAMES and out["hough_preset"] == "simulator"
    assert main(["replay", str(tmp_path / "none.mp4"), "--detector", "tfalda"]) == 2
    assert "none.mp4: no such file or folder" in capsys.readouterr().err
    assert main(["replay", str(video), "--detector", "hough", "--out", str(video),
                 "--force"]) == 2
    assert "is the --source input" in capsys.readouterr().err
    existing = tmp_path / "old.mp4"
    existing.write_bytes(b"keep me")
    assert main(["replay", str(video), "--detector", "hough", "--out", str(existing)]) == 2
    assert existing.read_bytes() == b"keep me"
    for bad in (["--loops", "0"], ["--loops", "2", "--forever"], ["--detector", "canny"]):
        args = ["replay", str(video), *(["--detector", "hough"] if "--detector" not in bad
                                         else []), *bad]
        assert main(args) == 2


def test_stages_writes_the_seeds_2x2_view(video: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "stages.mp4"
    assert main(["replay", str(video), "--detector", "hough", "--out", str(out),
                 "--stages", "--json"]) == 0
    source = open_source(out)
    assert (source.info.width_px, source.info.height_px) == (1504, 518)
    assert len(list(source.frames())) == FRAMES
    capsys.readouterr()
    for bad in (["--detector", "tfalda", "--out", str(tmp_path / "t.mp4")],
                ["--detector", "hough"]):
        assert main(["replay", str(video), *bad, "--stages"]) == 2
        assert "--stages" in capsys.readouterr().err
    with pytest.raises(ValueError, match="hough"):
        replay(video, Detector.TFALDA, stages=True)


def test_the_seed_preset_is_the_seeds_numbers(video: Path) -> None:
    seed = replay(video, Detector.HOUGH, hough=replay_module.HoughPreset.SEED)
    assert seed["hough_preset"] == "seed" and seed["frames"] == FRAMES
    # The synthetic lines are 250 DN: bright enough for the seed's 0.9 threshold too.
    assert seed["detections_per_frame"] >= 2


def test_loops_equal_to_the_default_still_excludes_forever(video: Path, capsys) -> None:
    """Found by the fuzz: argparse let `--loops=1 --forever` through (1 is the default)."""
    assert main(["replay", str(video), "--detector", "hough", "--loops=1", "--forever"]) == 2
    assert "not allowed with argument" in capsys.readouterr().err


def test_max_frames_bounds_forever_and_its_video(video: Path, tmp_path: Path) -> None:
    """--forever --out grew without bound on disk: --max-frames stops it after N frames,
    with the video of exactly those frames."""
    out = tmp_path / "o.mp4"
    run = tfalda("replay", video, "--detector", "hough", "--forever", "--max-frames", "15",
                 "--out", out, "--json", cwd=tmp_path)
    result = run.json()
    assert result["frames"] == 15 and result["stopped"] == "max_frames"
    assert result["loops_completed"] == 15 // FRAMES and result["out"] == str(out)
    source = open_source(out)
    assert source.info.encoding == "h264" and sum(1 for _ in source.frames()) == 15
    assert "--max-frames" not in run.err  # bounded: no note about the growth
    # With --loops, whichever comes first.
    assert tfalda("replay", video, "--detector", "tfalda", "--loops", "5", "--max-frames", "7",
                  "--json", cwd=tmp_path).json()["frames"] == 7
    assert tfalda("replay", video, "--detector", "hough", "--loops", "1", "--max-frames", "99",
                  "--json", cwd=tmp_path).json()["stopped"] == "loops"
    tfalda("replay", video, "--detector", "hough", "--max-frames", "0", cwd=tmp_path, code=2)
    help_text = " ".join(tfalda("replay", "--help", cwd=tmp_path).out.split())
    assert "--out grows ≈ 2–3.5 kB a frame, about 1 GB an hour" in help_text
    assert "--max-frames N stop after N frames" in help_text


def test_forever_with_out_and_no_bound_says_how_the_video_grows(
        video: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys) -> None:
    _interrupt_on_call(monkeypatch, 4)
    assert main(["replay", str(video), "--detector", "hough", "--forever", "--out",
                 str(tmp_path / "o.mp4"), "--json"]) == 0
    captured = capsys.readouterr()
    assert json.loads(captured.out)["frames"] == 3
    assert "grows ≈ 2–3.5 kB a frame" in captured.err and "--max-frames N" in captured.err
