"""ROI placement: table 2.4, listing A.6 ``adjust_total``, the curve states, the border."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from tfalda_sim.perception import LaneSegment, RoiLayout, StateKind
from tfalda_sim.perception.params import INITIAL_ROIS, ROI_BORDER_PX
from tfalda_sim.perception.rois import (
    LeftCurveState,
    RightCurveState,
    Roi,
    clamp,
    classify,
    follow,
    initial_rois,
    row_geometry,
    windows,
)

W = 752
L = RoiLayout()  # the thesis layout (table 2.4, listing A.6)


def test_two_rows_are_table_2_4() -> None:
    assert windows(initial_rois(RoiLayout())) == list(INITIAL_ROIS)


@pytest.mark.parametrize("rows", [3, 4, 6])
def test_more_rows_split_the_same_band(rows: int) -> None:
    geo = row_geometry(RoiLayout(rows=rows))
    assert len(geo) == rows and geo[0][0] == 260 and geo[-1][0] + geo[-1][1] == 425
    for (y0, h0), (y1, _) in itertools.pairwise(geo):
        assert y0 + h0 + 5 == y1 and h0 >= 20
    for left, right in initial_rois(RoiLayout(rows=rows)):
        assert 0 < left.x and right.end < W and left.x < right.x


def test_follow_is_adjust_total() -> None:
    roi = Roi(80, 340, 180, 85)
    lane = LaneSegment(240.0, -80.0, 1.0, 340.0, 424.0)  # ends at x 240 (top) and 160 (bottom)
    nxt = follow(lane, roi, L)
    assert (nxt.x, nxt.width) == (160 - 50, 75 + 80)
    steep = LaneSegment(300.0, -400.0, 1.0, 340.0, 424.0)
    assert follow(steep, roi, L).width == 275  # clamped to the widest
    vertical = LaneSegment(300.0, 0.0, 1.0, 340.0, 424.0)
    assert follow(vertical, roi, L).width == 100  # and to the narrowest


@pytest.mark.parametrize("x", [-500.0, -10.0, 0.0, 700.0, 751.0, 5000.0])
def test_follow_keeps_the_roi_inside_the_image(x: float) -> None:
    for d in (-300.0, 0.0, 300.0):
        nxt = follow(LaneSegment(x, d, 1.0, 340.0, 424.0), Roi(80, 340, 180, 85), L)
        assert nxt.x >= ROI_BORDER_PX and nxt.end <= W - ROI_BORDER_PX
        assert 100 <= nxt.width <= 275


def test_left_curve_moves_the_left_roi_left_by_half_the_overlap() -> None:
    left, right = Roi(200, 260, 150, 75), Roi(300, 260, 200, 75)  # overlap 50, right.x < 325
    state = classify(left, right, L)
    assert state.kind is StateKind.LEFT_CURVE
    new_left, new_right = state.correct(left, right, L)
    assert (new_left.x, new_left.width) == (175, 125) and new_right == right


def test_right_curve_moves_the_right_roi_right_by_half_the_overlap() -> None:
    left, right = Roi(300, 260, 160, 75), Roi(400, 260, 200, 75)  # overlap 60, left ends 460
    state = classify(left, right, L)
    assert state.kind is StateKind.RIGHT_CURVE
    new_left, new_right = state.correct(left, right, L)
    assert new_left == left and (new_right.x, new_right.width) == (430, 170)


def test_no_overlap_is_straight() -> None:
    assert classify(Roi(195, 260, 150, 75), Roi(365, 260, 150, 75), L).kind is StateKind.STRAIGHT


def test_curve_corrections_at_the_image_border() -> None:
    left, right = Roi(1, 260, 150, 75), Roi(100, 260, 150, 75)
    new_left, _ = LeftCurveState().correct(left, right, L)
    assert new_left.x == ROI_BORDER_PX and new_left.width >= 100
    left, right = Roi(500, 260, 200, 75), Roi(600, 260, 151, 75)
    _, new_right = RightCurveState().correct(left, right, L)
    assert new_right.end <= W - ROI_BORDER_PX


def test_clamp_handles_any_roi() -> None:
    rng = np.random.default_rng(0)
    for _ in range(500):
        x, w = int(rng.integers(-2000, 2000)), int(rng.integers(-50, 2000))
        roi = clamp(Roi(x, 300, w, 50), L)
        assert ROI_BORDER_PX <= roi.x and roi.end <= W - ROI_BORDER_PX and roi.width >= 100
