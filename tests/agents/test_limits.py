"""tfalda-sim limits: the bisection (exact to 0.1 m/s, both ends), the distribution, a real
run, its resume, Ctrl-C and bad input."""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path
from typing import Any

import pytest

from tests.cli_helpers import tfalda
from tfalda_sim.agents import limits
from tfalda_sim.cli import main

GRID = limits.speed_grid()


def _passing_up_to(threshold: float, calls: list[float] | None = None) -> Any:
    def passes(speed: float) -> dict[str, Any]:
        if calls is not None:
            calls.append(speed)
        return {"success": speed <= threshold + 1e-9}
    return passes


def test_the_grid_runs_from_the_lowest_to_the_top_speed_in_exact_tenths() -> None:
    assert GRID[0] == 0.5 and GRID[-1] == 8.3 == limits.TOP_SPEED_M_S and len(GRID) == 79
    assert all(s == round(s, 1) for s in GRID)
    assert all(math.isclose(b - a, 0.1) for a, b in itertools.pairwise(GRID))


def test_the_bisection_finds_every_limit_of_the_grid_exactly() -> None:
    for speed in GRID:
        calls: list[float] = []
        found = limits.bisect_limit(_passing_up_to(speed, calls))
        assert found["limit_m_s"] == speed, (speed, found)
        assert found["below_min_speed"] is False
        assert found["at_top_speed"] is (speed == 8.3)
        assert [d["speed_m_s"] for d in found["drives"]] == calls
        assert len(calls) <= 2 + math.ceil(math.log2(len(GRID) - 1))  # 9 drives at most


@pytest.mark.parametrize("threshold, limit", [(0.59, 0.5), (3.349, 3.3), (3.35, 3.3),
                                              (8.29, 8.2), (100.0, 8.3)])
def test_a_limit_between_grid_speeds_is_the_grid_speed_below(threshold: float,
                                                             limit: float) -> None:
    assert limits.bisect_limit(_passing_up_to(threshold))["limit_m_s"] == limit


def test_a_failure_at_the_lowest_speed_has_no_limit_and_one_drive() -> None:
    calls: list[float] = []
    found = limits.bisect_limit(_passing_up_to(0.49, calls))
    assert found == {"limit_m_s": None, "below_min_speed": True, "at_top_speed": False,
                     "drives": [{"speed_m_s": 0.5, "success": False}]}
    assert calls == [0.5]


def test_a_pass_at_the_top_speed_is_the_limit_after_two_drives() -> None:
    calls: list[float] = []
    found = limits.bisect_limit(_passing_up_to(8.3, calls))
    assert found["limit_m_s"] == 8.3 and found["at_top_speed"] and calls == [0.5, 8.3]


def _rec(seed: int, limit: float | None) -> dict[str, Any]:
    return {"seed": seed, "limit_m_s": limit, "below_min_speed": limit is None,
            "at_top_speed": limit == 8.3, "drives": []}


def test_the_summary_is_the_distribution_with_tracks_below_the_lowest_speed_slowest() -> None:
    s = limits.summarise([_rec(0, 2.0), _rec(1, 3.0), _rec(2, 4.0), _rec(3, 8.3), _rec(4, 1.0)])
    assert s == {"count": 5, "below_min_speed": 0, "at_top_speed": 1, "min_m_s": 1.0,
                 "q1_m_s": 2.0, "median_m_s": 3.0, "q3_m_s": 4.0, "max_m_s": 8.3}
    s = limits.summarise([_rec(0, None), _rec(1, 3.0), _rec(2, 4.0), _rec(3, 5.0)])
    assert s["below_min_speed"] == 1 and s["min_m_s"] is None and s["q1_m_s"] is None
    assert s["median_m_s"] == 3.5 and s["q3_m_s"] == 4.25 and s["max_m_s"] == 5.0
    assert limits.summarise([])["median_m_s"] is None


def test_a_real_bisection_is_deterministic_and_consistent_with_its_drives() -> None:
    """The dynamic car slides off beyond its grip: a limit between the ends, found
    twice alike."""
    from tfalda_sim.timing import TIMINGS

    job = ("pid", None, 1, 1, "thesis", False, "dynamic", TIMINGS["ideal"], 0.5)
    first = limits.run_job(job)
    assert first["limit_m_s"] is not None and 0.5 < first["limit_m_s"] < 8.3
    passed = [d["speed_m_s"] for d in first["drives"] if d["success"]]
    failed = [d["speed_m_s"] for d in first["drives"] if not d["success"]]
    assert max(passed) == first["limit_m_s"]
    assert min(failed) == pytest.approx(first["limit_m_s"] + 0.1)
    assert limits.run_job(job) == first


def test_a_run_and_its_resume_give_the_same_limits(tmp_path: Path) -> None:
    """Two tracks, one lap: the full run, then a run resumed after its first track (the
    second is driven again, alike)."""
    argv = ("limits", "--seeds", "0:2", "--laps", "1", "--workers", "1", "--results",
            "r.jsonl", "--json")
    full = tfalda(*argv, "--out", "full.json", cwd=tmp_path).json()
    assert [r["seed"] for r in full["per_seed"]] == [0, 1]
    assert full["summary"]["count"] == 2 and full["interrupted"] is False
    for r in full["per_seed"]:
        assert r["limit_m_s"] is None or r["limit_m_s"] in GRID
        assert r["below_min_speed"] is (r["limit_m_s"] is None)
    assert json.loads((tmp_path / "full.json").read_text()) == full
    lines = (tmp_path / "r.jsonl").read_text().splitlines()
    assert len(lines) == 3 and json.loads(lines[0])["config"]["vehicle"] == "kinematic"
    (tmp_path / "r.jsonl").write_text("\n".join(lines[:2]) + "\n")  # stopped after seed 0
    resumed = tfalda(*argv, "--resume", cwd=tmp_path).json()
    assert resumed["per_seed"] == full["per_seed"] and resumed["summary"] == full["summary"]
    # Other options than the file's: refused, naming the one that differs.
    run = tfalda(*argv, "--resume", "--vehicle", "dynamic", cwd=tmp_path, code=2)
    assert '--vehicle was "kinematic", now "dynamic"' in run.err, str(run)


def test_ctrl_c_keeps_the_tracks_finished(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    def job(j: limits.Job) -> dict[str, Any]:
        if j[2] == 2:
            raise KeyboardInterrupt
        return _rec(j[2], 1.0 + j[2])

    monkeypatch.setattr(limits, "run_job", job)
    code = main(["limits", "--seeds", "0:4", "--laps", "1", "--workers", "1", "--out",
                 str(tmp_path / "o.json"), "--plot", str(tmp_path / "h.png"), "--json"])
    out, err = capsys.readouterr()
    assert code == 130, err
    doc = json.loads(out)
    assert doc["interrupted"] is True and [r["seed"] for r in doc["per_seed"]] == [0, 1]
    assert json.loads((tmp_path / "o.json").read_text()) == doc
    assert (tmp_path / "h.png").read_bytes()[:4] == b"\x89PNG"
    assert "kept the 2 of 4 tracks that had finished" in err


@pytest.mark.parametrize("argv, message", [
    (["--seeds", "5:5"], "argument --seeds: seeds A:B needs B > A, got '5:5'"),
    (["--lowest-speed", "8.3"], "argument --lowest-speed: expected a number in [0.05, 8.2] m/s"),
    (["--seeds", "5"], "argument --seeds: seeds must read A:B"),
    (["--laps", "0"], "argument --laps: expected an integer from 1 to 1000, got '0'"),
    (["--agent", "mpc"], "argument --agent: invalid choice: 'mpc'"),
    (["--policy", "p.zip"], "--policy is for the ppo agent only"),
    (["--plot", "h.jpg"], "--plot"),
    (["--resume"], "--resume continues the sweep saved in --results F.jsonl"),
    (["--workers", "0"], "argument --workers: expected an integer ≥ 1"),
])
def test_bad_input_is_refused_in_one_line_before_any_work(argv: list[str], message: str,
                                                          tmp_path: Path) -> None:
    run = tfalda("limits", *argv, "--out", "o.json", cwd=tmp_path, code=2)
    assert message in run.err.strip().splitlines()[-1], str(run)
    assert run.out == "" and not (tmp_path / "o.json").exists()


def test_existing_outputs_are_kept_without_force(tmp_path: Path) -> None:
    (tmp_path / "o.json").write_text("{}")
    run = tfalda("limits", "--seeds", "0:1", "--out", "o.json", "--plot", "h.png",
                 cwd=tmp_path, code=2)
    assert "o.json exists; add --force" in run.err, str(run)
    assert (tmp_path / "o.json").read_text() == "{}" and not (tmp_path / "h.png").exists()


def test_every_option_has_help_with_its_default() -> None:
    import argparse

    from tests.cli_helpers import leaf_commands

    for action in leaf_commands()[("limits",)]._actions:
        if isinstance(action, argparse._HelpAction):
            continue
        name = action.option_strings[-1]
        assert action.help and action.help != argparse.SUPPRESS, f"limits {name}: no help"
        if action.default not in (None, False):
            assert "default" in action.help, f"limits {name}: default not shown"


def test_a_raised_lowest_speed_starts_the_bisection_there(tmp_path: Path) -> None:
    """Seed 0: the PID leaves the road in slow drives (the LIS's fault counter runs out
    per frame) but passes from 1 m/s on; from --lowest-speed 1 it has a limit."""
    doc = tfalda("limits", "--seeds", "0:1", "--laps", "1", "--workers", "1",
                 "--lowest-speed", "1", "--json", cwd=tmp_path).json()
    assert doc["lowest_speed_m_s"] == 1.0
    (track,) = doc["per_seed"]
    assert track["drives"][0]["speed_m_s"] == 1.0
    assert track["limit_m_s"] is not None and track["limit_m_s"] >= 1.0
    assert limits.speed_grid(1.0)[:2] == [1.0, 1.1] and limits.speed_grid(1.0)[-1] == 8.3
