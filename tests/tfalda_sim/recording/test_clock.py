"""The recording clock: frames' own times kept, a restart (the next loop, the next
episode) one frame interval after the last frame, frames without a time spaced evenly."""

from __future__ import annotations

import itertools
import math

import pytest

from tfalda_sim.recording import RecordingClock


def test_restarts_continue_one_interval_after_the_last_frame() -> None:
    clock = RecordingClock(50.0)
    times = [clock.time(t) for t in (0.0, 0.02, 0.04, 0.0, 0.02, 0.01)]
    assert times == pytest.approx([0.0, 0.02, 0.04, 0.06, 0.08, 0.10])
    assert all(b > a for a, b in itertools.pairwise(times))


def test_frames_without_a_time_are_a_frame_interval_apart() -> None:
    clock = RecordingClock(25.0)
    assert [clock.time(math.nan) for _ in range(3)] == pytest.approx([0.0, 0.04, 0.08])
    assert clock.time(1.0) == pytest.approx(1.0)  # own times kept where there are some
