"""The metrics can fail: truth lanes score 1, shifted lanes score 0, missing lanes are
false negatives, a lane on the wrong marking is a false positive."""

from __future__ import annotations

import numpy as np
import pytest

from tfalda_sim.evaluation import score_frame, truth_distance
from tfalda_sim.evaluation.metrics import (
    TUSIMPLE_THRESHOLD_PX,
    boundary_x_at_rows,
    lane_hit_rates,
    lane_x_at_rows,
    roi_truth_x,
    tusimple_accuracy,
)
from tfalda_sim.perception.params import INITIAL_ROIS
from tfalda_sim.rendering import FrameTruth, Renderer, frame_truth
from tfalda_sim.tracks import load_named


@pytest.fixture(scope="module")
def straight_truth() -> FrameTruth:
    track = load_named("straight")
    x, y, h = track.pose(2.0, -0.2)
    return frame_truth(track, Renderer().camera, (float(x), float(y), float(h)))


def rois() -> np.ndarray:
    return np.array(INITIAL_ROIS, dtype=np.int32)


def truth_lanes(truth: FrameTruth, roi_boxes: np.ndarray) -> np.ndarray:
    """Each ROI's lane laid exactly on the ego boundary it should find."""
    lanes = []
    for k, roi in enumerate(roi_boxes):
        rows, tx = roi_truth_x(truth, roi, k % 2)
        assert np.all(np.isfinite(tx)), "the straight's boundaries cross every ROI row"
        lanes.append([tx[0], rows[0], tx[-1], rows[-1]])
    return np.array(lanes)


def test_truth_lanes_score_one(straight_truth: FrameTruth) -> None:
    score = score_frame(truth_lanes(straight_truth, rois()), rois(), straight_truth)
    assert np.all(score.hit_rates == 1.0)
    assert score.confidence == 1.0
    assert np.all(score.accuracy == 1.0)
    assert score.truth_present.all()
    assert not score.false_positive.any() and not score.false_negative.any()


@pytest.mark.parametrize("shift_px", [30.0, -30.0])
def test_lanes_shifted_by_30_px_score_near_zero(straight_truth: FrameTruth,
                                                shift_px: float) -> None:
    lanes = truth_lanes(straight_truth, rois())
    inward = np.array([1.0, -1.0, 1.0, -1.0])  # left ROIs right, right ROIs left: no line
    lanes[:, [0, 2]] += (shift_px * inward)[:, None]
    score = score_frame(lanes, rois(), straight_truth)
    assert score.hit_rates.max() < 0.1
    assert np.all(score.accuracy < 0.1)
    assert score.false_positive.all() and score.false_negative.all()


def test_a_missing_lane_is_a_false_negative(straight_truth: FrameTruth) -> None:
    lanes = truth_lanes(straight_truth, rois())
    lanes[2] = np.nan
    score = score_frame(lanes, rois(), straight_truth)
    assert score.false_negative.tolist() == [False, False, True, False]
    assert not score.false_positive.any()  # nothing was given there
    assert score.hit_rates[2] == 0.0
    assert score.confidence == pytest.approx(0.75)


def test_a_lane_on_the_wrong_marking_hits_but_is_a_false_positive(
        straight_truth: FrameTruth) -> None:
    # the upper-left lane jumps onto the opposite lane's outer line (thesis 4.2.2): the
    # black-box test still counts a hit, the ego-lane accuracy does not
    x0 = boundary_x_at_rows(_left_line(straight_truth), np.array([260.0, 333.0]))
    assert np.all(np.isfinite(x0))
    lanes = truth_lanes(straight_truth, rois())
    lanes[0] = [x0[0], 260.0, x0[1], 333.0]
    box = rois()
    box[0] = [int(x0.min()) - 20, 260, 150, 74]
    score = score_frame(lanes, box, straight_truth)
    assert score.hit_rates[0] > 0.95
    assert score.false_positive[0] and score.false_negative[0]


def _left_line(truth: FrameTruth) -> np.ndarray:
    """Pixels of the opposite lane's outer line, as a polyline from the car outwards."""
    from tfalda_sim.tracks import Marking

    ys, xs = np.nonzero(truth.labels == int(Marking.LEFT_LINE))
    rows = np.unique(ys)
    pts = np.array([[xs[ys == r].mean(), r] for r in rows[::-1]])
    return pts


def test_hit_rates_count_pixels_outside_the_image_as_misses() -> None:
    distance = np.zeros((10, 10), np.float32)  # every pixel on a marking
    rates = lane_hit_rates(np.array([[5.0, 0.0, 5.0, 9.0], [5.0, 0.0, 5.0, 19.0]]), distance)
    assert rates[0] == 1.0
    assert rates[1] == pytest.approx(0.5)


def test_truth_distance_without_markings_is_infinite() -> None:
    assert np.all(np.isinf(truth_distance(np.zeros((4, 5), np.uint8))))


def test_boundary_crossings_take_the_one_nearest_the_car() -> None:
    # a line from the bottom up to row 10, bending back down to row 20 further right
    line = np.array([[0.0, 40.0], [10.0, 10.0], [40.0, 20.0]])
    x = boundary_x_at_rows(line, np.array([40.0, 25.0, 15.0, 5.0]))
    assert x[0] == pytest.approx(0.0)
    assert x[1] == pytest.approx(5.0)
    assert x[2] == pytest.approx(10 * 25 / 30)  # first segment, not the one bending back
    assert np.isnan(x[3])


def test_lane_x_is_nan_outside_the_lane_and_for_flat_or_missing_lanes() -> None:
    rows = np.array([9.0, 10.0, 15.0, 20.0, 21.0])
    x = lane_x_at_rows(np.array([0.0, 10.0, 10.0, 20.0]), rows)
    assert np.isnan(x[0]) and np.isnan(x[-1])
    assert x[1:4] == pytest.approx([0.0, 5.0, 10.0])
    assert np.all(np.isnan(lane_x_at_rows(np.array([0.0, 5.0, 9.0, 5.0]), rows)))
    assert np.all(np.isnan(lane_x_at_rows(np.array([np.nan, 5.0, 9.0, 8.0]), rows)))


def test_tusimple_threshold_widens_with_the_truth_angle() -> None:
    rows = np.arange(100.0)
    vertical = np.full(100, 50.0)
    diagonal = 50.0 + rows  # 45°: threshold × √2
    off = TUSIMPLE_THRESHOLD_PX * 1.2
    assert tusimple_accuracy(vertical + off, vertical, rows) == 0.0
    assert tusimple_accuracy(diagonal + off, diagonal, rows) == 1.0
    assert np.isnan(tusimple_accuracy(vertical, np.full(100, np.nan), rows))


def test_score_frame_rejects_mismatched_shapes(straight_truth: FrameTruth) -> None:
    with pytest.raises(ValueError, match=r"\(n, 4\)"):
        score_frame(np.zeros((4, 4)), np.zeros((3, 4)), straight_truth)
