"""The kinematic bicycle's servo and motor limits."""

from __future__ import annotations

import math

import pytest

from tfalda_sim.vehicle import CarParams, motor_step, servo_step, yaw_rate

CAR = CarParams()


def test_servo_moves_at_its_rate_and_stops_at_the_limit() -> None:
    dt = 0.005
    steer, t = 0.0, 0.0
    while steer < CAR.max_steer_rad:
        previous = steer
        steer = servo_step(steer, 1.0, dt, CAR)  # command beyond the range
        t += dt
        assert steer - previous <= CAR.max_steer_rate_rad_s * dt + 1e-12
        assert t < 1.0
    assert steer == pytest.approx(CAR.max_steer_rad)
    # Full lock to full lock takes 2 δmax / rate.
    assert t == pytest.approx(CAR.max_steer_rad / CAR.max_steer_rate_rad_s, abs=dt)
    assert servo_step(steer, steer - 1e-4, dt, CAR) == pytest.approx(steer - 1e-4)


def test_motor_accelerates_brakes_and_never_reverses() -> None:
    v = motor_step(1.0, 1.0, 0.1, CAR)
    assert v == pytest.approx(1.0 + 0.1 * CAR.max_accel_m_s2)
    assert motor_step(1.0, -1.0, 0.1, CAR) == pytest.approx(1.0 - 0.1 * CAR.max_brake_m_s2)
    assert motor_step(0.1, -1.0, 1.0, CAR) == 0.0
    assert motor_step(CAR.max_speed_m_s, 1.0, 1.0, CAR) == CAR.max_speed_m_s


def test_yaw_rate_is_that_of_the_bicycle() -> None:
    assert yaw_rate(2.0, 0.3, CAR) == pytest.approx(2.0 * math.tan(0.3) / 0.26)
    assert yaw_rate(2.0, 0.0, CAR) == 0.0


@pytest.mark.parametrize("bad", [{"wheelbase_m": 0.0}, {"max_speed_m_s": math.nan},
                                 {"rear_overhang_m": 0.5}, {"max_steer_rad": 1.6}])
def test_bad_car_parameters_are_refused(bad: dict) -> None:
    with pytest.raises(ValueError, match=next(iter(bad))):
        CarParams(**bad)
