"""The dynamic single-track model against closed forms: the kinematic limit at low
speed, the linear tyres' understeer gradient, the friction limit, stability for any
input; the servo's lag, dead band and rate limit."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tfalda_sim.dynamics import (
    GRAVITY_M_S2,
    STATE_SIZE,
    DynamicsParams,
    advance,
    cruise_accel,
    kinematic_state,
)
from tfalda_sim.vehicle import (
    MAX_STEER_RAD,
    MAX_STEER_RATE_RAD_S,
    REAL_SERVO,
    WHEELBASE_M,
    CarParams,
    ServoParams,
    servo_step,
    servo_target_step,
)

PARAMS = DynamicsParams()
P = PARAMS.vector(WHEELBASE_M)
CAR = CarParams()
DT = 0.005


def steady(speed_m_s: float, steer_rad: float, seconds: float = 6.0,
           params: np.ndarray = P) -> np.ndarray:
    """The state after ``seconds`` at a held wheel angle, cruise control holding the
    speed (the motor's lag included)."""
    state = kinematic_state(0.0, 0.0, 0.0, speed_m_s, 0.0, params)
    for _ in range(int(seconds / DT)):
        a = cruise_accel(state[3], speed_m_s, CAR.max_accel_m_s2, CAR.max_brake_m_s2)
        advance(state, steer_rad, a, DT, params, 1.0, CAR.max_speed_m_s)
    return state


def test_at_low_speed_the_yaw_rate_is_the_kinematic_models() -> None:
    for speed, steer in ((1.0, 0.1), (1.0, -0.2), (0.8, 0.3), (1.2, 0.05)):
        state = steady(speed, steer, seconds=3.0)
        kinematic = state[3] * math.tan(steer) / WHEELBASE_M
        assert state[5] == pytest.approx(kinematic, rel=0.02), (speed, steer)


def test_standing_start_is_the_kinematic_model() -> None:
    """From standstill with the wheels turned: no slip below the blend (the rear axle
    moves straight ahead), no NaN at zero speed."""
    state = kinematic_state(0.0, 0.0, 0.0, 0.0, 0.3, P)
    for _ in range(20):  # 0.1 s of full throttle: 0.4 m/s, below the blend
        advance(state, 0.3, CAR.max_accel_m_s2, DT, P, 1.0, CAR.max_speed_m_s)
        assert np.all(np.isfinite(state))
        lr = P[3]
        assert state[4] - lr * state[5] == pytest.approx(0.0, abs=1e-9)
    assert 0.15 < state[3] < 0.5  # the motor lags


def test_understeer_gradient_on_a_steady_circle_is_the_linear_tyres() -> None:
    """δ = L / R + K a_y with K = (1 / C_Sf − 1 / C_Sr) / (μ g): measured on steady
    circles in the tyres' linear range, within 5 %."""
    want = PARAMS.understeer_gradient_rad_s2_m()
    assert want > 0  # the F1TENTH tyres understeer
    for speed, steer in ((3.0, 0.03), (4.0, 0.02), (2.0, 0.05)):
        state = steady(speed, steer)
        v = math.hypot(state[3], state[4])
        radius = v / state[5]
        lateral = v * state[5]
        measured = (steer - WHEELBASE_M / radius) / lateral
        assert measured == pytest.approx(want, rel=0.05), (speed, steer)


def test_above_the_friction_limit_the_car_cannot_hold_the_radius() -> None:
    """A radius R the kinematic car holds at any speed: above √(μ g R) the dynamic car's
    lateral acceleration stays at μ g and it runs wide, on a wet floor sooner."""
    radius = 1.0
    steer = math.atan(WHEELBASE_M / radius)
    limit = math.sqrt(PARAMS.mu * GRAVITY_M_S2 * radius)
    below = steady(0.8 * limit, steer)
    # Held but for the understeer (δ = L / R + K a_y, and more as the tyres curve).
    assert 0.8 * limit / below[5] == pytest.approx(radius, rel=0.2)
    for speed in (1.2 * limit, 1.6 * limit):
        state = steady(speed, steer)
        v = math.hypot(state[3], state[4])
        assert v * abs(state[5]) <= 1.02 * PARAMS.mu * GRAVITY_M_S2
        assert v / state[5] > 1.3 * radius  # runs wide
    wet = DynamicsParams(mu=0.3).vector(WHEELBASE_M)
    state = steady(0.8 * limit, steer, params=wet)
    assert math.hypot(state[3], state[4]) / state[5] > 2.0 * radius


def test_mu_scale_is_a_slippery_patch() -> None:
    dry = kinematic_state(0.0, 0.0, 0.0, 3.0, 0.0, P)
    wet = dry.copy()
    for _ in range(200):
        advance(dry, 0.3, 0.0, DT, P, 1.0, CAR.max_speed_m_s)
        advance(wet, 0.3, 0.0, DT, P, 0.25, CAR.max_speed_m_s)
    assert abs(wet[5]) < 0.6 * abs(dry[5])


@settings(max_examples=60, deadline=None)
@given(speed=st.floats(0.0, CAR.max_speed_m_s),
       steers=st.lists(st.floats(-MAX_STEER_RAD, MAX_STEER_RAD), min_size=1, max_size=60),
       accels=st.lists(st.floats(-CAR.max_brake_m_s2, CAR.max_accel_m_s2), min_size=1,
                       max_size=60),
       mu_scale=st.floats(0.05, 1.0))
def test_no_nan_or_explosion_for_any_input(speed: float, steers: list[float],
                                           accels: list[float], mu_scale: float) -> None:
    state = kinematic_state(1.0, -2.0, 0.5, speed, steers[0], P)
    for k, steer in enumerate(steers):
        advance(state, steer, accels[k % len(accels)], 0.02, P, mu_scale,
                CAR.max_speed_m_s)
        assert np.all(np.isfinite(state)) and state.shape == (STATE_SIZE,)
        assert 0.0 <= state[3] <= CAR.max_speed_m_s
        assert abs(state[4]) < 2 * CAR.max_speed_m_s and abs(state[5]) < 60.0


def test_params_refuse_impossible_values() -> None:
    with pytest.raises(ValueError, match="mu must be finite and > 0"):
        DynamicsParams(mu=0.0)
    with pytest.raises(ValueError, match="mass_kg"):
        DynamicsParams(mass_kg=math.nan)
    with pytest.raises(ValueError, match="shorter than the wheelbase"):
        DynamicsParams(cog_to_front_m=0.3).vector(WHEELBASE_M)
    with pytest.raises(ValueError, match="shape_c"):
        DynamicsParams(shape_c=2.5)
    with pytest.raises(ValueError, match=r"ServoParams\.lag_s"):
        ServoParams(lag_s=-0.01)


def test_the_servo_reaches_a_step_target_no_faster_than_its_rate_limit() -> None:
    """With lag and dead band (the real servo) and without: the wheel never moves faster
    than the rate limit; the lag only slows it; the dead band stops it short."""
    dt = 0.001
    for servo in (ServoParams(), REAL_SERVO):
        steer = target = 0.0
        times = []
        for k in range(1, 400):
            target = servo_target_step(target, MAX_STEER_RAD, dt, servo.lag_s)
            new = servo_step(steer, target, dt, CAR, servo.dead_band_rad)
            assert abs(new - steer) <= MAX_STEER_RATE_RAD_S * dt + 1e-15
            steer = new
            if steer >= MAX_STEER_RAD - servo.dead_band_rad - 1e-12 and not times:
                times.append(k * dt)
        assert times and times[0] >= (MAX_STEER_RAD - servo.dead_band_rad
                                      ) / MAX_STEER_RATE_RAD_S - 1e-9
        assert MAX_STEER_RAD - steer <= servo.dead_band_rad + 1e-12
    # The lag: after one time constant the target has covered 1 − 1/e of a step.
    target = servo_target_step(0.0, 1.0, REAL_SERVO.lag_s, REAL_SERVO.lag_s)
    assert target == pytest.approx(1.0 - math.exp(-1.0))
    # Without lag and dead band: today's servo exactly.
    assert servo_step(0.1, 0.3, 0.005, CAR) == servo_step(0.1, 0.3, 0.005, CAR, 0.0)
    assert servo_target_step(0.2, 0.3, 0.005, 0.0) == 0.3
