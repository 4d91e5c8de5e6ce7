"""Property-based fuzz of the command line: hypothesis-built argument vectors for every
subcommand, run in-process through ``tfalda_sim.cli.main``.

For any argv, ``main`` must return 0, 1, 2 or 130 (``tfalda_sim.cli_common``), let no
exception escape, print no traceback and no "internal error", and never change a file
that existed before without ``--force``; exit 2 (bad input) must leave the disk as it
was, "nothing written" must be true, ``--json`` with exit 0/1 must print a JSON object.
The argvs are working ones mutated (``STARTS``) and ones built from the parser's actions
alone (a new option or command is fuzzed without editing this file), with values from a
pool of valid-looking and hostile ones: empty, NaN, ∞, 10⁴⁰⁰, huge and reversed seed
ranges, very long strings, existing files and folders, a symlink, paths under a regular
file, /proc and /sys (which even root cannot write: the tests run as root, so chmod
makes nothing read-only), ``--workers`` far above the CPUs.

Real work would take minutes, so each example runs under a time budget that simulates
Ctrl-C: SIGALRM raises KeyboardInterrupt in the main thread after ``BUDGET_S`` (a
quarter of the examples: ``EARLY_S``), and the command must then stop cleanly with 130
(or have finished in time with 0/1/2; ``replay --forever`` ends with 0), leave no
temporary file and no worker process behind. A second alarm ``HANG_S`` later fails the
example as a command that ignores Ctrl-C.

The examples run in a sandbox folder (``SANDBOX``) of pre-existing files, restored after
each example from a pristine copy; cwd is the sandbox, so default outputs
(``runs/ppo``, ``out/stress``) land there too. ``pytest -s`` prints per command how the
examples ended.
"""

from __future__ import annotations

import argparse
import atexit
import contextlib
import hashlib
import importlib
import io
import json
import multiprocessing
import os
import shutil
import signal
import stat
import tempfile
import threading
import time
import traceback
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import FrameType

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from tests.cli_helpers import leaf_commands
from tfalda_sim.cli import build_parser, main
from tfalda_sim.parallel import available_cpus
from tfalda_sim.tracks.named import named_path

BUDGET_S = 1.5
"""Wall time an example may work before its simulated Ctrl-C [s]."""
EARLY_S = 0.4
"""The budget of a quarter of the examples: a Ctrl-C during the start-up (loading a
track, building the renderer, starting the pool) rather than during the work [s]."""
HANG_S = 20.0
"""After the Ctrl-C, time the command has to stop before the example fails [s]."""
CHILD_GRACE_S = 3.0
"""Time the worker processes of an interrupted command have to exit [s]."""

EXAMPLES: dict[tuple[str, ...], int] = {
    ("track", "list"): 8, ("track", "generate"): 25, ("track", "validate"): 25,
    ("render",): 20, ("replay",): 14,
    ("evaluate",): 18, ("compare",): 8, ("drive",): 8, ("stress",): 7,
    ("evaluate-agent",): 7, ("train",): 8,
}
"""Examples per command: more for the quick ones (a new command gets DEFAULT_EXAMPLES)."""
DEFAULT_EXAMPLES = 15

FUZZ = settings(deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
                # No explain phase: it re-runs examples, each up to BUDGET_S.
                phases=[Phase.explicit, Phase.reuse, Phase.generate, Phase.shrink])

SANDBOX = Path(tempfile.mkdtemp(prefix="tfalda-cli-fuzz-"))
"""The examples' working folder, with the pre-existing files of ``_build_sandbox``."""
PRISTINE = Path(tempfile.mkdtemp(prefix="tfalda-cli-fuzz-pristine-"))
"""A copy of the sandbox as built: what it is restored from after each example."""
SCRATCH = Path(tempfile.mkdtemp(prefix="tfalda-cli-fuzz-warmup-"))
"""Where the warm-up runs write (never the sandbox)."""
for _folder in (SANDBOX, PRISTINE, SCRATCH):
    atexit.register(shutil.rmtree, _folder, True)

REAL_POLICY = Path(__file__).resolve().parents[1] / "agents" / "policies" / "ppo.zip"


# --------------------------------------------------------------------------- sandbox
def _png() -> bytes:
    ok, buf = cv2.imencode(".png", np.full((8, 8), 128, np.uint8))
    assert ok
    return buf.tobytes()


def _clip(path: Path, frames: int = 12) -> None:
    """A short synthetic camera recording: dark mat, two bright lane lines."""
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 25.0, (752, 480))
    assert writer.isOpened()
    for k in range(frames):
        frame = np.full((480, 752, 3), 35, np.uint8)
        cv2.line(frame, (200 + k, 479), (340, 240), (210, 210, 210), 6)
        cv2.line(frame, (560 - k, 479), (420, 240), (210, 210, 210), 6)
        writer.write(frame)
    writer.release()


def _build_sandbox(root: Path) -> None:
    files: dict[str, bytes] = {
        "track.json": named_path("oval").read_bytes(),
        "bad.json": b"{not json",
        "file.json": b"{}\n",
        "pic.png": _png(),
        "frames/straight-road.png": (Path(__file__).parent / "data" / "reference"
                                     / "straight-road.png").read_bytes(),
        "frames/straight-road.labels.json": (Path(__file__).parent / "data" / "reference"
                                             / "straight-road.labels.json").read_bytes(),
        "road.png": (Path(__file__).parent / "data" / "reference" / "straight-road.png"
                     ).read_bytes(),
        "car.yaml": (Path(__file__).parents[1] / "tfalda_sim" / "camera" / "profiles"
                     / "reference-car.yaml").read_bytes(),
        "points.json": b'{"centre": [[100, 400], [300, 100]], "right": [[700, 400], [400, 100]]}',
        "frames.jsonl": b'{"seq": 0}\n',
        "lanes.xml": b"<lanes/>\n",
        "policy.zip": b"not a zip",
        "report/stress.jsonl": b"{}\n", "report/stress.json": b"{}", "report/stress.md": b"|",
        "report/stress.png": _png(), "report/compare.jsonl": b"{}\n",
        "report/compare.json": b"{}", "report/compare.md": b"|", "report/compare.png": _png(),
        "report/policy.zip": REAL_POLICY.read_bytes(), "report/train.json": b"{}",
        # The default outputs of stress (out/stress) and train (runs/ppo).
        "out/stress/stress.json": b"{}", "runs/ppo/train.json": b"{}",
    }
    for name, data in files.items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_bytes(data)
    _clip(root / "clip.mp4")
    (root / "empty").mkdir()
    (root / "link.png").symlink_to("pic.png")


@dataclass(frozen=True)
class Entry:
    """One sandbox entry as ``snapshot`` sees it (``digest``: a link's target)."""

    kind: str
    digest: str = ""
    mtime_ns: int = 0
    mode: int = 0


def snapshot_entry(path: Path) -> Entry | None:
    """A file by content hash, mtime and mode, a symlink by its target, a folder by its
    existence (its mtime changes with any new entry); None if there is none."""
    try:
        st_ = path.lstat()
    except OSError:
        return None
    if stat.S_ISLNK(st_.st_mode):
        return Entry("link", os.readlink(path))
    if stat.S_ISDIR(st_.st_mode):
        return Entry("dir")
    return Entry("file", hashlib.sha256(path.read_bytes()).hexdigest(), st_.st_mtime_ns,
                 stat.S_IMODE(st_.st_mode))


def snapshot(root: Path = SANDBOX) -> dict[str, Entry]:
    """Every entry under ``root`` by relative path (``snapshot_entry``)."""
    out: dict[str, Entry] = {}
    for folder, dirs, names in os.walk(root):
        for name in dirs + names:
            path = Path(folder) / name
            entry = snapshot_entry(path)
            if entry is not None:
                out[str(path.relative_to(root))] = entry
    return out


def restore(baseline: dict[str, Entry]) -> None:
    """Put the sandbox back as built: new entries removed, changed ones copied back."""
    now = snapshot()
    for rel in sorted(set(now) - set(baseline), key=len, reverse=True):
        path = SANDBOX / rel
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path, ignore_errors=True)
        else:
            path.unlink(missing_ok=True)
    for rel, entry in sorted(baseline.items()):
        if snapshot_entry(SANDBOX / rel) == entry:
            continue
        path, src = SANDBOX / rel, PRISTINE / rel
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        elif path.exists() or path.is_symlink():
            path.unlink()
        if entry.kind == "dir":
            path.mkdir(parents=True)
        elif entry.kind == "link":
            path.symlink_to(entry.digest)
        else:
            path.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, path)
    assert snapshot() == baseline, "the sandbox could not be restored"


# --------------------------------------------------------------------------- children
def _live_children() -> dict[int, str]:
    """The running (not zombie) child processes of this process: pid → command line."""
    multiprocessing.active_children()  # reaps finished multiprocessing children
    pids: set[int] = set()
    for task in Path("/proc/self/task").iterdir():
        with contextlib.suppress(OSError):
            pids.update(int(p) for p in (task / "children").read_text().split())
    out: dict[int, str] = {}
    for pid in pids:
        try:
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(
                errors="replace").strip()
        except OSError:
            continue
        if state != "Z":
            out[pid] = cmd
    return out


HELPERS = ("multiprocessing.forkserver", "multiprocessing.resource_tracker")
"""Long-lived helpers multiprocessing starts once per process (not pool workers)."""


def _leftover_children(before: dict[int, str]) -> dict[int, str]:
    """Children started during the example that are still running after the grace
    period (multiprocessing's helper processes excepted); kills them by pid."""
    deadline = time.monotonic() + CHILD_GRACE_S
    while True:
        left = {pid: cmd for pid, cmd in _live_children().items()
                if pid not in before and not any(h in cmd for h in HELPERS)}
        if not left or time.monotonic() > deadline:
            break
        time.sleep(0.05)
    for pid in left:
        with contextlib.suppress(OSError):
            os.kill(pid, signal.SIGKILL)
    if left:
        time.sleep(0.1)
        multiprocessing.active_children()
    return left


# --------------------------------------------------------------------------- running
class Hung(BaseException):
    """Raised by the second alarm: the command did not stop after its Ctrl-C."""


@dataclass
class Outcome:
    argv: list[str]
    code: int | None = None
    out: str = ""
    err: str = ""
    escaped: str | None = None
    interrupted: bool = False
    seconds: float = 0.0
    changed: list[str] = field(default_factory=list)
    new: dict[str, str] = field(default_factory=dict)
    """Entries the run created: relative path → kind (file, dir, link)."""
    children: dict[int, str] = field(default_factory=dict)
    """Child processes still running after the grace period (killed since)."""
    peak_children: int = 0
    """Most child processes seen at once while the command ran (when sampled)."""

    def __str__(self) -> str:
        return (f"tfalda-sim {' '.join(a if len(a) < 80 else a[:40] + '…' for a in self.argv)}"
                f"\n→ exit {self.code} after {self.seconds:.2f} s"
                f"{' (Ctrl-C sent)' if self.interrupted else ''}\n"
                f"--- stdout\n{self.out[-1500:]}\n--- stderr\n{self.err[-3000:]}"
                + (f"\n--- escaped\n{self.escaped}" if self.escaped else ""))


def run_cli(argv: list[str], baseline: dict[str, Entry], budget_s: float = BUDGET_S,
            sample_children: bool = False) -> Outcome:
    """``main(argv)`` in the sandbox, Ctrl-C after ``budget_s``; what it did to the
    sandbox and its child processes (``sample_children``: also count them while it runs,
    from a thread). The sandbox is restored before returning."""
    outcome = Outcome(list(argv))
    sampling = threading.Event()

    def sample() -> None:
        while not sampling.wait(0.05):
            outcome.peak_children = max(outcome.peak_children, len(_live_children()))
    fired = [0]

    def alarm(signum: int, frame: FrameType | None) -> None:
        fired[0] += 1
        if fired[0] == 1:
            raise KeyboardInterrupt
        raise Hung

    before_children = _live_children()
    out, err = io.StringIO(), io.StringIO()
    cwd = os.getcwd()
    previous = signal.signal(signal.SIGALRM, alarm)
    sampler = threading.Thread(target=sample, daemon=True)
    if sample_children:
        sampler.start()
    t0 = time.perf_counter()
    try:
        os.chdir(SANDBOX)
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            signal.setitimer(signal.ITIMER_REAL, budget_s, HANG_S)
            try:
                outcome.code = main(argv)
            finally:
                signal.setitimer(signal.ITIMER_REAL, 0)
    except Hung:
        outcome.escaped = f"did not stop within {HANG_S:g} s of its Ctrl-C"
    except BaseException as exc:  # anything escaping main is a finding
        outcome.escaped = "".join(traceback.format_exception(exc))
    finally:
        signal.signal(signal.SIGALRM, previous)
        os.chdir(cwd)
        sampling.set()
        if sample_children:
            sampler.join()
    outcome.seconds = time.perf_counter() - t0
    outcome.interrupted = fired[0] > 0
    outcome.out, outcome.err = out.getvalue(), err.getvalue()
    outcome.children = _leftover_children(before_children)
    after = snapshot()
    outcome.changed = sorted(k for k, v in baseline.items() if after.get(k) != v)
    outcome.new = {k: after[k].kind for k in sorted(set(after) - set(baseline))}
    restore(baseline)
    return outcome


def _is_temporary(rel: str) -> bool:
    name = Path(rel).name
    return ".tmp" in name or name.startswith(".tfalda-sim-probe")


def _swallow_expected(argv: list[str]) -> bool:
    """Whether exit 0/1 after a Ctrl-C is what ``argv`` should do: ``replay --forever``
    ends that way by design."""
    return argv[0] == "replay" and any(a == "--forever" or a.startswith("--fo") for a in argv)


def check(outcome: Outcome, baseline: dict[str, Entry]) -> None:
    """The properties every run of the command line must have."""
    argv = outcome.argv
    assert outcome.escaped is None, f"an exception escaped main\n{outcome}"
    assert outcome.code in (0, 1, 2, 130), f"undocumented exit code\n{outcome}"
    assert "Traceback" not in outcome.err, str(outcome)
    assert "internal error" not in outcome.err, str(outcome)
    assert outcome.code != 130 or outcome.interrupted, f"130 without a Ctrl-C\n{outcome}"
    if outcome.interrupted and outcome.code in (0, 1) and not _swallow_expected(argv):
        pytest.fail(f"the Ctrl-C was swallowed: exit {outcome.code}, not 130\n{outcome}")
    assert not outcome.children, (
        f"worker processes left running after the command returned: {outcome.children}\n"
        f"{outcome}")
    if "--force" not in argv:
        assert not outcome.changed, (
            f"pre-existing {outcome.changed} changed without --force\n{outcome}")
    leftovers = [p for p in outcome.new if _is_temporary(p)]
    assert not leftovers, f"temporary files left behind: {leftovers}\n{outcome}"
    new_files = [p for p, kind in outcome.new.items() if kind != "dir"]
    if outcome.code == 2:  # bad input: refused before any work, the disk as it was
        assert not outcome.new, (
            f"bad input (exit 2) but {list(outcome.new)} were created\n{outcome}")
    if "nothing written" in outcome.err:
        assert not new_files, f"says 'nothing written' but wrote {new_files}\n{outcome}"
    options = argv[:argv.index("--")] if "--" in argv else argv
    if "--json" in options and outcome.code in (0, 1) and not (
            {"-h", "--help"} & set(options)):
        try:
            doc = json.loads(outcome.out.strip().splitlines()[-1] if outcome.out else "")
        except (json.JSONDecodeError, IndexError):
            pytest.fail(f"--json but stdout is not one JSON object\n{outcome}")
        assert isinstance(doc, dict), str(outcome)


# --------------------------------------------------------------------------- strategies
LONG = "x" * 5000
DIGITS_400 = "1" + "0" * 400
NUMBERS = ["", "nan", "inf", "-inf", "-1", "0", "1e9", DIGITS_400, "1e-9", "-0", "0x10",
           "1_000", " 3", "+1", "\u0663", "1e308", "4.2", "2**63", "9223372036854775808"]
r"""Hostile numbers (\u0663 is an Arabic-Indic 3: ``int()`` and ``str.isdigit`` take it)."""
RANGES = ["0:100000000", "5:2", "a:b", "3:3", "3:", ":", "-1:3", "1:2:3", "0:1",
          "9223372036854775806:9223372036854775807", f"0:{DIGITS_400}"]
STRINGS = [LONG, " ", "-", "é", "\udcff.png", "none,", ",", "oval ", "OVAL"]
PATHS_EXISTING = [
    "track.json", "bad.json", "file.json", "pic.png", "clip.mp4", "frames.jsonl",
    "lanes.xml", "policy.zip", "report", "report/stress.json", "report/compare.png",
    "report/policy.zip", "out/stress", "runs/ppo", "runs/ppo/train.json", "empty",
    "link.png", ".", "", "./pic.png", "empty/../pic.png", str(SANDBOX / "pic.png"),
    str(SANDBOX / "report"), str(SANDBOX / "clip.mp4"), "PIC.PNG"]
PATHS_NEW = [
    "new.png", "new.json", "new.mp4", "new.jsonl", "new.xml", "new.zip", "new.md",
    "newdir", "sub/new.png", "sub/deep/new.mp4", "empty/new.png", "report/new.png",
    "empty/newdir", "new.PNG", "new.MP4", "new", str(SANDBOX / "abs.png"), "a" * 251 + ".png"]
PATHS_BAD = [
    "file.json/x.png", "file.json/sub", "pic.png/x.mp4", "clip.mp4/new.json", "/proc/x.png",
    "/sys/x.png", "/proc/newdir", "/sys/x.json", "/sys/x.mp4", "/proc/x/y.jsonl",
    "/sys/x.xml", "/sys/newdir", "a" * 300 + ".png", "d/" * 40 + "x.png", "missing.mp4",
    "missing.json", "missing.zip"]
PATHS = PATHS_EXISTING + PATHS_NEW + PATHS_BAD
HOSTILE = NUMBERS + RANGES + STRINGS + PATHS

VALID: dict[str, list[str]] = {
    "seed": ["0", "1", "7", "12"], "difficulty": ["0", "0.5", "1"],
    "track": ["oval", "straight", "figure-eight", "thesis", "7", "1", "track.json",
              "bad.json", "missing.json", "left-curve"],
    "file": ["track.json", "oval", "bad.json", "missing.json", "thesis", "file.json",
             "report"],
    "s": ["1", "0", "5.5", "-3", "1e6"], "lateral": ["-0.2", "0", "0.5", "-5"],
    "heading": ["0", "0.1", "-3.14", "100"],
    "seeds": ["3:4", "7:8", "3:5", "0:100000000"],
    "epsilon_px": ["5", "0", "752", "0.5"], "speed": ["1.5", "0.5", "4", "0.01"],
    "stride": ["1", "5", "50"], "max_frames": ["1", "3", "10"],
    "workers": ["1", "2", "3", "64"], "laps": ["1", "2", "1000"],
    "thesis": ["straight", "curve,track", "curve", "track,track"],
    "timesteps": ["1", "64", "1000000000000"], "n_envs": ["1", "2", "64"],
    "faults": ["none", "blackout", "none,blackout", "bogus"],
    "speeds": ["1.5", "1,2", "0.5,1.5,3"], "loops": ["1", "2", "3"],
    "camera": ["thesis", "reference-car", "car.yaml", "bad.json", "sony", "road.png"],
    "policy": [str(REAL_POLICY), "policy.zip", "report/policy.zip", "missing.zip",
               "track.json"],
}
"""Valid-looking values by option dest."""

VALID.update({"results": ["new.jsonl", "frames.jsonl", "sub/new.jsonl", "file.json"],
              "ray_address": ["127.0.0.1:1", "auto"]})

NOT_FUZZED = {"ray"}
"""Choices the fuzz never passes: ``--backend ray`` starts a Ray (seconds, beyond the
examples' budget; tests/tfalda_sim/test_ray_backend.py tests it). ``--ray-address`` is
still fuzzed: without ``--backend ray`` the parser refuses it."""

FOR_COMMAND: dict[tuple[str, ...], dict[str, list[str]]] = {
    ("track", "generate"): {"out": ["new.json", "sub/new.json", "track.json"],
                            "png": ["new.png", "pic.png", "sub/new.png", "link.png"]},
    ("render",): {"out": ["new.png", "sub/new.png", "pic.png", "link.png"],
                  "truth": ["truth.png", "pic.png", "new.png"]},
    ("evaluate",): {"plot": ["new.png", "pic.png"], "xml": ["new.xml", "lanes.xml"],
                    "jsonl": ["new.jsonl", "frames.jsonl"], "video": ["new.mp4", "clip.mp4"]},
    ("compare",): {"out": ["newdir", "report", "empty", "sub/newdir"],
                   "seeds": ["3:4", "7:8", "0:100000000"]},
    ("drive",): {"video": ["new.mp4", "clip.mp4", "sub/new.mp4"],
                 "camera_video": ["cam.mp4", "clip.mp4", "new.mp4"],
                 "track": ["oval", "7", "figure-eight", "thesis", "straight", "1", "oval.json"]},
    ("train",): {"out": ["newdir", "report", "runs/ppo", "empty", "sub/run"]},
    ("stress",): {"out": ["newdir", "report", "out/stress", "empty"],
                  "seeds": ["10003:10004", "10003:10005", "0:100000000"]},
    ("evaluate-agent",): {"out": ["new.json", "track.json", "sub/new.json"],
                          "seeds": ["10003:10004", "10003:10005", "0:100000000"]},
    ("camera", "fit"): {"frame": ["road.png", "pic.png", "clip.mp4", "missing.png"],
                        "out": ["new.yaml", "car.yaml", "sub/new.yaml", "new.yml"],
                        "overlay": ["new.png", "pic.png", "road.png"],
                        "intrinsics": ["car.yaml", "bad.json", "missing.yaml", "road.png"],
                        "points": ["points.json", "bad.json", "file.json"],
                        "bonnet": ["auto", "none", "points.json", "bad.json"],
                        "forward_m": ["0.2", "0", "-5", "nan"]},
    ("camera", "show"): {"camera": ["thesis", "reference-car", "car.yaml", "bad.json",
                                    "sony", "road.png"]},
    ("replay",): {"video": ["clip.mp4", "link.png", "pic.png", "missing.mp4", "report",
                            str(SANDBOX / "clip.mp4")],
                  "out": ["new.mp4", "clip.mp4", "sub/new.mp4"]},
}
"""Valid-looking values of one command's options (mostly its output paths, whose suffix
depends on the command); they come first, before ``VALID``."""

UNKNOWN = ["--bogus", "--bogus=1", "-z", "--", "extra", "--help", "-h", "--json=1",
           "--no-such-option", "---", "-", "--=x"]


def _valid_values(command: tuple[str, ...], action: argparse.Action) -> list[str]:
    """What a user would plausibly pass to ``action``: its choices, the tables above; for
    an option the tables do not know, the path pool (Path) or the hostile pool."""
    valid = [str(c) for c in action.choices or () if str(c) not in NOT_FUZZED]
    valid += FOR_COMMAND.get(command, {}).get(action.dest, VALID.get(action.dest, []))
    if not valid:
        valid = PATHS if action.type is Path else HOSTILE
    return valid


def _options(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    return [a for a in parser._actions if not isinstance(a, argparse._HelpAction)]


@contextlib.contextmanager
def _quiet() -> Iterator[None]:
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        yield


_PARSER = build_parser()


def _parses(argv: list[str]) -> bool:
    """Whether argparse accepts ``argv`` (the command's own checks come later)."""
    with _quiet():
        try:
            _PARSER.parse_args(argv)
        except SystemExit:
            return False
    return True


@st.composite
def _argv(draw: st.DrawFn, command: tuple[str, ...], hostile: int) -> list[str]:
    rate = draw(st.sampled_from([1, 2, 4]))  # tenths of the optional options passed

    def chance(tenths: int) -> bool:
        return draw(st.integers(0, 9)) < tenths

    def value(action: argparse.Action) -> str:
        pool = HOSTILE if chance(hostile) else _valid_values(command, action)
        return draw(st.sampled_from(pool))

    groups: list[list[str]] = []
    for action in _options(leaf_commands()[command]):
        if not action.option_strings:  # a positional
            if not (hostile and chance(1)):
                groups.append([value(action)])
            continue
        wanted = (not (hostile and chance(1))) if action.required else chance(rate)
        if not wanted:
            continue
        flag = draw(st.sampled_from(action.option_strings))
        if action.nargs == 0:
            groups.append([f"{flag}=1"] if hostile and chance(1) else [flag])
        elif hostile and chance(1):
            groups.append([flag])  # the value missing
        else:
            v = value(action)
            groups.append([f"{flag}={v}"] if chance(2) else [flag, v])
    if hostile and chance(3):
        groups.append([draw(st.sampled_from(UNKNOWN))])
    ordered = draw(st.permutations(groups))
    return [*command, *(token for group in ordered for token in group)]


STARTS: dict[tuple[str, ...], list[list[str]]] = {
    ("track", "list"): [["--json"]],
    ("track", "generate"): [["--seed", "1", "--out", "new.json", "--png", "new.png", "--json"]],
    ("track", "validate"): [["track.json", "--json"], ["figure-eight"]],
    ("render",): [["--track", "oval", "--s", "1", "--out", "new.png", "--truth", "truth.png",
                   "--json"]],
    ("evaluate",): [["--frames", "frames", "--labels", "frames", "--camera", "reference-car",
                     "--repeat", "2", "--json"],
                    ["--scenario", "random", "--seeds", "3:4", "--max-frames", "3", "--jsonl",
                     "new.jsonl", "--plot", "new.png", "--json"],
                    ["--scenario", "straight", "--stride", "50", "--xml", "new.xml",
                     "--video", "new.mp4"],
                    ["--scenario", "random", "--seeds", "3:5", "--max-frames", "2",
                     "--workers", "2", "--ablation", "--plot", "new.png"]],
    ("compare",): [["--no-thesis", "--seeds", "3:4", "--max-frames", "3", "--workers", "1",
                    "--out", "newdir", "--json"],
                   ["--no-generated", "--thesis", "straight", "--out", "newdir"]],
    ("drive",): [["--track", "oval", "--laps", "1", "--video", "new.mp4", "--camera-video",
                  "cam.mp4", "--json"]],
    ("stress",): [["--seeds", "10003:10004", "--faults", "none", "--workers", "1", "--out",
                   "newdir", "--json"]],
    ("evaluate-agent",): [["--seeds", "10003:10004", "--laps", "1", "--workers", "1", "--out",
                           "new.json", "--json"]],
    ("train",): [["--timesteps", "64", "--n-envs", "1", "--out", "newdir", "--json"]],
    ("camera", "fit"): [["road.png", "--fit-focal", "--out", "new.yaml", "--json"],
                        ["road.png", "--intrinsics", "car.yaml", "--out", "new.yaml",
                         "--bonnet", "none"]],
    ("camera", "show"): [["reference-car", "--json"], ["car.yaml"]],
    ("camera", "list"): [["--json"]],
    ("replay",): [["clip.mp4", "--detector", "hough", "--out", "new.mp4", "--json"],
                  ["clip.mp4", "--detector", "tfalda", "--loops", "2", "--out", "new.mp4"],
                  ["clip.mp4", "--detector", "hough", "--forever", "--stages", "--out",
                   "new.mp4"]],
}
"""Argument vectors that work (the console tests' and a few more): the starting points
of ``mutated``, which gets most examples past the argument checks into the work."""


def _groups(parser: argparse.ArgumentParser, argv: list[str]) -> list[list[str]]:
    """``argv`` split into its options with their values and its positionals."""
    groups: list[list[str]] = []
    tokens = iter(argv)
    for token in tokens:
        action = parser._option_string_actions.get(token)
        groups.append([token] if action is None or action.nargs == 0 else [token, next(tokens)])
    return groups


@st.composite
def mutated(draw: st.DrawFn, command: tuple[str, ...]) -> list[str]:
    """A working argv of ``STARTS`` with 0–3 mutations: a value replaced (valid-looking or
    hostile), an option dropped, an option of the parser added, ``--force`` added."""
    parser = leaf_commands()[command]
    groups = _groups(parser, draw(st.sampled_from(STARTS[command])))
    for _ in range(draw(st.integers(0, 3))):
        kind = draw(st.sampled_from(["value", "value", "drop", "add", "force"]))
        if kind == "value" and groups:
            k = draw(st.integers(0, len(groups) - 1))
            action = (parser._option_string_actions.get(groups[k][0])
                      if groups[k][0].startswith("-") else
                      next(a for a in _options(parser) if not a.option_strings))
            if action is not None and (action.nargs != 0 or not action.option_strings):
                pool = draw(st.sampled_from([_valid_values(command, action), HOSTILE]))
                groups[k] = [*groups[k][:-1], draw(st.sampled_from(pool))]
        elif kind == "drop" and groups:
            del groups[draw(st.integers(0, len(groups) - 1))]
        elif kind == "add":
            action = draw(st.sampled_from([a for a in _options(parser) if a.option_strings]))
            flag = draw(st.sampled_from(action.option_strings))
            groups.append([flag] if action.nargs == 0 else
                          [flag, draw(st.sampled_from(_valid_values(command, action)))])
        elif kind == "force":
            groups.append(["--force"])
    return [*command, *(token for group in groups for token in group)]


@st.composite
def generated(draw: st.DrawFn, command: tuple[str, ...]) -> list[str]:
    """An argv built from the parser alone (a new command or option is covered): the
    positionals and required options nearly always, a random subset of the other
    options, in a random order, as ``--opt value`` or ``--opt=value``. Each example draws
    how hostile it is: from none (then the argv is drawn again, up to 5 times, until
    argparse accepts it) to a third of its values from the hostile pool, bare options and
    unknown ones."""
    hostile = draw(st.sampled_from([0, 1, 3]))  # tenths of the values
    argv = draw(_argv(command, hostile))
    for _ in range(4 if hostile == 0 else 0):
        if _parses(argv):
            break
        argv = draw(_argv(command, hostile))
    return argv


def argvs(command: tuple[str, ...]) -> st.SearchStrategy[list[str]]:
    """Argument vectors for ``command``: mutated working ones, and built from scratch."""
    if command not in STARTS:
        return generated(command)
    return st.one_of(mutated(command), generated(command))


# --------------------------------------------------------------------------- fixtures
def _warm_up() -> None:
    """Load the numba kernels, matplotlib, torch and stable-baselines3 once, untimed: a
    Ctrl-C landing in the middle of a first import would test the test, not the CLI."""
    for module in ("tfalda_sim.agents.drive", "tfalda_sim.agents.evaluate",
                   "tfalda_sim.agents.stress",
                   "tfalda_sim.evaluation.baseline", "tfalda_sim.evaluation.charts",
                   "tfalda_sim.evaluation.sweep", "stable_baselines3", "tfalda_sim.agents.train"):
        with contextlib.suppress(ImportError):  # the rl extra may be missing
            importlib.import_module(module)

    s = str(SCRATCH)
    clip = str(SANDBOX / "clip.mp4")
    with _quiet():
        for argv in (
                ["render", "--track", "oval", "--s", "1", "--out", f"{s}/r.png",
                 "--truth", f"{s}/t.png", "--effects", "random"],
                ["evaluate", "--scenario", "random", "--seeds", "3:4", "--max-frames", "2",
                 "--plot", f"{s}/e.png", "--xml", f"{s}/e.xml", "--video", f"{s}/e.mp4"],
                ["compare", "--no-thesis", "--seeds", "3:4", "--max-frames", "2",
                 "--workers", "1", "--out", f"{s}/c"],
                ["replay", clip, "--detector", "tfalda", "--out", f"{s}/rt.mp4"],
                ["replay", clip, "--detector", "hough", "--out", f"{s}/rh.mp4", "--stages"],
                ["track", "generate", "--seed", "1", "--png", f"{s}/g.png"],
                # a drive with cartons: the obstacle kernels compile here, not in a fuzzed
                # run, where the simulated Ctrl-C could land in llvmlite's finalizers
                # (an exception raised in a __del__ is swallowed, never reaches main)
                ["drive", "--laps", "1", "--obstacles", "--camera", "reference-car"]):
            assert main(argv) == 0, argv


@pytest.fixture(scope="module")
def baseline() -> dict[str, Entry]:
    """The sandbox, built and copied to PRISTINE, and the commands warmed up."""
    _build_sandbox(SANDBOX)
    shutil.copytree(SANDBOX, PRISTINE, symlinks=True, dirs_exist_ok=True)
    _warm_up()
    return snapshot()


# --------------------------------------------------------------------------- tests
def test_sandbox_snapshot_sees_a_change(baseline: dict[str, Entry]) -> None:
    """The check is not vacuous: an overwrite, a touch and a new file all show."""
    (SANDBOX / "pic.png").write_bytes(b"changed")
    os.utime(SANDBOX / "track.json", ns=(0, 0))
    (SANDBOX / "report" / "new.md").write_text("new")
    after = snapshot()
    assert {k for k, v in baseline.items() if after.get(k) != v} == {"pic.png", "track.json"}
    assert set(after) - set(baseline) == {"report/new.md"}
    restore(baseline)
    assert snapshot() == baseline


def test_budget_interrupts_a_long_command(baseline: dict[str, Entry]) -> None:
    """The simulated Ctrl-C works: a 1000-lap drive stops with 130 and keeps its video."""
    outcome = run_cli(["drive", "--track", "oval", "--laps", "1000", "--video", "v.mp4"],
                      baseline)
    check(outcome, baseline)
    assert outcome.code == 130 and outcome.interrupted, str(outcome)
    assert "interrupted (Ctrl-C)" in outcome.err and "v.mp4" in outcome.new, str(outcome)
    assert outcome.seconds < BUDGET_S + HANG_S


def test_refused_overwrite_is_seen(baseline: dict[str, Entry]) -> None:
    """An existing output without --force: exit 2, the file untouched."""
    outcome = run_cli(["track", "generate", "--seed", "1", "--png", "pic.png"], baseline)
    check(outcome, baseline)
    assert outcome.code == 2 and "--force" in outcome.err, str(outcome)
    forced = run_cli(["track", "generate", "--seed", "1", "--png", "pic.png", "--force"],
                     baseline)
    check(forced, baseline)
    assert forced.code == 0 and forced.changed == ["pic.png"], str(forced)


@pytest.mark.parametrize("command", list(leaf_commands()), ids=" ".join)
def test_fuzz(command: tuple[str, ...], baseline: dict[str, Entry]) -> None:
    seen: Counter[str] = Counter()

    @settings(FUZZ, max_examples=EXAMPLES.get(command, DEFAULT_EXAMPLES))
    @given(argv=argvs(command), budget_s=st.sampled_from([BUDGET_S] * 3 + [EARLY_S]))
    def fuzz(argv: list[str], budget_s: float) -> None:
        outcome = run_cli(argv, baseline, budget_s)
        seen[f"exit {outcome.code}" + (" after Ctrl-C" if outcome.interrupted else "")] += 1
        check(outcome, baseline)

    fuzz()
    print(f"{' '.join(command)}: {dict(sorted(seen.items()))}")  # shown with -s
    # Not vacuous: some examples got past the argument checks into the command's work.
    assert sum(n for k, n in seen.items() if not k.startswith("exit 2")) > 0, seen


@pytest.mark.parametrize("argv", [
    ["evaluate", "--scenario", "random", "--seeds", "0:100000000", "--workers", "64",
     "--jsonl", "new.jsonl"],
    ["compare", "--no-thesis", "--seeds", "0:100000000", "--workers", "64", "--out", "newdir"],
    ["stress", "--seeds", "0:100000000", "--workers", "64", "--out", "newdir"],
    ["evaluate-agent", "--seeds", "0:100000000", "--workers", "64", "--laps", "1"],
], ids=lambda argv: argv[0])
def test_interrupted_pool_leaves_no_worker(argv: list[str], baseline: dict[str, Entry]) -> None:
    """``--workers 64`` is capped at the CPUs (≥ 2 workers on a multi-core machine); the
    Ctrl-C lands while the pool works on an endless range: 130, no worker left."""
    outcome = run_cli(argv, baseline, sample_children=True)
    check(outcome, baseline)
    assert outcome.code == 130 and outcome.interrupted, str(outcome)
    assert "--workers 64 capped to" in outcome.err, str(outcome)
    if available_cpus() >= 2:  # the pool did run (one process: no pool)
        assert outcome.peak_children >= 2, str(outcome)


def test_train_keeps_an_earlier_runs_tensorboard_logs(tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """The fuzz's no-overwrite rule where the fuzz cannot reach (a training needs longer
    than the budget to finish its first rollout): ``train --out DIR`` once checked only
    DIR/policy.zip and DIR/train.json, then put its TensorBoard logs in place of
    DIR/tb/PPO_1, deleting an earlier run's. PPO is shrunk to one 64-step rollout so the
    run takes a few seconds."""
    pytest.importorskip("stable_baselines3", reason="train needs the rl extra")
    import tfalda_sim.agents.train

    @dataclass(frozen=True)
    class TinyPpo(tfalda_sim.agents.train.PpoConfig):
        n_steps: int = 64
        batch_size: int = 64
        n_epochs: int = 1

    monkeypatch.setattr(tfalda_sim.agents.train, "PpoConfig", TinyPpo)
    old = tmp_path / "run" / "tb" / "PPO_1" / "events.out.tfevents.earlier-run"
    old.parent.mkdir(parents=True)
    old.write_bytes(b"an earlier run's logs")
    monkeypatch.chdir(tmp_path)
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(["train", "--timesteps", "64", "--n-envs", "1", "--out", "run", "--json"])
    assert code in (0, 2), err.getvalue()
    assert old.is_file() and old.read_bytes() == b"an earlier run's logs", (
        f"exit {code}: {old.relative_to(tmp_path)} was replaced without --force; the folder "
        f"now holds {sorted(str(p.relative_to(tmp_path)) for p in old.parents[1].rglob('*'))}")
    assert code == 2 and "add --force" in err.getvalue()
    # With --force the new run's logs go beside the earlier ones, which are kept.
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(["train", "--timesteps", "64", "--n-envs", "1", "--out", "run", "--json",
                     "--force"])
    assert code == 0, err.getvalue()
    assert old.read_bytes() == b"an earlier run's logs"
    assert sorted(p.name for p in (tmp_path / "run" / "tb").iterdir()) == ["PPO_1", "PPO_2"]
    assert (tmp_path / "run" / "policy.zip").is_file()


def test_evaluate_agent_stops_at_ctrl_c_with_one_worker(baseline: dict[str, Entry]) -> None:
    """Found by the fuzz (fixed): a Ctrl-C during a drive of ``evaluate-agent --workers
    1`` must end the sweep with 130 — it was caught inside the drive, whose lap was then
    scored as a failed seed, and the next seed started. 1000 laps: the Ctrl-C surely lands
    in the drive, not in its set-up."""
    outcome = run_cli(["evaluate-agent", "--seeds", "10003:10004", "--laps", "1000",
                       "--workers", "1", "--json"], baseline, budget_s=3.0)
    assert outcome.interrupted, str(outcome)
    assert outcome.code == 130, str(outcome)
