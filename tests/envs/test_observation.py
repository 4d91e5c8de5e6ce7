"""The "lanes" vector: layout, names, values."""

from __future__ import annotations

import numpy as np

from tfalda_sim.envs.observation import (
    STATES,
    lane_vector,
    lane_vector_bounds,
    lane_vector_names,
    lane_vector_rows,
    read_lane_vector,
)
from tfalda_sim.perception import LaneObservation, StateKind


def fake_observation() -> LaneObservation:
    return LaneObservation(
        frame=3, rois=np.array([[195, 260, 150, 75], [365, 260, 150, 75],
                                [80, 340, 180, 85], [429, 340, 180, 85]], np.int32),
        lanes=np.array([[300.0, 260.0, 250.0, 334.0], [400.0, 260.0, 470.0, 334.0],
                        [240.0, 340.0, 180.0, 424.0], [np.nan, np.nan, np.nan, np.nan]]),
        d=np.zeros(4), intensity=np.zeros(4), lam=np.zeros(4),
        replaced=np.array([False, True, False, False]),
        corrected=np.array([False, False, True, False]),
        widths=np.array([[110.0, 200.0], [240.0, 300.0]]), fault_count=4, roi_reset=False,
        state=StateKind.LEFT_CURVE, first_frame=False, next_rois=np.zeros((4, 4), np.int32))


def test_names_and_bounds_have_one_entry_per_index() -> None:
    for rows in (2, 3):
        names = lane_vector_names(rows)
        low, high = lane_vector_bounds(rows)
        assert len(names) == len(set(names)) == len(low) == len(high)
        assert np.all(low < high)
    assert len(lane_vector_names(2)) == 42


def test_values_sit_at_their_documented_indices() -> None:
    names = lane_vector_names(2)
    v = lane_vector(fake_observation(), image_width=752, image_height=480, fault_limit=10,
                    speed_ratio=0.25, steer_ratio=-0.5)
    at = dict(zip(names, v.tolist(), strict=True))
    assert v.dtype == np.float32
    assert at["r0_left_x_top"] == np.float32(300 / 752)
    assert at["r0_left_y_bottom"] == np.float32(334 / 480)
    assert at["r1_right_x_top"] == -1.0  # missing lane
    assert at["r0_right_roi_centre_x"] == np.float32(440 / 752)
    assert (at["r0_right_replaced"], at["r0_left_replaced"]) == (1.0, 0.0)
    assert at["r1_left_corrected"] == 1.0
    assert at["r1_width_bottom"] == np.float32(300 / 752)
    assert at["fault_count"] == np.float32(4 / 11)
    assert [at[f"state_{s.name.lower()}"] for s in STATES] == [0, 1, 0, 0, 0]
    assert (at["speed"], at["steer"]) == (0.25, -0.5)
    low, high = lane_vector_bounds(2)
    assert np.all((low <= v) & (v <= high))


def test_read_lane_vector_inverts_lane_vector() -> None:
    obs = fake_observation()
    v = lane_vector(obs, image_width=752, image_height=480, fault_limit=10,
                    speed_ratio=0.25, steer_ratio=-0.5)
    back = read_lane_vector(v, image_width=752, image_height=480)
    assert back.rows == lane_vector_rows(len(v)) == 2
    np.testing.assert_allclose(back.lanes[:3], obs.lanes[:3], atol=1e-3)
    assert np.all(np.isnan(back.lanes[3]))  # the missing lane
    np.testing.assert_allclose(back.roi_centre_x_px, obs.rois[:, 0] + obs.rois[:, 2] / 2,
                               atol=1e-3)
    assert back.replaced.tolist() == obs.replaced.tolist()
    assert back.corrected.tolist() == obs.corrected.tolist()
    np.testing.assert_allclose(back.widths_px, obs.widths, atol=1e-3)
    assert back.fault_share == np.float32(4 / 11)
    assert (back.roi_reset, back.first_frame, back.state) == (False, False,
                                                              StateKind.LEFT_CURVE)
    assert (back.speed_ratio, back.steer_ratio) == (0.25, -0.5)
    assert read_lane_vector({"lanes": v, "image": None}, image_width=752,
                            image_height=480).state is StateKind.LEFT_CURVE
    try:
        read_lane_vector(v[:-1], image_width=752, image_height=480)
    except ValueError as exc:
        assert "41 entries" in str(exc)
    else:
        raise AssertionError("a vector of the wrong size was read")
