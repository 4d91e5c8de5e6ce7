"""The benchmark scripts run and report what BENCHMARKS.md quotes, and BENCHMARKS.md is
what ``benchmarks/report.py`` makes of their committed results (no timing is asserted:
speed is measured by the scripts, never by tests)."""

from __future__ import annotations

import copy
import functools
import importlib.util
import itertools
import json
import os
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def run_json(script: str, *args: str) -> dict:
    """``script``'s ``--json`` output with ``args`` (run once per arguments in a pytest
    run: the page's schema test and the script's own test share a run)."""
    return copy.deepcopy(_run_json(script, args))


@functools.cache
def _run_json(script: str, args: tuple[str, ...]) -> dict:
    done = subprocess.run([sys.executable, str(BENCHMARKS / script), *args, "--json"],
                          capture_output=True, text=True, timeout=600, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout)


@functools.cache
def report_module() -> ModuleType:
    """``benchmarks/report.py``, imported from its file."""
    spec = importlib.util.spec_from_file_location("benchmarks_report", BENCHMARKS / "report.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def test_benchmarks_md_is_generated_from_the_committed_results() -> None:
    """BENCHMARKS.md is exactly what ``report.py`` writes from ``benchmarks/results/``
    (``--check``: no benchmark runs), and stays one page."""
    done = subprocess.run([sys.executable, str(BENCHMARKS / "report.py"), "--check"],
                          capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 0, (done.stdout[-3000:], done.stderr[-1000:])
    page = (BENCHMARKS.parent / "BENCHMARKS.md").read_bytes()
    assert len(page) <= 40_000


def test_report_check_shows_a_difference(tmp_path: Path, monkeypatch, capsys) -> None:
    """``--check`` against a page that differs: exit 1 and a diff naming the line."""
    report = report_module()
    page = tmp_path / "BENCHMARKS.md"
    page.write_text(report.render(report.load_results()).replace("# Benchmarks",
                                                                 "# Old benchmarks"))
    monkeypatch.setattr(report, "PAGE", page)
    assert report.main(["--check"]) == 1
    out = capsys.readouterr().out
    assert "-# Old benchmarks" in out and "+# Benchmarks" in out


SMALL_ARGS: dict[str, tuple[str, ...]] = {
    "bench_env": ("--steps", "40", "--warmup-steps", "20"),
    "bench_reset": ("--resets", "3"),
    "bench_render": ("--frames", "10"),
    "bench_perception": ("--frames", "10"),
    "bench_replay": ("--frames", "10", "--rounds", "2", "--drive-steps", "10"),
    "bench_candidates": ("--rois", "24", "--repeat", "1"),
    "bench_tracks": ("--seeds", "5", "--raster-seeds", "2"),
}
"""Each benchmark of the page with sizes small enough for a test."""


def test_every_benchmark_of_the_page_has_small_sizes() -> None:
    assert [b.name for b in report_module().BENCHMARKS] == list(SMALL_ARGS)


@pytest.mark.parametrize("name", list(SMALL_ARGS))
def test_the_page_reads_only_keys_the_script_prints(name: str) -> None:
    """The script, run now with small sizes, prints the same keys as its committed result
    (which is of the script as it is), and every key the page reads is one of them."""
    report = report_module()
    reads: dict[str, set[tuple[str, ...]]] = {}
    report.render(report.load_results(reads))
    printed = report.key_paths(run_json(f"{name}.py", *SMALL_ARGS[name]))
    committed = json.loads((report.RESULTS / f"{name}.json").read_text(encoding="utf-8"))
    assert report.key_paths(committed) == printed, (
        f"benchmarks/results/{name}.json is not of the script as it is: rerun "
        f"`python benchmarks/report.py --run {name}`")
    assert reads[name] and reads[name] <= printed, reads[name] - printed
    assert {"cpu", "cores", "python", "date", "commit"} <= set(committed["machine"])


def test_bench_env_reports_every_configuration_against_car_racing() -> None:
    result = run_json("bench_env.py", "--steps", "40", "--warmup-steps", "20")
    assert (result["steps"], result["warmup_steps"], result["reference_warmup_steps"]) == (
        40, 20, 20)
    envs = result["envs"]
    reference = envs["CarRacing-v3 (reference)"]
    assert isinstance(reference, dict), reference  # Box2D is installed (dev extra)
    for name, r in envs.items():
        assert isinstance(r, dict), f"{name}: {r}"
        assert r["steps_per_s"] > 0 and r["ratio_to_car_racing"] > 0
    assert {"make_vec, 1 env, lanes, generated", "make_vec, 2 envs, lanes, generated",
            "lanes, fixed track (oval)", "lanes, new generated track per reset",
            "1 process alone, lanes, generated",
            "2 processes at once, lanes, generated",
            "2 processes at once, each at its own pace",
            "lanes, fixed track (oval), dynamic car, real-car timing"} <= set(envs)
    dynamic_cost = "step cost: dynamic car + real-car timing / kinematic car (lanes, fixed)"
    assert set(result["ratios"]) == {"make_vec 2 envs / 1 env",
                                     "2 processes at once / 1 (the machine's ceiling)",
                                     "2 processes, each at its own pace / 1",
                                     "generated / fixed track (lanes)",
                                     "generated / fixed track (lanes), resets off the clock",
                                     dynamic_cost}
    # The real car's step cost is the kinematic car's rate over its own (same run).
    assert result["ratios"][dynamic_cost] == pytest.approx(
        envs["lanes, fixed track (oval)"]["steps_per_s"]
        / envs["lanes, fixed track (oval), dynamic car, real-car timing"]["steps_per_s"])
    # A single env's resets are clocked apart: a part of its time, so its steps alone
    # are faster than its steps with resets; the ratio without them is theirs.
    for name in ("lanes, fixed track (oval)", "lanes, new generated track per reset"):
        r = envs[name]
        if r["episodes"] == 1:  # no reset in these 40 steps: nothing to time
            assert r["ms_per_reset"] is None
            assert r["steps_per_s_without_resets"] == pytest.approx(r["steps_per_s"])
        else:
            assert r["ms_per_reset"] > 0
            assert r["steps_per_s_without_resets"] > r["steps_per_s"]
    assert result["ratios"]["generated / fixed track (lanes), resets off the clock"] == (
        pytest.approx(envs["lanes, new generated track per reset"]["steps_per_s_without_resets"]
                      / envs["lanes, fixed track (oval)"]["steps_per_s_without_resets"]))
    # A process's own stepping time is part of its turn's wall clock: at their own pace
    # the two are at least as fast as in turns that wait for the slower one.
    pair = envs["2 processes at once, lanes, generated"]
    assert envs["2 processes at once, each at its own pace"]["steps_per_s"] == pytest.approx(
        pair["own_pace_steps_per_s"])
    assert pair["own_pace_steps_per_s"] >= pair["steps_per_s"]
    assert envs["1 process alone, lanes, generated"]["own_pace_steps_per_s"] >= (
        envs["1 process alone, lanes, generated"]["steps_per_s"])
    # The CPU is named (figures compare only on one CPU; the host changes between runs).
    machine = result["machine"]
    assert machine["cores"] == os.cpu_count() and machine["simd"] != ""
    cpuinfo = Path("/proc/cpuinfo")
    models = [line.partition(":")[2].strip() for line in
              (cpuinfo.read_text(errors="replace").splitlines() if cpuinfo.exists() else [])
              if line.partition(":")[0].strip() == "model name"]
    assert machine["cpu"] == (models[0] if models else machine["cpu"]) and machine["cpu"]
    # The printed table (without --json) holds every figure, one row each, the numbers of
    # every row in the same columns however long its name.
    sys.path.insert(0, str(BENCHMARKS))
    try:
        import bench_env
    finally:
        sys.path.remove(str(BENCHMARKS))
    lines = bench_env.table(result).splitlines()
    assert machine["cpu"] in lines[0]
    assert "40 steps after 20 warm-up steps per env or stream (CarRacing-v3: 20)" in lines[0]
    rows = {line.split("  ", 1)[0]: line for line in lines[2:]}
    assert set(rows) == set(envs) | set(result["ratios"])
    name = "2 processes at once, each at its own pace"
    assert rows[name].split()[-5:] == [f"{envs[name]['steps_per_s']:.0f}",
                                       f"{envs[name]['ms_per_step']:.3f}",
                                       f"{envs[name]['episodes']:.0f}",
                                       f"{envs[name]['ratio_to_car_racing']:.2f}×", "–"]
    name = "lanes, new generated track per reset"
    reset = envs[name]["ms_per_reset"]
    assert rows[name].split()[-2:] == [f"{envs[name]['ratio_to_car_racing']:.2f}×",
                                       "–" if reset is None else f"{reset:.3f}"]
    for ratio, value in result["ratios"].items():
        assert rows[ratio].split()[-1] == f"{value:.2f}"
    # right-aligned numbers: a ratio row ends where the steps/s column does (41 chars before)
    ends = {len(line) for line in lines[2:2 + len(envs)]}
    assert len(ends) == 1 and {len(line) for line in lines[2 + len(envs):]} == {
        ends.pop() - 41}


@pytest.mark.parametrize(("args", "message"), [
    (("--steps", "0"), "--steps must be ≥ 1"),
    (("--warmup-steps", "-1"), "--warmup-steps must be ≥ 0"),
    (("--warmup-steps", "many"), "invalid int value"),
])
def test_bench_env_names_bad_arguments(args: tuple[str, ...], message: str) -> None:
    done = subprocess.run([sys.executable, str(BENCHMARKS / "bench_env.py"), *args],
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 2 and message in done.stderr and "Traceback" not in done.stderr


def test_bench_candidates_finds_the_kernels_identical() -> None:
    result = run_json("bench_candidates.py", "--rois", "24", "--repeat", "1")
    assert result["identical_results"] is True
    assert result["rois"] == 24
    assert result["executed_additions_per_roi"] >= result["useful_additions_per_roi"] > 0
    assert set(result["kernels"]) == {"first", "previous", "previous_uint16", "current",
                                      "current_uint16"}
    k = result["kernels"]
    for name, current in (("previous", "current"), ("previous_uint16", "current_uint16"),
                          ("first", "current")):  # each against the right current kernel
        assert k[name]["time_over_current"] == pytest.approx(
            k[name]["us_per_roi"] / k[current]["us_per_roi"])
    assert result["speed_up_over_previous_uint16"] == pytest.approx(
        k["previous_uint16"]["us_per_roi"] / k["current_uint16"]["us_per_roi"])
    path = result["per_roi_path"]
    assert path["identical_lanes"] is True
    assert path["speed_up_over_previous"] == pytest.approx(
        path["previous_us_per_roi"] / path["current_us_per_roi"])


def test_bench_reset_times_lazy_eager_and_fixed_track_resets() -> None:
    result = run_json("bench_reset.py", "--resets", "3")
    assert set(result["reset"]) == {"fixed track (seed 7)", "new track, lazy scene",
                                    "new track, eager scene", "new track, lazy, image mode"}
    for name, r in result["reset"].items():
        assert r["resets"] == 3 and 0 < r["median_ms"] <= r["max_ms"], name
    assert result["eager_over_lazy"] > 0


REPLAY_KINDS: dict[str, str] = {
    "MP4 video (reference)": "video",
    "image folder, PNG": "images",
    "ROS 1 bag, Image mono8": "ros1",
    "ROS 2 bag (sqlite3), Image mono8": "ros2-sqlite3",
    "ROS 2 bag (MCAP storage), CompressedImage PNG": "ros2-mcap",
    "MCAP file, Image mono8": "mcap",
}
"""bench_replay's source kinds and the kind ``open_source`` finds each to be."""


def test_bench_replay_reads_and_replays_every_kind_against_the_mp4() -> None:
    """Every kind of recording is read alone and replayed through both detectors, each
    figure with its ratio to the MP4's; the lossless kinds give the detectors the same
    frames, so the same detections; a drive recorded to MCAP records the start's frame and
    one a step."""
    result = run_json("bench_replay.py", *SMALL_ARGS["bench_replay"])
    assert (result["frames"], result["rounds"], result["frame_size_px"]) == (10, 2, [752, 480])
    assert result["reference"] == "MP4 video (reference)"
    kinds = result["kinds"]
    assert list(kinds) == list(REPLAY_KINDS)  # the table's order: the reference first
    for name, k in kinds.items():
        assert k["source_kind"] == REPLAY_KINDS[name]
        assert k["mb_per_frame"] > 0 and k["open_ms"] > 0
        for mode in ("read", "tfalda", "hough"):
            assert k[mode]["frames_per_s"] > 0 and k[mode]["ratio_to_mp4"] > 0, (name, mode)
        for detector in ("tfalda", "hough"):
            assert k[detector]["detector_ms_median"] > 0
            assert k[detector]["detections_per_frame"] > 0
    for mode in ("read", "tfalda", "hough"):  # every round's ratio of the MP4 to itself
        assert kinds["MP4 video (reference)"][mode]["ratio_to_mp4"] == 1.0
    lossless = [k for name, k in kinds.items() if name != "MP4 video (reference)"]
    for detector in ("tfalda", "hough"):
        assert len({k[detector]["detections_per_frame"] for k in lossless}) == 1, detector
    assert kinds["ROS 1 bag, Image mono8"]["encoding"] == "mono8"
    rec = result["recording"]
    assert (rec["track"], rec["drive_steps"], rec["frames_recorded"]) == ("oval", 10, 11)
    assert rec["mb_per_frame"] > 0 and rec["cost_ratio"] > 0
    for key in ("without", "with_mcap"):
        assert rec[key]["ms_per_step"] == pytest.approx(1000 / rec[key]["steps_per_s"])
    assert result["machine"]["pinned_to_one_core"] and result["machine"]["cores"] >= 1
    # The printed table: the machine, the header, a row per kind with its figures in the
    # same columns however long its name, then the drives.
    sys.path.insert(0, str(BENCHMARKS))
    try:
        import bench_replay
    finally:
        sys.path.remove(str(BENCHMARKS))
    lines = bench_replay.table(result).splitlines()
    assert result["machine"]["cpu"] in lines[0] and "medians of 2 rounds" in lines[0]
    rows = lines[2:2 + len(kinds)]
    assert [row.split("  ", 1)[0] for row in rows] == list(kinds)
    assert len({len(row) for row in rows}) == 1
    png = kinds["image folder, PNG"]
    assert rows[1].split()[-6:] == [
        cell for mode in ("read", "tfalda", "hough")
        for cell in (f"{png[mode]['frames_per_s']:.0f}", f"{png[mode]['ratio_to_mp4']:.2f}×")]
    assert lines[-1].startswith("drive on oval, 10 steps a drive")
    assert f"{rec['cost_ratio']:.2f}×" in lines[-1]


@pytest.mark.parametrize(("args", "message"), [
    (("--frames", "0"), "--frames must be ≥ 1"),
    (("--rounds", "0"), "--rounds must be ≥ 1"),
    (("--frames", "3001"), "--frames must be ≤ 3000"),
    (("--drive-steps", "20001"), "--drive-steps must be ≤ 20000"),
    (("--drive-steps", "many"), "invalid int value"),
])
def test_bench_replay_names_bad_arguments(args: tuple[str, ...], message: str) -> None:
    done = subprocess.run([sys.executable, str(BENCHMARKS / "bench_replay.py"), *args],
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 2 and message in done.stderr and "Traceback" not in done.stderr


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="bench_ab needs two cores")
def test_bench_ab_runs_two_checkouts_side_by_side() -> None:
    """This checkout against itself (the other checkout's Python is any interpreter with
    tfalda-sim installed): both sides report every figure and their ratio."""
    result = run_json("bench_ab.py", "--other", sys.executable, "--steps", "30",
                      "--resets", "2", "--pairs", "2")
    assert [row["pair"] for row in result["pairs"]] == [1, 2]
    first, second = result["pairs"]
    assert (first["this_core"], first["other_core"]) == (second["other_core"],
                                                         second["this_core"])
    for row in result["pairs"]:
        assert set(row["this"]) == set(row["other"]) == set(row["ratio"]) == {
            "fixed_steps_per_s", "generated_steps_per_s", "reset_median_ms"}
        assert all(v > 0 for v in row["ratio"].values())


def test_bench_ab_takes_turns_on_one_core() -> None:
    """``--turns``: this checkout against itself on one core, in turns; every figure of
    both sides and their ratio (near 1: the same code, the drift on both alike)."""
    result = run_json("bench_ab.py", "--other", sys.executable, "--turns", "--steps", "330",
                      "--resets", "12")
    assert result["steps"] == 330 and result["resets"] == 12 and not result["interrupted"]
    for side in ("this", "other", "ratio"):
        assert set(result[side]) == {"fixed_steps_per_s", "generated_steps_per_s",
                                     "reset_median_ms"}
        assert all(v > 0 for v in result[side].values())
    assert result["machine"]["one_core_in_turns"] == min(os.sched_getaffinity(0))


def test_bench_ab_refuses_pairs_with_turns() -> None:
    done = subprocess.run([sys.executable, str(BENCHMARKS / "bench_ab.py"), "--other",
                           sys.executable, "--turns", "--pairs", "2"], capture_output=True,
                          text=True, timeout=60, check=False)
    assert done.returncode == 2 and "contradict" in done.stderr
    assert "Traceback" not in done.stderr


def test_bench_ab_refuses_a_missing_interpreter() -> None:
    done = subprocess.run([sys.executable, str(BENCHMARKS / "bench_ab.py"), "--other",
                           "/nonexistent/python"], capture_output=True, text=True,
                          timeout=60, check=False)
    assert done.returncode == 2 and "not an executable file" in done.stderr
    assert "Traceback" not in done.stderr


def test_bench_vec_ab_takes_turns_with_the_vector_envs() -> None:
    """``bench_vec_ab.py``: this checkout against itself, every vector env figure of both
    sides, their ratio, each side's 2 envs / 1 env and the per-round ratios' quartiles."""
    result = run_json("bench_vec_ab.py", "--other", sys.executable, "--rounds", "3",
                      "--turn-steps", "40", "--warmup-steps", "30")
    assert (result["rounds"], result["turn_steps"], result["warmup_steps"]) == (3, 40, 30)
    assert not result["interrupted"]
    keys = {"2", "2same", "1"}
    assert set(result["figures"]) == keys
    for side in ("this", "other", "ratio"):
        assert set(result[side]) == keys | {"2/1"}
        assert all(v > 0 for v in result[side].values())
    for side in ("this", "other"):
        assert result[side]["2/1"] == pytest.approx(result[side]["2"] / result[side]["1"])
    for key, (q1, median, q3) in result["per_round_ratio_quartiles"].items():
        assert key in keys and 0 < q1 <= median <= q3


@pytest.mark.parametrize(("args", "message"), [
    (["--other", "/nonexistent/python"], "not an executable file"),
    (["--other", sys.executable, "--rounds", "0"], "--rounds must be"),
    (["--other", sys.executable, "--turn-steps", "1000001"], "--turn-steps must be"),
    (["--other", sys.executable, "--warmup-steps", "-1"], "--warmup-steps must be"),
])
def test_bench_vec_ab_refuses_bad_arguments(args: list[str], message: str) -> None:
    done = subprocess.run([sys.executable, str(BENCHMARKS / "bench_vec_ab.py"), *args],
                          capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 2 and message in done.stderr
    assert "Traceback" not in done.stderr


EPISODE_STEPS = 7
"""Steps of an episode of the benchmark tests' stand-in envs."""


def test_vector_configurations_and_the_ceiling_step_the_same_streams(monkeypatch) -> None:
    """Every vector configuration of ``bench_env`` and its ceiling step the same streams:
    env i is reset with seed i and gets stream i's actions, whether one vector env holds
    both streams, two 1-env ones hold one each, or the ceiling's single envs step them
    (resetting the step after an episode's end, spending its action, as a vector env's
    autoreset does), so their ratios compare the same work; what envs of one process
    share between resets (the generated tracks, the last painted marking map) is dropped
    before every turn's steps."""
    import threading
    from multiprocessing import Pipe

    import gymnasium as gym
    import numpy as np

    monkeypatch.syspath_prepend(str(BENCHMARKS))
    import bench_env

    space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
    events: list[str] = []  # "forget" or "step", in order

    class StandIn(gym.Env):
        """An env of ``EPISODE_STEPS``-step episodes that logs its seeds and actions."""

        action_space = space
        observation_space = space

        def __init__(self, log: list) -> None:
            self.log, self.t = log, 0

        def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple:
            self.log.append(("reset", seed))
            self.t = 0
            return np.zeros(1, np.float32), {}

        def step(self, action: np.ndarray) -> tuple:
            assert action.shape == (1,) and action.dtype == np.float32
            events.append("step")
            self.log.append(float(action[0]))
            self.t += 1
            return np.zeros(1, np.float32), 0.0, self.t == EPISODE_STEPS, False, {}

        def close(self) -> None:
            pass

    logs: dict[str, dict[int, list]] = {}

    def vector(name: str, first: int, n: int) -> gym.vector.VectorEnv:
        """Gymnasium's own NEXT_STEP autoreset and ``seed + i`` over stand-ins."""
        return gym.vector.SyncVectorEnv(
            [lambda i=i: StandIn(logs.setdefault(name, {}).setdefault(first + i, []))
             for i in range(n)])

    real_forget = bench_env.forget_shared_tracks
    monkeypatch.setattr(bench_env, "forget_shared_tracks",
                        lambda: (events.append("forget"), real_forget()))
    steps = 2 * bench_env.CHUNK_STEPS + 10
    warmup = 25
    result = bench_env.interleaved_vector_steps_per_second(
        {"two": lambda: [vector("two", 0, 2)],
         "ones": lambda: [vector("ones", 0, 1), vector("ones", 1, 1)]},
        steps=steps, quiet=True, warmup=warmup)
    assert set(result) == {"two", "ones"}
    # Each set-up and each turn (a turn of CHUNK_STEPS env steps, another, the last 10)
    # drops the caches before its steps, and only then.
    turns = 3
    blocks = " ".join(events).split("forget")
    assert blocks[0] == "" and len(blocks) == 1 + 2 * (1 + turns)
    assert all(block.split() and set(block.split()) == {"step"} for block in blocks[1:])

    # The ceiling's process loop, in this process over a pipe: the same streams.
    made: list[StandIn] = []
    monkeypatch.setattr(bench_env.gym, "make", lambda env_id: made.append(
        StandIn(logs.setdefault("solo", {}).setdefault(len(made), []))) or made[-1])
    monkeypatch.setattr(bench_env.cv2, "setNumThreads", lambda n: None)
    here, there = Pipe()
    loop = threading.Thread(target=bench_env._solo_process,
                            args=(there, None, [0, 1], warmup))
    loop.start()
    assert here.recv() is None  # warmed up
    episodes = 0
    for n in (bench_env.CHUNK_STEPS // 2, bench_env.CHUNK_STEPS // 2, 5):
        start = len(events)
        here.send(n)
        elapsed, ended = here.recv()
        episodes += ended
        assert elapsed >= 0 and events[start] == "forget" and "forget" not in events[start + 1:]
    here.send(0)
    loop.join(timeout=10)
    assert not loop.is_alive()

    # A ceiling made with another warm-up than the vector envs' would step other episodes.
    solo = object.__new__(bench_env._SoloProcessTurns)
    solo.warmup, solo.conns, solo.procs = warmup + 1, [], []
    with pytest.raises(ValueError, match=f"warmed up {warmup + 1} steps a stream, the "
                                         f"others {warmup}"):
        bench_env.interleaved_vector_steps_per_second({"solo": lambda: solo}, steps=10,
                                                      quiet=True, warmup=warmup)

    assert logs["two"] == logs["ones"] == logs["solo"]  # per stream: seed, actions, resets
    for i in range(bench_env.STREAMS):
        stream = logs["two"][i]
        assert stream[0] == ("reset", i)
        assert len(stream) == 1 + warmup + steps // 2
        actions = np.array([v for v in stream if isinstance(v, float)])
        assert np.all(np.abs(actions) <= 1.0) and np.std(actions) > 0.3  # uniform on [-1, 1]
        assert stream.count(("reset", None)) >= steps // 2 // (EPISODE_STEPS + 1) - 1
    assert logs["two"][0] != logs["two"][1]  # two streams
    assert episodes == result["two"]["episodes"] > 0  # the same episodes ended in turns

    # What is forgotten: a generated track and the last scene's marking map.
    from tfalda_sim.rendering import build_scene
    from tfalda_sim.rendering.scene import _last_marking
    from tfalda_sim.tracks import generate
    from tfalda_sim.tracks.generator import _generate_cached

    build_scene(generate(3))
    assert _generate_cached.cache_info().currsize > 0 and _last_marking
    real_forget()
    assert _generate_cached.cache_info().currsize == 0 and not _last_marking


def test_single_envs_and_the_reference_step_in_the_same_rounds(monkeypatch) -> None:
    """``bench_env`` steps the reference in turns with the envs divided by it: every
    round gives each env one turn, a slower reference spreads its fewer steps over the
    same rounds (the host's drift stays out of the ratios), each makes exactly its
    steps, and a total of no steps is refused."""
    import gymnasium as gym
    import numpy as np

    monkeypatch.syspath_prepend(str(BENCHMARKS))
    import bench_env

    log: list[str] = []

    def recorder(name: str) -> type:
        class Recorder:
            action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

            def reset(self, *, seed: int | None = None) -> None:
                pass

            def step(self, action: np.ndarray) -> tuple:
                log.append(name)
                return None, 0.0, False, False, {}

            def close(self) -> None:
                pass
        return Recorder

    assert bench_env.CHUNK_STEPS == 300  # the turns below
    steps = 4 * bench_env.CHUNK_STEPS  # four rounds
    result = bench_env.interleaved_steps_per_second(
        {"ref": recorder("ref"), "env": recorder("env")}, steps, quiet=True,
        totals={"ref": 10}, warmups={"ref": 3, "env": 7})
    assert log[:10] == ["ref"] * 3 + ["env"] * 7  # each warmed up by its own count
    timed = log[10:]
    assert timed.count("ref") == 10 and timed.count("env") == steps
    # turns in rounds: ref, env, ref, env, … — the reference's 10 steps in four turns
    turns = [(name, len(list(run))) for name, run in itertools.groupby(timed)]
    assert turns == [("ref", 3), ("env", 300), ("ref", 3), ("env", 300), ("ref", 3),
                     ("env", 300), ("ref", 1), ("env", 300)]
    assert {r["episodes"] for r in result.values()} == {1}
    assert {r["ms_per_reset"] for r in result.values()} == {None}  # no reset to time
    with pytest.raises(ValueError, match="at least one step"):
        bench_env.interleaved_steps_per_second({"ref": recorder("ref")}, steps, quiet=True,
                                               totals={"ref": 0})


def test_single_envs_resets_are_clocked_apart(monkeypatch) -> None:
    """A single env's resets are timed on their own: the mean reset, and the rate of its
    steps without them (what free resets would give), on the harness's clock, here one
    that a stand-in moves: 1 ms a step, 10 ms a reset, an episode's end every 50 steps."""
    from types import SimpleNamespace

    import gymnasium as gym
    import numpy as np

    monkeypatch.syspath_prepend(str(BENCHMARKS))
    import bench_env

    now = [0.0]
    monkeypatch.setattr(bench_env, "time", SimpleNamespace(perf_counter=lambda: now[0]))

    class SlowResets:
        action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
        steps = 0

        def reset(self, *, seed: int | None = None) -> None:
            now[0] += 0.010

        def step(self, action: np.ndarray) -> tuple:
            now[0] += 0.001
            self.steps += 1
            return None, 0.0, self.steps % 50 == 0, False, {}

        def close(self) -> None:
            pass

    steps, warmup = bench_env.CHUNK_STEPS, 20
    r = bench_env.interleaved_steps_per_second({"env": SlowResets}, steps, quiet=True,
                                               warmups={"env": warmup})["env"]
    # 20 warm-up steps, then 300: episodes end at steps 50, 100, …, 300 of the env's count
    assert r["episodes"] == 1 + (warmup + steps) // 50 == 7
    assert r["ms_per_reset"] == pytest.approx(10.0)
    assert r["steps_per_s"] == pytest.approx(steps / (0.001 * steps + 0.010 * 6))
    assert r["steps_per_s_without_resets"] == pytest.approx(1000.0)


def test_bench_kernel_ab_swaps_a_revisions_kernels_into_env_steps() -> None:
    result = run_json("bench_kernel_ab.py", "--rev", "HEAD", "--module",
                      "tfalda_sim.rendering.renderer", "--kernels", "_combine,_sample_atlas",
                      "--rounds", "3", "--turn-steps", "20")
    assert result["kernels"] == ["_combine", "_sample_atlas"]
    assert result["rounds"] == 3 and result["turn_steps"] == 20
    assert result["before_us_per_step"] > 0 and result["after_us_per_step"] > 0
    q1, q3 = result["ratio_quartiles"]
    assert 0 < q1 <= result["ratio_after_to_before"] <= q3
    assert result["machine"]["cores"] >= 1 and result["machine"]["pinned_to_one_core"]


@pytest.mark.parametrize(("args", "message"), [
    (("--rev", "no-such-revision", "--module", "tfalda_sim.rendering.renderer",
      "--kernels", "_combine"), "give a commit"),
    (("--rev", "HEAD", "--module", "tfalda_sim.rendering.renderer", "--kernels", "_nope"),
     "has no function _nope"),
    (("--rev", "HEAD", "--module", "tfalda_sim.no_such_module", "--kernels", "_combine"),
     "unknown module"),
    (("--rev", "HEAD", "--module", "tfalda_sim.rendering.renderer", "--kernels", "_combine",
      "--track", "no-such-track"), "unknown track"),
])
def test_bench_kernel_ab_names_bad_arguments(args: tuple[str, ...], message: str) -> None:
    refused("bench_kernel_ab.py", args, message)


def refused(script: str, args: tuple[str, ...], message: str) -> None:
    """``script`` with ``args`` (and one round) exits 2 naming the problem, no traceback."""
    done = subprocess.run([sys.executable, str(BENCHMARKS / script), *args, "--rounds", "1"],
                          capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 2
    assert message in done.stderr and "Traceback" not in done.stderr


def test_bench_paint_repaints_an_envs_tiles_with_both_revisions() -> None:
    result = run_json("bench_paint.py", "--rev", "HEAD", "--steps", "150", "--rounds", "2")
    assert result["identical"] is True
    assert result["episodes"] >= 1 and result["calls"] >= result["episodes"]
    assert result["tiles"] >= result["calls"] > 0
    assert result["before_ms"] > 0 and result["after_ms"] > 0
    assert result["after_us_per_tile"] == pytest.approx(
        result["after_ms"] * 1e3 / result["tiles"])
    q1, q3 = result["ratio_quartiles"]
    assert 0 < q1 <= result["ratio_after_to_before"] <= q3
    assert result["machine"]["cores"] >= 1 and result["machine"]["pinned_to_one_core"]


@pytest.mark.parametrize(("args", "message"), [
    (("--rev", "no-such-revision"), "give a commit"),
    (("--rev", "HEAD", "--steps", "0"), "must be ≥ 1"),
    (("--rev", "HEAD", "--steps", "100001"), "must be ≤ 100000"),
])
def test_bench_paint_names_bad_arguments(args: tuple[str, ...], message: str) -> None:
    refused("bench_paint.py", args, message)
