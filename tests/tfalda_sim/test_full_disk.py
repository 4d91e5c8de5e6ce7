"""A full disk: every command that writes a video, a PNG or a JSON file fails with one line
naming the file (not its temporary name), the reason and the fix, exits non-zero, keeps an
existing file and leaves no temporary file behind.

Each case runs twice, through the installed console script: on a small tmpfs filled up
(ENOSPC, as a real full disk; skipped where tmpfs cannot be mounted), and under a file size
limit (``RLIMIT_FSIZE`` with SIGXFSZ ignored, so a write fails with EFBIG instead of
killing the process; works anywhere). Under the size limit the numba kernels' cache files
(up to ≈ 0.5 MB) must still be writable on a cold cache: the video cases allow 1 MB; the
small PNG/JSON cases first run the command once without the limit (warming the cache)."""

from __future__ import annotations

import errno
import os
import resource
import signal
import subprocess
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from tests.cli_helpers import SCRIPT, TIMEOUT_S, Run, child_env, tfalda
from tests.small_disk import tmpfs
from tfalda_sim.video import VideoWriter

VIDEO_LIMIT = 1 << 20
"""Room for a video case [bytes]: above any numba cache file, below every video written."""

PRECIOUS = b"an existing file the failed command must not touch"


@dataclass
class SmallDisk:
    """``folder`` on a disk that takes only a few bytes more: a filled tmpfs, or any folder
    with the commands run under a file size limit (``kind``)."""

    kind: str
    folder: Path
    cwd: Path

    def run(self, *argv: str | Path, room: int, code: int = 2, warm: bool = False) -> Run:
        """Run the console script where ``room`` bytes more fit (tmpfs: free space; the
        limit: file size), asserting no traceback, no internal error and ``code``.
        ``warm``: under the limit, run it once without first (into a scratch folder) so
        that the numba kernels' cache is written then, not under the limit."""
        if self.kind == "tmpfs":
            _fill(self.folder, room)
            return tfalda(*argv, cwd=self.cwd, code=code)
        args = [str(a) for a in argv]
        if warm:
            scratch = self.cwd / "warm"
            scratch.mkdir(exist_ok=True)
            tfalda(*[a.replace(self.folder.name + "/", "warm/") for a in args], "--force",
                   cwd=self.cwd)

        def limit() -> None:
            signal.signal(signal.SIGINT, signal.SIG_DFL)
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # EFBIG, not a kill
            resource.setrlimit(resource.RLIMIT_FSIZE, (room, room))

        assert SCRIPT is not None
        proc = subprocess.run([SCRIPT, *args], cwd=self.cwd, env=child_env(),
                              capture_output=True, text=True, timeout=TIMEOUT_S,
                              check=False, preexec_fn=limit)
        run = Run(tuple(args), proc.returncode, proc.stdout, proc.stderr)
        assert "Traceback" not in run.err and "internal error" not in run.err, str(run)
        assert run.code == code, str(run)
        return run


def _fill(folder: Path, room: int) -> None:
    """Leave about ``room`` bytes free on ``folder``'s file system."""
    st = os.statvfs(folder)
    free = st.f_bavail * st.f_frsize
    with open(folder / "filler", "ab") as fh:
        fh.write(b"\0" * max(0, free - room))


@pytest.fixture(params=["tmpfs", "limit"])
def small(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[SmallDisk]:
    folder = tmp_path / "small"
    folder.mkdir()
    if request.param == "limit":
        yield SmallDisk("limit", folder, tmp_path)
        return
    with tmpfs(folder, "4m"):
        yield SmallDisk("tmpfs", folder, tmp_path)


def _assert_refused(disk: SmallDisk, run: Run, target: str) -> None:
    """One line naming ``target`` and the reason; the old file kept; no temporary file."""
    last = run.err.strip().splitlines()[-1]
    reason = os.strerror(errno.ENOSPC if disk.kind == "tmpfs" else errno.EFBIG)
    assert last.startswith(f"error: cannot write {target}: {reason}; "), str(run)
    assert ".tfalda-sim-" not in run.err and ".tmp" not in run.err, str(run)
    assert "Failed to write frame" not in run.err, str(run)
    assert (disk.cwd / target).read_bytes() == PRECIOUS
    assert [p.name for p in disk.folder.iterdir() if p.name != "filler"] == [Path(target).name]


def _existing(disk: SmallDisk, name: str) -> str:
    (disk.folder / name).write_bytes(PRECIOUS)
    return f"{disk.folder.name}/{name}"


def test_drive_video_on_a_full_disk(small: SmallDisk) -> None:
    target = _existing(small, "d.mp4")
    run = small.run("drive", "--track", "oval", "--laps", "1", "--video", target, "--force",
                    room=VIDEO_LIMIT)
    _assert_refused(small, run, target)
    assert "wrote" not in run.out


def test_drive_camera_video_on_a_full_disk(small: SmallDisk) -> None:
    target = _existing(small, "c.mp4")
    # Two laps of grey frames: ≈ 2 MB.
    run = small.run("drive", "--track", "oval", "--laps", "2", "--camera-video", target,
                    "--force", room=VIDEO_LIMIT)
    _assert_refused(small, run, target)


def noise_video(path: Path, frames: int = 60) -> Path:
    """A recording whose annotated replay is large (blocks of noise: every frame new)."""
    rng = np.random.default_rng(0)
    with VideoWriter(path, 25.0) as w:
        for _ in range(frames):
            blocks = rng.integers(0, 256, (60, 94), dtype=np.uint8)
            w.write(np.kron(blocks, np.ones((8, 8), np.uint8)))
    return path


def test_replay_out_on_a_full_disk(small: SmallDisk) -> None:
    source = noise_video(small.cwd / "noise.mp4")
    target = _existing(small, "rp.mp4")
    run = small.run("replay", source, "--detector", "hough", "--out", target, "--force",
                    room=VIDEO_LIMIT)
    _assert_refused(small, run, target)


@pytest.mark.parametrize("option", ["--mcap", "--per-frame"])
def test_replay_recording_and_per_frame_lines_on_a_full_disk(small: SmallDisk,
                                                             option: str) -> None:
    source = noise_video(small.cwd / "noise.mp4")
    target = _existing(small, "rp.mcap" if option == "--mcap" else "rp.jsonl")
    run = small.run("replay", source, "--detector", "hough", "--loops", "20", option, target,
                    "--force", room=VIDEO_LIMIT if option == "--mcap" else 4096,
                    warm=option == "--per-frame")
    _assert_refused(small, run, target)


def test_drive_mcap_on_a_full_disk(small: SmallDisk) -> None:
    target = _existing(small, "d.mcap")
    run = small.run("drive", "--track", "oval", "--laps", "1", "--mcap", target, "--force",
                    room=VIDEO_LIMIT)
    _assert_refused(small, run, target)
    assert "wrote" not in run.out


def test_evaluate_video_on_a_full_disk(small: SmallDisk) -> None:
    """evaluate writes the video to its staged name first: the error still names --video."""
    target = _existing(small, "e.mp4")
    # seed 0's lap: 299 frames, ≈ 1 MB of video.
    run = small.run("evaluate", "--scenario", "random", "--seeds", "0:1", "--no-lis",
                    "--video", target, "--force", room=256 << 10, warm=True)
    _assert_refused(small, run, target)


def test_render_png_on_a_full_disk(small: SmallDisk) -> None:
    target = _existing(small, "r.png")
    run = small.run("render", "--track", "oval", "--s", "1", "--out", target, "--force",
                    room=32 << 10, warm=True)
    _assert_refused(small, run, target)


@pytest.mark.parametrize("option", ["--out", "--png"])
def test_track_json_and_png_on_a_full_disk(small: SmallDisk, option: str) -> None:
    """track generate --out writes JSON through ``atomic_write`` inside the staged outputs."""
    target = _existing(small, "t.json" if option == "--out" else "t.png")
    run = small.run("track", "generate", "--seed", "3", option, target, "--force",
                    room=1024, warm=True)
    _assert_refused(small, run, target)


def test_evaluate_jsonl_on_a_full_disk(small: SmallDisk) -> None:
    target = _existing(small, "e.jsonl")
    run = small.run("evaluate", "--scenario", "random", "--seeds", "0:1", "--max-frames",
                    "40", "--no-lis", "--jsonl", target, "--force", room=2048, warm=True)
    _assert_refused(small, run, target)


def test_a_failed_write_names_the_target_not_its_temporary_file(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """In-process, without a small disk: ENOSPC from a write() (no file name in it) inside
    ``Outputs`` and ``atomic_write`` becomes a WriteError naming the target."""
    from tfalda_sim.fileio import WriteError, atomic_write
    from tfalda_sim.outputs import Outputs

    def full(*_: object) -> int:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    target = tmp_path / "a.json"
    target.write_bytes(PRECIOUS)
    with pytest.raises(WriteError, match=rf"cannot write {target}: No space left on device; "
                                         "free some space"), Outputs() as outs:
        (outs.path(tmp_path / "b.png")).write_bytes(b"png")
        with open(outs.path(target), "w") as fh:
            monkeypatch.setattr(fh, "write", full)
            fh.write("{}")
    monkeypatch.undo()
    with pytest.raises(WriteError, match=rf"cannot write {target}: No space"), \
            atomic_write(target) as fh:
        monkeypatch.setattr(fh, "write", full)
        fh.write("{}")
    assert target.read_bytes() == PRECIOUS
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json"]
    # Other errors pass through unchanged: a missing input is not a full disk.
    with pytest.raises(FileNotFoundError), Outputs() as outs:
        outs.path(target).write_text("{}")
        (tmp_path / "missing.json").read_text()

