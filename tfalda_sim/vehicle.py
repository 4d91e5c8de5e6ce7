"""The car: a kinematic bicycle model of a 1:10 Carolo-Cup car with a steering servo.

The reference point is the rear axle centre (the car frame of ``tfalda_sim.camera``:
x forward, y left). At speed ``v`` and front-wheel angle ``δ`` the car turns about a
centre on the rear axle's line: ``ẋ = v cos ψ``, ``ẏ = v sin ψ``, ``ψ̇ = v tan δ / L``.
The servo moves ``δ`` towards its command at a limited rate; the motor changes ``v`` at
limited acceleration (or holds a set speed). Nothing here knows about tracks or pymunk
(``tfalda_sim.world`` moves the car's body with these rates).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

WHEELBASE_M: float = 0.26
"""Distance rear axle → front axle of a 1:10 car [m]."""

MAX_SPEED_M_S: float = 8.3
"""Design top speed of the thesis' car [m/s] (thesis 1.1, REFERENCE.md)."""

MIN_CRUISE_SPEED_M_S: float = 0.05
"""Slowest cruise speed accepted [m/s] (ours: 5 cm/s, about the crawl of a 1:10 car; a
lap of the 53 m longest generated track then takes 53,000 frames — anything slower is no
drive, and a speed near 0 turns per-metre quantities into overflows)."""

MAX_STEER_RAD: float = 0.44
"""Largest front-wheel angle [rad] (≈ 25°, a typical 1:10 chassis: turning radius 0.55 m
at the rear axle, tighter than any curve the rules allow)."""

MAX_STEER_RATE_RAD_S: float = 8.7
"""Steering servo speed [rad/s] (a standard servo's 0.12 s per 60°)."""


@dataclass(frozen=True)
class CarParams:
    """Geometry and limits of the car (units in brackets)."""

    wheelbase_m: float = WHEELBASE_M
    """Rear axle → front axle [m]."""
    length_m: float = 0.43
    """Body length, bumper to bumper [m]."""
    width_m: float = 0.19
    """Body width [m]."""
    rear_overhang_m: float = 0.085
    """Body behind the rear axle [m]."""
    max_steer_rad: float = MAX_STEER_RAD
    """Largest front-wheel angle either way [rad]."""
    max_steer_rate_rad_s: float = MAX_STEER_RATE_RAD_S
    """Servo speed [rad/s]."""
    max_speed_m_s: float = MAX_SPEED_M_S
    """Top speed [m/s]; the car does not reverse."""
    max_accel_m_s2: float = 4.0
    """Largest acceleration of the motor [m/s²] (throttle +1)."""
    max_brake_m_s2: float = 6.0
    """Largest deceleration [m/s²] (throttle −1)."""

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"CarParams.{f.name} must be finite and > 0, got {value!r}")
        if self.rear_overhang_m >= self.length_m:
            raise ValueError("CarParams.rear_overhang_m must be shorter than length_m")
        if self.max_steer_rad >= 0.5 * math.pi:
            raise ValueError("CarParams.max_steer_rad must be < π/2")

    def body_outline(self) -> list[tuple[float, float]]:
        """The body's corners in the car frame [m] (counter-clockwise)."""
        back, front = -self.rear_overhang_m, self.length_m - self.rear_overhang_m
        half = 0.5 * self.width_m
        return [(back, -half), (front, -half), (front, half), (back, half)]


SERVO_PWM_PERIOD_S: float = 0.020
"""Period of a hobby servo's control pulse [s]: 50 Hz, one new target per 20 ms (the RC
servo PWM convention: a 1–2 ms pulse repeated every 20 ms)."""

SERVO_DEAD_BAND_US: float = 5.0
"""Dead band of a standard analog servo [µs of pulse width] (the MG995 datasheet's "dead
band width 5 µs"): a command nearer the current position than this moves nothing."""

SERVO_HALF_RANGE_US: float = 500.0
"""Pulse width from centre to a full deflection [µs] (1500 ± 500 µs)."""


@dataclass(frozen=True)
class ServoParams:
    """The steering servo beyond its rate limit (``CarParams.max_steer_rate_rad_s``):
    a first-order lag of its target behind the command and a dead band. The default is
    an ideal servo (no lag, no dead band); ``REAL_SERVO`` is a hobby servo's."""

    lag_s: float = 0.0
    """Time constant of the target following the command [s] (0: none)."""
    dead_band_rad: float = 0.0
    """Wheel-angle error the servo does not correct [rad] (0: none)."""

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not (
                    math.isfinite(value) and value >= 0):
                raise ValueError(f"ServoParams.{f.name} must be finite and ≥ 0, got "
                                 f"{value!r}")


REAL_SERVO = ServoParams(
    lag_s=SERVO_PWM_PERIOD_S,
    dead_band_rad=MAX_STEER_RAD * SERVO_DEAD_BAND_US / SERVO_HALF_RANGE_US)
"""A hobby servo: it takes a new target once per pulse period (modelled as a first-order
lag of that time constant) and ignores errors within its dead band (5 µs of a 500 µs half
range, scaled to the wheel's full angle)."""


def servo_step(steer_rad: float, command_rad: float, dt_s: float, car: CarParams,
               dead_band_rad: float = 0.0) -> float:
    """The wheel angle [rad] after ``dt_s`` of the servo moving from ``steer_rad`` towards
    ``command_rad`` (clipped to the steering range) at its limited rate; within
    ``dead_band_rad`` of the target it does not move."""
    target = min(max(command_rad, -car.max_steer_rad), car.max_steer_rad)
    if dead_band_rad > 0.0 and abs(target - steer_rad) <= dead_band_rad:
        return steer_rad
    step = car.max_steer_rate_rad_s * dt_s
    return steer_rad + min(max(target - steer_rad, -step), step)


def servo_target_step(target_rad: float, command_rad: float, dt_s: float,
                      lag_s: float) -> float:
    """The servo's target [rad] after ``dt_s`` of following ``command_rad`` with a
    first-order lag of time constant ``lag_s`` (exact for a command held over the step;
    0: the command at once)."""
    if lag_s <= 0.0:
        return command_rad
    return command_rad + (target_rad - command_rad) * math.exp(-dt_s / lag_s)


def motor_step(speed_m_s: float, throttle: float, dt_s: float, car: CarParams) -> float:
    """The speed [m/s] after ``dt_s`` at ``throttle`` ∈ [−1, 1] (+1 full acceleration,
    −1 full braking), kept within [0, top speed]."""
    rate = throttle * (car.max_accel_m_s2 if throttle >= 0 else car.max_brake_m_s2)
    return min(max(speed_m_s + rate * dt_s, 0.0), car.max_speed_m_s)


def yaw_rate(speed_m_s: float, steer_rad: float, car: CarParams) -> float:
    """ψ̇ = v tan δ / L [rad/s]."""
    return speed_m_s * math.tan(steer_rad) / car.wheelbase_m
