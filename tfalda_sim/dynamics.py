"""The car that can slide: a dynamic single-track (bicycle) model of a 1:10 car with
saturating tyre forces, a motor with first-order lag, rolling resistance and a blend to
the kinematic model at walking pace.

State at the centre of gravity (CoG) in the car frame (x forward, y left): longitudinal
speed ``vx``, lateral speed ``vy``, yaw rate ``r``; with the motor's delivered
acceleration ``a``. With ``lf``/``lr`` the CoG's distances to the front/rear axle,
``L = lf + lr``, front-wheel angle ``δ``:

- slip angles ``α_f = δ − atan2(vy + lf r, vx)``, ``α_r = −atan2(vy − lr r, vx)``;
- static axle loads ``F_zf = m g lr / L``, ``F_zr = m g lf / L``;
- lateral tyre forces from Pacejka's magic formula without curvature,
  ``F_y = μ F_z sin(C atan(B α))``, with ``B C = C_S`` so that the small-slip slope is
  ``μ C_S F_z`` — the linear tyre of the F1TENTH gym's single-track model (CommonRoad's
  vehicle models), saturating at the friction limit ``μ F_z`` instead of growing without
  bound;
- ``m (v̇x − vy r) = m a − F_yf sin δ − F_roll``, ``m (v̇y + vx r) = F_yr + F_yf cos δ``,
  ``I_z ṙ = lf F_yf cos δ − lr F_yr``; the motor ``ȧ = (a_cmd − a) / τ``, its force
  limited by the rear tyre's grip.

Below ``BLEND_LOW_M_S`` the state is the kinematic model's (``vy``, ``r`` of a car rolling
without slip at ``δ``), above ``BLEND_HIGH_M_S`` the dynamic model's, in between a linear
mix: the tyre model's slip angles are singular at standstill, so a standing start goes
through the kinematic model (as the F1TENTH gym switches at low speed).

The integration is classic Runge–Kutta (RK4) in fixed substeps of at most
``MAX_SUBSTEP_S`` inside one numba call, beside pymunk: pymunk moves the kinematic body
with the mean velocity of the substeps (``tfalda_sim.world``), as it does for the
kinematic car. A pymunk dynamic body would integrate the tyre forces with its first-order
(semi-implicit Euler) step, whose stability bound at the tyres' stiffness,
``(C_αf + C_αr) / (m vx)`` ≈ 100 s⁻¹ at 1 m/s, is uncomfortably near a 5 ms step;
RK4's region is larger and it is 4th-order accurate for the closed-form tests.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np
from numba import njit

from .vehicle import WHEELBASE_M

GRAVITY_M_S2: float = 9.81
"""Standard gravity [m/s²]."""

# The F1TENTH gym's single-track parameters (f1tenth_gym, ``F110Env`` default ``params``:
# mu, C_Sf, C_Sr, lf, lr, h, m, I), measured on the F1TENTH 1:10 car (Traxxas Slash 4x4
# chassis, wheelbase 0.3302 m). The only published full set for a 1:10 car; a Carolo-Cup
# car is the same scale and class of chassis, so its tyres and mass are taken as they are,
# the geometry scaled to our wheelbase.
F1TENTH_MU: float = 1.0489
"""Tyre–floor friction coefficient [-] (F1TENTH gym ``mu``)."""
F1TENTH_CS_FRONT_PER_RAD: float = 4.718
"""Front cornering stiffness per unit normal load [1/rad] (F1TENTH gym ``C_Sf``)."""
F1TENTH_CS_REAR_PER_RAD: float = 5.4562
"""Rear cornering stiffness per unit normal load [1/rad] (F1TENTH gym ``C_Sr``)."""
F1TENTH_LF_M: float = 0.15875
"""CoG → front axle of the F1TENTH car [m] (F1TENTH gym ``lf``)."""
F1TENTH_LR_M: float = 0.17145
"""CoG → rear axle of the F1TENTH car [m] (F1TENTH gym ``lr``)."""
F1TENTH_MASS_KG: float = 3.74
"""Mass of the F1TENTH car [kg] (F1TENTH gym ``m``)."""
F1TENTH_YAW_INERTIA_KG_M2: float = 0.04712
"""Yaw moment of inertia of the F1TENTH car [kg m²] (F1TENTH gym ``I``)."""

PACEJKA_SHAPE_C: float = 1.3
"""Magic formula shape factor for side force [-]: Pacejka, *Tire and Vehicle Dynamics*
(3rd ed., 2012), section 4.3.2, where C ≈ 1.3 for the lateral force. With ``B = C_S / C``
the peak ``μ F_z`` is reached at α = tan(π / 2C) / B ≈ 0.41 rad front: sliding, not a
cliff."""

ROLLING_RESISTANCE: float = 0.015
"""Rolling resistance coefficient [-]: rubber tyres on a smooth hard floor, the 0.010–0.015
of car tyres on concrete in Gillespie, *Fundamentals of Vehicle Dynamics* (SAE, 1992),
table 4.1 (upper end: a small, soft tyre)."""

MOTOR_TIME_CONSTANT_S: float = 0.05
"""First-order lag of the drive's delivered acceleration [s]: a brushless speed
controller's current loop and the drivetrain's spin-up; Liniger, Domahidi & Morari,
"Optimization-based autonomous racing of 1:43 scale RC cars" (Optim. Control Appl. Meth.,
2015) identify their drivetrain without lag at a 20 ms sample; 50 ms is a conservative
2.5 samples of a 50 frames/s camera."""

BLEND_LOW_M_S: float = 0.5
"""Below this speed [m/s] the car moves as the kinematic model (slip angles are singular
at standstill)."""
BLEND_HIGH_M_S: float = 1.0
"""Above this speed [m/s] the car moves as the dynamic model; linear mix in between."""

MAX_SUBSTEP_S: float = 0.001
"""Longest RK4 substep [s]: ten times under the fastest tyre time constant at the blend's
lower end (≈ 10 ms at 0.5 m/s)."""

SPEED_GAIN_PER_S: float = 10.0
"""Cruise control's gain [1/s]: acceleration commanded per m/s of speed error (the set
speed is reached in ≈ 0.1 s plus the motor's lag, as fast as the kinematic car's
instant hold allows a real drive)."""


@dataclass(frozen=True)
class DynamicsParams:
    """The dynamic model's parameters (units in brackets); defaults: the F1TENTH gym's
    car scaled to ``WHEELBASE_M`` (the CoG split and the yaw inertia's radius of
    gyration kept in proportion)."""

    mass_kg: float = F1TENTH_MASS_KG
    """Mass [kg]."""
    yaw_inertia_kg_m2: float = F1TENTH_YAW_INERTIA_KG_M2 * (
        WHEELBASE_M / (F1TENTH_LF_M + F1TENTH_LR_M)) ** 2
    """Yaw moment of inertia [kg m²]."""
    cog_to_front_m: float = WHEELBASE_M * F1TENTH_LF_M / (F1TENTH_LF_M + F1TENTH_LR_M)
    """CoG → front axle [m]; CoG → rear axle is the wheelbase minus this."""
    mu: float = F1TENTH_MU
    """Tyre–floor friction coefficient [-]."""
    cornering_front_per_rad: float = F1TENTH_CS_FRONT_PER_RAD
    """Front cornering stiffness per unit normal load [1/rad]."""
    cornering_rear_per_rad: float = F1TENTH_CS_REAR_PER_RAD
    """Rear cornering stiffness per unit normal load [1/rad]."""
    shape_c: float = PACEJKA_SHAPE_C
    """Magic formula shape factor [-] (1 < C < 2)."""
    rolling_resistance: float = ROLLING_RESISTANCE
    """Rolling resistance coefficient [-] (≥ 0)."""
    motor_time_constant_s: float = MOTOR_TIME_CONSTANT_S
    """Motor lag [s] (≥ 0; 0: none)."""

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise TypeError(f"DynamicsParams.{f.name} must be a number, got {value!r}")
            low_ok = value >= 0 if f.name in ("rolling_resistance",
                                               "motor_time_constant_s") else value > 0
            if not (math.isfinite(value) and low_ok):
                bound = "≥ 0" if f.name in ("rolling_resistance",
                                            "motor_time_constant_s") else "> 0"
                raise ValueError(f"DynamicsParams.{f.name} must be finite and {bound}, got "
                                 f"{value!r}")
        if not 1.0 < self.shape_c < 2.0:
            raise ValueError(f"DynamicsParams.shape_c must lie in (1, 2), got {self.shape_c!r}")

    def vector(self, wheelbase_m: float) -> np.ndarray:
        """The parameters as the kernel reads them (``_P_*`` indices)."""
        if not self.cog_to_front_m < wheelbase_m:
            raise ValueError(f"DynamicsParams.cog_to_front_m ({self.cog_to_front_m} m) must "
                             f"be shorter than the wheelbase ({wheelbase_m} m)")
        lf = self.cog_to_front_m
        lr = wheelbase_m - lf
        return np.array([self.mass_kg, self.yaw_inertia_kg_m2, lf, lr, self.mu,
                         self.cornering_front_per_rad / self.shape_c,
                         self.cornering_rear_per_rad / self.shape_c, self.shape_c,
                         self.rolling_resistance, self.motor_time_constant_s], np.float64)

    def understeer_gradient_rad_s2_m(self) -> float:
        """The linear tyres' understeer gradient K [rad per m/s² of lateral
        acceleration]: on a steady circle of radius R, δ = L / R + K v² / R. With loads
        ``m g lr / L`` and ``m g lf / L`` and stiffness ``μ C_S F_z`` per axle,
        K = (1 / C_Sf − 1 / C_Sr) / (μ g)."""
        return (1.0 / self.cornering_front_per_rad - 1.0 / self.cornering_rear_per_rad) / (
            self.mu * GRAVITY_M_S2)


# Indices of the kernel's parameter vector and state.
_P_MASS, _P_INERTIA, _P_LF, _P_LR, _P_MU, _P_BF, _P_BR, _P_C, _P_ROLL, _P_TAU = range(10)
STATE_SIZE = 7
"""x [m], y [m] (the rear axle centre in the world), yaw [rad], vx, vy [m/s] (the CoG's
velocity in the car frame), r [rad/s], a [m/s²] (the motor's delivered acceleration)."""


@njit(cache=True)
def _derivatives(s: np.ndarray, steer: float, a_cmd: float, p: np.ndarray,
                 mu_scale: float, out: np.ndarray) -> None:
    """ds/dt of the dynamic model at state ``s`` (``STATE_SIZE``)."""
    yaw, vx, vy, r, a = s[2], s[3], s[4], s[5], s[6]
    m, iz, lf, lr = p[_P_MASS], p[_P_INERTIA], p[_P_LF], p[_P_LR]
    mu = p[_P_MU] * mu_scale
    wheelbase = lf + lr
    fzf = m * GRAVITY_M_S2 * lr / wheelbase
    fzr = m * GRAVITY_M_S2 * lf / wheelbase
    vxs = max(vx, 1e-3)  # the blend keeps vx ≥ BLEND_LOW_M_S wherever this matters
    alpha_f = steer - math.atan2(vy + lf * r, vxs)
    alpha_r = -math.atan2(vy - lr * r, vxs)
    c = p[_P_C]
    fyf = mu * fzf * math.sin(c * math.atan(p[_P_BF] * alpha_f))
    fyr = mu * fzr * math.sin(c * math.atan(p[_P_BR] * alpha_r))
    # Rear-wheel drive: the drive force within what the rear tyre's grip leaves.
    grip = mu * fzr
    fx = min(max(m * a, -grip), grip)
    roll = p[_P_ROLL] * m * GRAVITY_M_S2 if vx > 0.0 else 0.0
    cos_d, sin_d = math.cos(steer), math.sin(steer)
    # The rear axle centre moves with the CoG's velocity minus r × lr (car frame).
    vrx, vry = vx, vy - lr * r
    cos_y, sin_y = math.cos(yaw), math.sin(yaw)
    out[0] = vrx * cos_y - vry * sin_y
    out[1] = vrx * sin_y + vry * cos_y
    out[2] = r
    out[3] = (fx - fyf * sin_d - roll) / m + vy * r
    out[4] = (fyr + fyf * cos_d) / m - vx * r
    out[5] = (lf * fyf * cos_d - lr * fyr) / iz
    tau = p[_P_TAU]
    out[6] = (a_cmd - a) / tau if tau > 0.0 else 0.0


@njit(cache=True)
def _blend(s: np.ndarray, steer: float, lr: float, wheelbase: float) -> None:
    """Mix ``vy`` and ``r`` towards the kinematic model's at low speed (see the module's
    docstring); never backwards."""
    vx = s[3]
    if vx < 0.0:
        s[3] = 0.0
        vx = 0.0
    if vx >= 1.0:  # BLEND_HIGH_M_S
        return
    w = min(max((vx - 0.5) / (1.0 - 0.5), 0.0), 1.0)  # BLEND_LOW_M_S … BLEND_HIGH_M_S
    tan_d = math.tan(steer)
    r_kin = vx * tan_d / wheelbase
    vy_kin = r_kin * lr  # the rear axle moves straight ahead: vy − lr r = 0
    s[4] = w * s[4] + (1.0 - w) * vy_kin
    s[5] = w * s[5] + (1.0 - w) * r_kin


@njit(cache=True)
def advance(state: np.ndarray, steer: float, a_cmd: float, dt: float, p: np.ndarray,
            mu_scale: float, max_speed: float) -> None:
    """``state`` (``STATE_SIZE``) moved on by ``dt`` [s] at wheel angle ``steer`` [rad]
    and commanded acceleration ``a_cmd`` [m/s²] in RK4 substeps of at most
    ``MAX_SUBSTEP_S``, in place. ``mu_scale`` multiplies the friction coefficient (a wet
    patch); the speed stays within [0, ``max_speed``]."""
    n = max(1, int(math.ceil(dt / 0.001 - 1e-9)))  # MAX_SUBSTEP_S
    h = dt / n
    k1 = np.empty(STATE_SIZE)
    k2 = np.empty(STATE_SIZE)
    k3 = np.empty(STATE_SIZE)
    k4 = np.empty(STATE_SIZE)
    tmp = np.empty(STATE_SIZE)
    lr = p[_P_LR]
    wheelbase = p[_P_LF] + lr
    tau = p[_P_TAU]
    for _ in range(n):
        if tau <= 0.0:
            state[6] = a_cmd
        _derivatives(state, steer, a_cmd, p, mu_scale, k1)
        for i in range(STATE_SIZE):
            tmp[i] = state[i] + 0.5 * h * k1[i]
        _derivatives(tmp, steer, a_cmd, p, mu_scale, k2)
        for i in range(STATE_SIZE):
            tmp[i] = state[i] + 0.5 * h * k2[i]
        _derivatives(tmp, steer, a_cmd, p, mu_scale, k3)
        for i in range(STATE_SIZE):
            tmp[i] = state[i] + h * k3[i]
        _derivatives(tmp, steer, a_cmd, p, mu_scale, k4)
        for i in range(STATE_SIZE):
            state[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
        if state[3] > max_speed:
            state[3] = max_speed
        _blend(state, steer, lr, wheelbase)


def cruise_accel(speed_m_s: float, set_speed_m_s: float, max_accel: float,
                 max_brake: float) -> float:
    """The acceleration [m/s²] cruise control commands to hold ``set_speed_m_s``."""
    return min(max(SPEED_GAIN_PER_S * (set_speed_m_s - speed_m_s), -max_brake), max_accel)


def kinematic_state(x: float, y: float, yaw: float, speed_m_s: float, steer_rad: float,
                    p: np.ndarray) -> np.ndarray:
    """A state rolling without slip at ``speed_m_s`` and wheel angle ``steer_rad`` (a
    reset): the kinematic model's lateral speed and yaw rate."""
    lr = p[_P_LR]
    r = speed_m_s * math.tan(steer_rad) / (p[_P_LF] + lr)
    return np.array([x, y, yaw, speed_m_s, r * lr, r, 0.0], np.float64)
