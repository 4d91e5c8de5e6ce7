"""The Hough-vs-TFALDA comparison: one line metric for both, the runner, the CLI."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tfalda_sim.cli import main
from tfalda_sim.evaluation.baseline import (
    HOUGH_SIMULATOR,
    TFALDA_LIS,
    Tally,
    compare_scenario,
    markdown_table,
    score_lines,
)
from tfalda_sim.evaluation.scenarios import generated_scenario
from tfalda_sim.rendering import Renderer, frame_truth
from tfalda_sim.tracks import load_named


@pytest.fixture(scope="module")
def straight_truth():
    track = load_named("straight")
    renderer = Renderer()
    x, y, h = track.pose(1.0, -0.5 * track.lane_width_m)
    return frame_truth(track, renderer.camera, (float(x), float(y), float(h)),
                       bonnet=renderer.bonnet)


def _along(boundary: np.ndarray, y0: float, y1: float) -> np.ndarray:
    """A segment on the boundary polyline between rows y0 and y1."""
    from tfalda_sim.evaluation.metrics import boundary_x_at_rows

    x0, x1 = boundary_x_at_rows(boundary, np.array([y0, y1]))
    return np.array([x0, y0, x1, y1])


def test_lines_on_the_ego_boundaries_are_hits_and_found(straight_truth) -> None:
    left = _along(straight_truth.left_boundary_px, 300, 420)
    right = _along(straight_truth.right_boundary_px, 300, 420)
    score = score_lines(np.stack([left, right]), straight_truth)
    assert score.hit_rates.min() > 0.9 and not score.false_positive.any()
    assert score.ego_visible.all() and score.ego_found.all()
    assert score.confidence > 0.9


def test_a_line_off_the_markings_is_a_false_positive_and_finds_nothing(straight_truth) -> None:
    left = _along(straight_truth.left_boundary_px, 300, 420)
    right = _along(straight_truth.right_boundary_px, 300, 420)
    middle = 0.5 * (left + right)  # the middle of the lane: no marking there
    score = score_lines(middle[None], straight_truth)
    assert score.false_positive.all() and score.hit_rates[0] < 0.2
    assert score.ego_visible.all() and not score.ego_found.any()
    # Rows with a non-finite value are no lines at all.
    empty = score_lines(np.full((4, 4), np.nan), straight_truth)
    assert len(empty.hit_rates) == 0 and empty.confidence == 0.0


def test_a_short_line_does_not_count_as_finding_a_boundary(straight_truth) -> None:
    stub = _along(straight_truth.right_boundary_px, 400, 404)  # 5 rows
    score = score_lines(stub[None], straight_truth)
    assert score.hit_rates[0] > 0.9 and not score.ego_found[1]


def test_tallies_add_up_and_summarise(straight_truth) -> None:
    right = _along(straight_truth.right_boundary_px, 300, 420)
    a, b = Tally(), Tally()
    a.add(score_lines(right[None], straight_truth), 0.001)
    b.add(score_lines(np.zeros((0, 4)), straight_truth), 0.003)
    s = (a + b).summary()
    assert s["frames"] == 2 and s["frames_without_line"] == 1
    assert s["lines_per_frame"] == 0.5 and s["ego_right_found"] == 0.5
    assert s["ego_left_found"] == 0.0
    assert s["ms_per_frame_median"] == pytest.approx(2.0, abs=0.01)  # binned to 0.01 ms
    assert s["hit_rate"] == pytest.approx(0.5 * score_lines(right[None], straight_truth)
                                          .confidence)


def test_every_detector_scores_the_same_frames() -> None:
    tallies = compare_scenario(generated_scenario(10000, max_frames=12))
    assert {t.frames for t in tallies.values()} == {12}
    assert all(len(t.times) == 12 and t.times.quantile(0.0) > 0 for t in tallies.values())
    for label in (TFALDA_LIS, HOUGH_SIMULATOR):
        s = tallies[label].summary()
        assert s["ego_right_found"] >= 0.8 and s["hit_rate"] > 0.8, (label, s)


def test_compare_cli_writes_json_markdown_and_plot(tmp_path: Path, capsys) -> None:
    args = ["compare", "--no-thesis", "--seeds", "10001:10002", "--max-frames", "6",
            "--workers", "1", "--out", str(tmp_path), "--json"]
    assert main(args) == 0
    out = json.loads(capsys.readouterr().out)
    runs = out["groups"]["generated"]
    assert set(runs) >= {TFALDA_LIS, HOUGH_SIMULATOR} and runs[TFALDA_LIS]["frames"] == 6
    saved = json.loads((tmp_path / "compare.json").read_text())
    assert saved["groups"] == out["groups"]
    assert (tmp_path / "compare.md").read_text() == markdown_table(saved)
    assert (tmp_path / "compare.png").stat().st_size > 1000
    # An existing report is kept unless --force.
    assert main(args) == 2
    assert "--force" in capsys.readouterr().err


@pytest.mark.parametrize("args, message", [
    (["--no-thesis", "--no-generated"], "nothing to compare"),
])
def test_compare_cli_refuses_an_empty_run(args: list[str], message: str, capsys) -> None:
    assert main(["compare", *args]) == 2
    assert message in capsys.readouterr().err


def test_compare_cli_refuses_an_unknown_scenario(capsys) -> None:
    assert main(["compare", "--thesis", "straight,bend"]) == 2
    assert "straight, curve and/or track" in capsys.readouterr().err


@pytest.mark.parametrize("args", [["--thesis", "straight", "--no-thesis"],
                                  ["--seeds", "1:3", "--no-generated"]])
def test_compare_refuses_contradictory_flags(args: list[str], capsys) -> None:
    """The issue's reproduction: --thesis straight --no-thesis ran the generated tracks."""
    assert main(["compare", *args]) == 2
    assert "not allowed with argument" in capsys.readouterr().err
