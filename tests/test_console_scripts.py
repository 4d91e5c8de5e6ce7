"""Every subcommand through the installed ``tfalda-sim`` console script, as a user runs it.

The in-process tests call ``tfalda_sim.cli.main``; these run the script installed next to
the interpreter running the tests, in a subprocess, with tiny budgets. They catch what
only an installation shows: an entry point that does not resolve, a dependency one
command imports that the package does not declare (``train`` once crashed with
"ImportError: You must install tqdm and rich" from SB3's progress bar). Each command
must exit 0, print no traceback and no "internal error", print JSON with its key figures
and write the files it says it wrote. ``test_every_subcommand_is_covered`` fails when a
subcommand is added without a test here.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import cv2
import numpy as np
import pytest

from tests.cli_helpers import (
    SCRIPT,
    TIMEOUT_S,
    Run,
    child_env,
    command_tree,
    default_sigint,
    leaf_commands,
    tfalda,
)
from tfalda_sim.tracks import NAMED_TRACKS, load_track

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"

COVERED: dict[tuple[str, ...], str] = {}
"""The subcommands with a console test here, by path → the test's name."""

F = TypeVar("F", bound=Callable[..., Any])


def covers(*command: str) -> Callable[[F], F]:
    """Register a test as the console test of ``command`` (``"track", "list"``)."""
    def register(fn: F) -> F:
        COVERED[command] = fn.__name__
        return fn
    return register


def assert_png(path: Path, shape: tuple[int, ...] | None = None) -> None:
    assert path.is_file(), f"{path} was not written"
    assert path.read_bytes()[:8] == PNG_MAGIC, f"{path} is not a PNG"
    if shape is not None:
        image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        assert image is not None and image.shape == shape, (path, getattr(image, "shape", None))


def video_frames(path: Path) -> int:
    """Frames an MP4 holds, counted by decoding it."""
    cap = cv2.VideoCapture(str(path))
    try:
        assert cap.isOpened(), f"{path} does not open as a video"
        n = 0
        while cap.grab():
            n += 1
        return n
    finally:
        cap.release()


# --------------------------------------------------------------------------- coverage
def test_every_subcommand_is_covered() -> None:
    """A subcommand added to the parser needs a console test here (``@covers``)."""
    assert set(COVERED) == set(leaf_commands()), (
        f"without a console test: {sorted(set(leaf_commands()) - set(COVERED))}; "
        f"tests of commands the parser lacks: {sorted(set(COVERED) - set(leaf_commands()))}")


def test_console_script_is_the_packages_entry_point() -> None:
    assert SCRIPT is not None, f"no tfalda-sim next to {sys.executable}"
    assert os.access(SCRIPT, os.X_OK)
    assert Path(SCRIPT).parent == Path(sys.executable).parent


@pytest.mark.parametrize("command", list(command_tree()),
                         ids=lambda c: " ".join(c) or "tfalda-sim")
def test_help(command: tuple[str, ...], tmp_path: Path) -> None:
    run = tfalda(*command, "--help", cwd=tmp_path)
    usage = " ".join(("usage: tfalda-sim", *command))
    assert run.out.startswith(usage), str(run)
    assert run.err == "", str(run)


# --------------------------------------------------------------------------- track
@covers("track", "list")
def test_track_list(tmp_path: Path) -> None:
    doc = tfalda("track", "list", "--json", cwd=tmp_path).json()
    assert [row["name"] for row in doc["tracks"]] == list(NAMED_TRACKS)
    for row in doc["tracks"]:
        assert row["length_m"] > 0 and isinstance(row["closed"], bool), row


@pytest.fixture(scope="module")
def generated_track(tmp_path_factory: pytest.TempPathFactory) -> tuple[Run, Path]:
    """``track generate --seed 1`` with both files, run once for the track tests."""
    cwd = tmp_path_factory.mktemp("track")
    return tfalda("track", "generate", "--seed", "1", "--json", "--out", "T.json",
                  "--png", "T.png", cwd=cwd), cwd


@covers("track", "generate")
def test_track_generate(generated_track: tuple[Run, Path]) -> None:
    run, cwd = generated_track
    doc = run.json()
    assert doc["seed"] == 1 and doc["valid"] is True and doc["violations"] == []
    assert doc["closed"] is True and doc["length_m"] > 5 and doc["segments"] > 0
    assert (doc["out"], doc["png"]) == ("T.json", "T.png")
    track = load_track(cwd / doc["out"])
    assert track.seed == 1 and track.length_m == pytest.approx(doc["length_m"])
    assert_png(cwd / doc["png"])


@covers("track", "validate")
def test_track_validate(generated_track: tuple[Run, Path]) -> None:
    _, cwd = generated_track
    run = tfalda("track", "validate", "T.json", cwd=cwd)
    assert "seed-1 (seed 1)" in run.out and "valid        yes" in run.out, str(run)


# --------------------------------------------------------------------------- render
# --------------------------------------------------------------------------- camera
REFERENCE_FRAMES = Path(__file__).parent / "data" / "reference"


@covers("camera", "fit")
def test_camera_fit(tmp_path: Path) -> None:
    frame = REFERENCE_FRAMES / "straight-road.png"
    doc = tfalda("camera", "fit", frame, "--fit-focal", "--out", "car.yaml", "--json",
                 cwd=tmp_path).json()
    assert doc["residual_px"] < 1.0 and doc["roll_fitted"], doc
    assert_png(tmp_path / "car-fit.png", (480, 752, 3))
    shown = tfalda("camera", "show", "car.yaml", "--json", cwd=tmp_path).json()
    reference = tfalda("camera", "show", "reference-car", "--json", cwd=tmp_path).json()
    # the fit's numbers, to the last bits another numpy/OpenCV release may change
    assert shown["mount"] == pytest.approx(reference["mount"], rel=1e-9, abs=1e-12)
    assert np.allclose(shown["camera_matrix"], reference["camera_matrix"], rtol=1e-9)
    # exists → --force; contradictory flags, bad input: one line, exit 2, nothing written
    again = tfalda("camera", "fit", frame, "--fit-focal", "--out", "car.yaml", cwd=tmp_path,
                   code=2)
    assert "--force" in again.err
    both = tfalda("camera", "fit", frame, "--fit-focal", "--intrinsics", "car.yaml", "--out",
                  "b.yaml", cwd=tmp_path, code=2)
    assert "not allowed with" in both.err
    cv2.imwrite(str(tmp_path / "flat.png"), np.full((480, 752), 40, np.uint8))
    flat = tfalda("camera", "fit", "flat.png", "--intrinsics", "car.yaml", "--out", "c.yaml",
                  cwd=tmp_path, code=2)
    assert "no markings found" in flat.err and not (tmp_path / "c.yaml").exists()
    assert not (tmp_path / "c-fit.png").exists()
    refit = tfalda("camera", "fit", frame, "--intrinsics", "car.yaml", "--out", "d.yaml",
                   "--json", cwd=tmp_path).json()
    assert abs(refit["height_m"] - doc["height_m"]) < 0.002
    # A profile's name as --intrinsics, as the help says (it was "no such file").
    named = tfalda("camera", "fit", frame, "--intrinsics", "reference-car", "--out", "e.yaml",
                   "--json", cwd=tmp_path).json()
    assert abs(named["height_m"] - doc["height_m"]) < 0.002


@covers("camera", "show")
def test_camera_show(tmp_path: Path) -> None:
    text = tfalda("camera", "show", "thesis", cwd=tmp_path).out
    assert "format: tfalda-sim-camera/1" in text and "parabola" in text
    doc = tfalda("camera", "show", "reference-car", "--json", cwd=tmp_path).json()
    assert doc["lens"] == "fisheye" and "polygon_px" in doc["bonnet"]
    bad = tfalda("camera", "show", "sony", cwd=tmp_path, code=2)
    assert "unknown camera 'sony'" in bad.err


@covers("camera", "list")
def test_camera_list(tmp_path: Path) -> None:
    assert tfalda("camera", "list", "--json", cwd=tmp_path).json() == {
        "cameras": ["thesis", "reference-car"]}


def test_camera_option_of_the_commands(tmp_path: Path) -> None:
    """``--camera`` through the console script: render, drive, evaluate, compare, replay
    and stress on the reference car; a camera file is an input no output may replace."""
    r = tfalda("render", "--track", "straight", "--s", "2", "--camera", "reference-car",
               "--out", "f.png", "--json", cwd=tmp_path).json()
    assert r["camera"] == "reference-car"
    assert_png(tmp_path / "f.png", (480, 752))
    d = tfalda("drive", "--track", "oval", "--laps", "1", "--camera", "reference-car",
               "--camera-video", "cam.mp4", "--json", cwd=tmp_path).json()
    assert d["laps_completed"] == 1 and d["camera"] == "reference-car"
    e = tfalda("evaluate", "--scenario", "random", "--seeds", "3:4", "--max-frames", "20",
               "--camera", "reference-car", "--json", cwd=tmp_path).json()
    assert e["camera"] == "reference-car" and e["frames_done"] == 20
    c = tfalda("compare", "--no-thesis", "--seeds", "3:4", "--max-frames", "10", "--workers",
               "1", "--camera", "reference-car", "--json", cwd=tmp_path).json()
    assert c["groups"]["generated"]
    rp = tfalda("replay", "cam.mp4", "--detector", "tfalda", "--camera", "reference-car",
                "--json", cwd=tmp_path).json()
    assert rp["frames"] > 100 and rp["camera"] == "reference-car"
    s = tfalda("stress", "--seeds", "10003:10004", "--faults", "blackout", "--workers", "1",
               "--camera", "reference-car", "--out", "st", "--json", cwd=tmp_path).json()
    assert s["runs"] == 2
    shutil.copy(Path(__file__).parents[1] / "tfalda_sim" / "camera" / "profiles"
                / "reference-car.yaml", tmp_path / "car.yaml")
    clash = tfalda("render", "--track", "oval", "--s", "1", "--camera", "car.yaml", "--out",
                   "car.yaml", "--force", cwd=tmp_path, code=2)
    assert "must end in .png" in clash.err or "input" in clash.err
    blind = tfalda("drive", "--track", "oval", "--camera", "missing.yaml", cwd=tmp_path,
                   code=2)
    assert "--camera" in blind.err and "no such file" in blind.err


def test_evaluate_labelled_real_frames(tmp_path: Path) -> None:
    """``evaluate --frames DIR --labels DIR --camera``: the black-box metric on the
    hand-labelled reference frames (docs/cameras.md)."""
    doc = tfalda("evaluate", "--frames", REFERENCE_FRAMES, "--labels", REFERENCE_FRAMES,
                 "--camera", "reference-car", "--repeat", "20", "--stills", "--detector",
                 "both", "--json", cwd=tmp_path).json()
    lis = doc["detectors"]["with LIS"]
    assert lis["frames"] == 2
    assert all(r["lanes_on_markings"] >= 3 for r in lis["per_frame"])
    assert doc["detectors"]["Hough (real frames)"]["ego_found_share"] == 1.0
    both = tfalda("evaluate", "--frames", REFERENCE_FRAMES, "--labels", REFERENCE_FRAMES,
                  "--scenario", "straight", cwd=tmp_path, code=2)
    assert "give one" in both.err
    nolabels = tfalda("evaluate", "--frames", REFERENCE_FRAMES, "--labels", tmp_path,
                      cwd=tmp_path, code=2)
    assert "has no labels" in nolabels.err
    (tmp_path / "f").mkdir()
    cv2.imwrite(str(tmp_path / "f" / "small.png"), np.zeros((100, 100), np.uint8))
    (tmp_path / "f" / "small.labels.json").write_text("{}")
    wrong = tfalda("evaluate", "--frames", "f", "--labels", "f", cwd=tmp_path, code=2)
    assert "100×100 px, the camera's frames are 752×480" in wrong.err


@covers("render")
def test_render(tmp_path: Path) -> None:
    doc = tfalda("render", "--track", "oval", "--s", "1", "--out", "F.png", "--truth", "G.png",
                 "--json", cwd=tmp_path).json()
    assert doc["track"] == "oval" and doc["s_m"] == 1.0 and doc["render_ms"] > 0
    assert len(doc["pose"]) == 3
    assert (doc["out"], doc["truth"]) == ("F.png", "G.png")
    assert_png(tmp_path / doc["out"], (480, 752))
    assert_png(tmp_path / doc["truth"], (480, 752, 3))


# --------------------------------------------------------------------------- evaluation
@covers("evaluate")
def test_evaluate(tmp_path: Path) -> None:
    doc = tfalda("evaluate", "--scenario", "random", "--seeds", "3:4", "--max-frames", "5",
                 "--json", "--jsonl", "X.jsonl", cwd=tmp_path).json()
    assert doc["scenario"] == "random" and doc["seeds"] == [3, 4]
    assert doc["interrupted"] is False and doc["frames_done"] == 5
    assert set(doc["pooled"]) == set(doc["runs"]) == {"with LIS", "without LIS"}
    for run in doc["per_seed"]:
        assert run["frames"] == 5 and 0.0 <= run["mean_confidence"] <= 1.0, run
    lines = (tmp_path / doc["jsonl"]).read_text().splitlines()
    assert len(lines) == doc["jsonl_lines"] == 2 * 5
    assert all(isinstance(json.loads(line), dict) for line in lines)


@covers("compare")
def test_compare(tmp_path: Path) -> None:
    doc = tfalda("compare", "--no-thesis", "--seeds", "3:4", "--max-frames", "5",
                 "--workers", "1", "--out", "DIR", "--json", cwd=tmp_path).json()
    assert doc["thesis_scenarios"] == [] and doc["seeds"] == [3, 4]
    assert doc["scenarios_done"] == doc["scenarios"] == 1 and doc["interrupted"] is False
    assert "generated" in doc["groups"] and doc["groups"]["generated"], doc["groups"]
    assert sorted(Path(p).name for p in doc["out"].values()) == sorted(
        ["compare.jsonl", "compare.json", "compare.md", "compare.png"])
    for path in doc["out"].values():
        assert (tmp_path / path).is_file() and (tmp_path / path).stat().st_size > 0, path
    assert json.loads((tmp_path / "DIR" / "compare.json").read_text())["scenarios_done"] == 1
    assert len((tmp_path / "DIR" / "compare.jsonl").read_text().splitlines()) == 1
    assert_png(tmp_path / "DIR" / "compare.png")


# --------------------------------------------------------------------------- agents
@pytest.fixture(scope="module")
def drive_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Run, Path]:
    """One PID lap of the oval with its video, run once (``replay`` reads the video)."""
    cwd = tmp_path_factory.mktemp("drive")
    return tfalda("drive", "--track", "oval", "--laps", "1", "--json", "--video", "V.mp4",
                  cwd=cwd), cwd


@covers("drive")
def test_drive(drive_run: tuple[Run, Path]) -> None:
    run, cwd = drive_run
    doc = run.json()
    assert doc["track"] == "oval" and doc["agent"] == "pid"
    assert doc["laps_completed"] == 1 and len(doc["lap_times_s"]) == 1
    assert 5.0 < doc["lap_times_s"][0] < 60.0 and doc["steps"] > 0
    assert doc["mean_abs_cross_track_m"] < 0.2
    assert doc["video"] == "V.mp4"
    assert video_frames(cwd / doc["video"]) == doc["steps"]


@covers("replay")
def test_replay(drive_run: tuple[Run, Path]) -> None:
    drive, cwd = drive_run
    assert (cwd / "V.mp4").is_file(), f"the drive wrote no video\n{drive}"
    doc = tfalda("replay", "V.mp4", "--detector", "hough", "--json", cwd=cwd).json()
    assert doc["detector"] == "hough" and doc["stopped"] == "loops"
    assert doc["loops_completed"] == 1 and doc["frames"] == drive.json()["steps"]
    assert doc["frames_per_s"] > 0 and doc["detections_per_frame"] > 0
    assert doc["out"] is None


@covers("stress")
def test_stress(tmp_path: Path) -> None:
    from tfalda_sim.agents.stress import REPORT_FILES

    doc = tfalda("stress", "--seeds", "10003:10004", "--faults", "none", "--workers", "1",
                 "--out", "DIR", "--json", cwd=tmp_path).json()
    assert doc["jobs"] == doc["runs"] == 2 and doc["interrupted"] is False
    assert {(row["fault"], row["roi_reset_stage"]) for row in doc["summary"]} == {
        ("none", True), ("none", False)}
    assert doc["out"] == "DIR"
    for name in REPORT_FILES.values():
        assert (tmp_path / "DIR" / name).is_file(), name
    assert len((tmp_path / "DIR" / REPORT_FILES["jsonl"]).read_text().splitlines()) == 2
    assert_png(tmp_path / "DIR" / REPORT_FILES["png"])


@covers("evaluate-agent")
def test_evaluate_agent(tmp_path: Path) -> None:
    doc = tfalda("evaluate-agent", "--seeds", "10003:10004", "--laps", "1", "--workers", "1",
                 "--json", cwd=tmp_path).json()
    assert doc["agent"] == "pid" and doc["seeds"] == [10003, 10004] and doc["laps"] == 1
    assert doc["interrupted"] is False and len(doc["runs"]) == 1
    (speed,) = doc["speeds"]
    assert speed["speed_m_s"] == 1.5 and speed["tracks"] == 1
    assert 0.0 <= speed["success_rate"] <= 1.0


@covers("limits")
def test_limits(tmp_path: Path) -> None:
    doc = tfalda("limits", "--seeds", "10003:10004", "--laps", "1", "--workers", "1",
                 "--vehicle", "dynamic", "--plot", "H.png", "--out", "L.json", "--json",
                 cwd=tmp_path).json()
    assert doc["agent"] == "pid" and doc["seeds"] == [10003, 10004] and doc["laps"] == 1
    assert doc["vehicle"] == "dynamic" and doc["timing"] == "ideal"
    assert doc["interrupted"] is False
    (track,) = doc["per_seed"]
    assert track["seed"] == 10003 and track["drives"]
    assert track["limit_m_s"] is None or 0.5 <= track["limit_m_s"] <= 8.3
    assert doc["summary"]["count"] == 1 and doc["summary"]["median_m_s"] == track["limit_m_s"]
    assert json.loads((tmp_path / "L.json").read_text()) == doc
    assert_png(tmp_path / "H.png")


def _train(tmp_path: Path, *extra: str) -> Run:
    pytest.importorskip("stable_baselines3", reason="train needs the rl extra")
    return tfalda("train", "--timesteps", "64", "--n-envs", "1", "--out", "out/tr", *extra,
                  cwd=tmp_path)


def _assert_trained(folder: Path) -> dict[str, Any]:
    assert zipfile.is_zipfile(folder / "policy.zip"), f"no policy in {folder}"
    summary = json.loads((folder / "train.json").read_text())
    assert summary["interrupted"] is False and summary["timesteps_done"] >= 64, summary
    return summary


@covers("train")
def test_train_json(tmp_path: Path) -> None:
    doc = _train(tmp_path, "--json").json()
    assert doc["timesteps"] == 64 and doc["n_envs"] == 1
    assert doc["interrupted"] is False and doc["timesteps_done"] >= 64
    assert _assert_trained(tmp_path / "out" / "tr")["timesteps_done"] == doc["timesteps_done"]


def test_train_with_two_envs_spawns_a_worker_from_the_script(tmp_path: Path) -> None:
    """Two envs: this process steps one, a spawned worker the other (the worker imports
    the console script's main module)."""
    pytest.importorskip("stable_baselines3", reason="train needs the rl extra")
    doc = tfalda("train", "--timesteps", "64", "--n-envs", "2", "--out", "out/tr", "--json",
                 cwd=tmp_path).json()
    assert doc["n_envs"] == 2 and doc["timesteps_done"] >= 64 and doc["steps_per_s"] > 0
    _assert_trained(tmp_path / "out" / "tr")


def test_train_with_a_camera(tmp_path: Path) -> None:
    doc = _train(tmp_path, "--camera", "reference-car", "--json").json()
    assert doc["camera"] == "reference-car" and "--camera reference-car" in doc["command"]
    _assert_trained(tmp_path / "out" / "tr")


def test_train_with_progress_bar(tmp_path: Path) -> None:
    """Without --json the progress bar runs: the path that needed SB3's tqdm+rich extra."""
    run = _train(tmp_path)
    assert "trained" in run.out and "steps/s" in run.out and "policy.zip" in run.out, str(run)
    assert "100%" in run.err, str(run)  # the bar reached its end
    _assert_trained(tmp_path / "out" / "tr")


# --------------------------------------------------------------------------- sweeps on Ray
def test_a_killed_sweep_leaves_its_journal_and_resumes_from_it(tmp_path: Path) -> None:
    """SIGKILL (no chance to clean up) once some tracks are in the journal: r.jsonl.partial
    stays with them; a fresh run over it is refused; --resume continues it (after a line
    cut mid-write) to the results and report of an uninterrupted run."""
    if SCRIPT is None:
        pytest.fail("no tfalda-sim console script")
    sweep = ("evaluate", "--scenario", "random", "--seeds", "0:8", "--max-frames", "25",
             "--json", "--workers", "2")
    proc = subprocess.Popen([SCRIPT, *sweep, "--results", "r.jsonl"], cwd=tmp_path,
                            env=child_env(), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    journal = tmp_path / "r.jsonl.partial"
    deadline = time.monotonic() + TIMEOUT_S
    while time.monotonic() < deadline and proc.poll() is None:
        if journal.exists() and len(journal.read_text().splitlines()) >= 3:  # header + 2
            break
        time.sleep(0.05)
    proc.kill()
    proc.wait(timeout=TIMEOUT_S)
    kept = journal.read_text().splitlines()
    assert 3 <= len(kept) < 9 and not (tmp_path / "r.jsonl").exists(), kept
    refused = tfalda(*sweep, "--results", "r.jsonl", cwd=tmp_path, code=2)
    assert "--resume continues it" in refused.err, str(refused)
    with journal.open("a") as fh:
        fh.write('{"seed": 7, "ru')  # a write the kill cut off
    resumed = tfalda(*sweep, "--results", "r.jsonl", "--resume", cwd=tmp_path)
    assert "continuing from" in resumed.err and "dropped the incomplete last" in resumed.err
    assert not journal.exists()
    assert (tmp_path / "r.jsonl").read_text().splitlines()[:len(kept)] == kept
    whole = tfalda(*sweep, "--results", "whole.jsonl", cwd=tmp_path).json()
    assert _without_timings(resumed.json()) == _without_timings(whole)
    assert ([_without_timings(json.loads(x)) for x in (tmp_path / "r.jsonl").read_text()
             .splitlines()] == [_without_timings(json.loads(x)) for x in
                                (tmp_path / "whole.jsonl").read_text().splitlines()])


def _without_timings(obj: Any) -> Any:
    """``obj`` without wall-clock figures (they differ between any two runs)."""
    if isinstance(obj, dict):
        return {k: _without_timings(v) for k, v in obj.items()
                if k not in ("detector_ms_median", "results")}
    if isinstance(obj, list):
        return [_without_timings(v) for v in obj]
    return obj


def test_a_sweep_on_ray_stopped_by_ctrl_c_resumes_to_the_uninterrupted_result(
        tmp_path: Path) -> None:
    """`evaluate` on a local Ray, SIGINT once some tracks are in --results: exit 130, the
    finished tracks kept; --resume (on the local pool) finishes the rest without redoing
    them, and results and report equal an uninterrupted run's."""
    if SCRIPT is None:
        pytest.fail("no tfalda-sim console script")
    sweep = ("evaluate", "--scenario", "random", "--seeds", "0:8", "--max-frames", "25",
             "--json")
    proc = subprocess.Popen([SCRIPT, *sweep, "--backend", "ray", "--workers", "2",
                             "--results", "r.jsonl"], cwd=tmp_path, env=child_env(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=default_sigint)
    deadline = time.monotonic() + TIMEOUT_S
    while time.monotonic() < deadline and proc.poll() is None:
        journal = tmp_path / "r.jsonl.partial"
        if journal.exists() and len(journal.read_text().splitlines()) >= 3:  # header + 2
            break
        time.sleep(0.1)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=TIMEOUT_S)
    assert proc.returncode == 130 and "Traceback" not in err, err
    last = err.strip().splitlines()[-1]
    assert last.startswith("interrupted (Ctrl-C): kept the") and "--resume" in last, last
    kept = (tmp_path / "r.jsonl").read_text().splitlines()
    assert 3 <= len(kept) < 9, "the sweep was not interrupted midway"
    resumed = tfalda(*sweep, "--workers", "2", "--results", "r.jsonl", "--resume",
                     cwd=tmp_path).json()
    assert (tmp_path / "r.jsonl").read_text().splitlines()[:len(kept)] == kept
    whole = tfalda(*sweep, "--workers", "2", "--results", "whole.jsonl", cwd=tmp_path).json()
    assert _without_timings(resumed) == _without_timings(whole)
    assert ([_without_timings(json.loads(x)) for x in (tmp_path / "r.jsonl").read_text()
             .splitlines()] == [_without_timings(json.loads(x)) for x in
                                (tmp_path / "whole.jsonl").read_text().splitlines()])
