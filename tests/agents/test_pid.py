"""The PID lane keeper: lane geometry from the lanes alone, and laps of a named track."""

from __future__ import annotations

import numpy as np
import pytest

from tfalda_sim.agents.drive import drive, make_agent
from tfalda_sim.agents.pid import LanePid
from tfalda_sim.envs import TfaldaTrackEnv
from tfalda_sim.envs.observation import lane_vector_rows
from tfalda_sim.tracks import load_named


def test_lane_geometry_from_the_lanes_matches_the_truth() -> None:
    env = TfaldaTrackEnv(track="oval")
    pid = LanePid()
    # Centred on the straight, then 8 cm to the left, then turned by 0.05 rad.
    for lateral, heading, want_y in ((-0.2, 0.0, 0.0), (-0.12, 0.0, -0.08)):
        obs, _ = env.reset(seed=0, options={"start": (0.5, lateral, heading)})
        for _ in range(3):
            obs, *_ = env.step(np.zeros(1, np.float32))
        centres, dirs = pid.lane_geometry(obs)
        assert np.all(np.abs(centres[:, 1] - want_y) < 0.03), centres
        assert np.all(np.abs(dirs[:, 1]) < 0.05)
        assert 0.3 < centres[-1, 0] < centres[0, 0] < 1.5  # lower row nearer than upper


def test_pid_steers_back_towards_the_lane_centre() -> None:
    env = TfaldaTrackEnv(track="oval")
    for lateral, sign in ((-0.12, -1.0), (-0.28, 1.0)):  # left of centre → steer right
        pid = LanePid()
        obs, _ = env.reset(seed=0, options={"start": (0.5, lateral, 0.0)})
        assert np.sign(pid.act(obs)[0]) == sign


def test_missing_lanes_are_not_taken_for_pixels() -> None:
    env = TfaldaTrackEnv(track="oval")
    pid = LanePid()
    obs, _ = env.reset(seed=0, options={"start": (0.5, -0.2, 0.0)})
    for _ in range(3):
        obs, *_ = env.step(np.zeros(1, np.float32))
    full, _ = pid.lane_geometry(obs)
    rows = lane_vector_rows(len(obs))
    # The lower row's left lane missing (−1, as the observation encodes it): the centre
    # comes from the right line, half a lane width to its left.
    one = obs.copy()
    lower_left = 4 * 2 * (rows - 1)
    one[lower_left:lower_left + 4] = -1.0
    centres, dirs = pid.lane_geometry(one)
    assert np.all(np.isfinite(centres)) and np.all(np.isfinite(dirs))
    assert np.abs(centres[-1] - full[-1]).max() < 0.03
    # Both lanes of the row missing: the row is unknown, not a guess.
    both = one.copy()
    both[lower_left + 4:lower_left + 8] = -1.0
    centres, _ = pid.lane_geometry(both)
    assert np.all(np.isnan(centres[-1])) and np.all(np.isfinite(centres[0]))


def test_pid_laps_a_named_track_from_the_camera_alone() -> None:
    result = drive(make_agent("pid"), load_named("oval"), laps=1, speed_m_s=1.5)
    assert result.laps_completed == 1 and result.departures == 0
    # On the lane centre in the curves too (R = 2 m): steering the lookahead point of the
    # lane itself instead of its tangent held the car 12 cm off centre there.
    assert result.mean_abs_cross_track_m < 0.03
    assert result.max_abs_cross_track_m < 0.04
    # The right lane of an anticlockwise loop is longer than the centre line by the lane
    # offset times the total turn (2π).
    track = load_named("oval")
    lane_length_m = track.length_m + 0.5 * track.lane_width_m * 2.0 * np.pi
    assert result.lap_times_s[0] == pytest.approx(lane_length_m / 1.5, rel=0.01)


def test_a_departure_is_counted_and_the_car_put_back() -> None:
    class Hard:
        """Full left lock: leaves the road at once."""

        def reset(self) -> None:
            pass

        def act(self, obs: np.ndarray) -> np.ndarray:
            return np.ones(1, np.float32)

    result = drive(Hard(), load_named("oval"), laps=1, max_steps=300)
    assert result.departures >= 2 and result.laps_completed == 0 and result.ended == "steps"
    ended = drive(Hard(), load_named("oval"), laps=1, recover=False)
    assert ended.departures == 1 and ended.ended == "departure"
