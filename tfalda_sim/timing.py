"""The pipeline's timing on a real car: how old the frame is that an observation comes
from, how late a command reaches the wheels, frames lost and the spread of the
pipeline's delay, and the steering servo's own lag — each in seconds, zero by default.

``TIMINGS["real-car"]`` is the thesis' car as the thesis and the hobby servo it steers
with describe it; ``Timing()`` (``"ideal"``) is today's idealised loop: the observation
of a step is computed from that step's frame and a command acts at once.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from .vehicle import REAL_SERVO, ServoParams

CAMERA_FRAME_PERIOD_S: float = 1.0 / 50.0
"""The thesis camera's frame period [s] (thesis 1.1: 50 frames/s): a frame is read out
one period after its exposure starts."""

THESIS_PROCESSING_S: float = 1.0 / 70.0
"""The prototype's processing time per frame [s] (thesis 1.1: about 70 frames/s on a
1 GHz VIA CPU at 100 % load)."""

REAL_CAMERA_LATENCY_S: float = 2.0 * CAMERA_FRAME_PERIOD_S
"""Age of the frame an observation comes from on the thesis' car [s]: read-out (one
frame period) plus processing (``THESIS_PROCESSING_S``) is 34 ms, so the newest result at a
frame's start is the one of the frame two periods before."""

REAL_JITTER_S: float = THESIS_PROCESSING_S
"""Spread of that delay [s]: a result arrives between read-out and read-out plus the
processing time, depending on the load (the prototype ran at 100 %)."""

SERVO_PULSE_PERIOD_S: float = 0.020
"""A hobby servo takes a new command once per control pulse, every 20 ms (the RC PWM
convention)."""

REAL_ACTUATOR_LATENCY_S: float = 0.5 * SERVO_PULSE_PERIOD_S
"""Delay from a command to the servo acting on it [s]: half a pulse period on average
(the command waits for the next pulse)."""

_NOISE_BOUNDS = {"speed_noise_m_s": 2.0, "steer_noise_rad": 0.5}
"""Largest odometry noise accepted (a quarter of the top speed [m/s]; more than the
steering range [rad])."""

MAX_LATENCY_S: float = 1.0
"""Longest latency accepted [s]: 50 frames of the thesis camera; beyond it no car
drives."""


@dataclass(frozen=True)
class Timing:
    """The pipeline's timing (seconds) and the steering servo."""

    camera_latency_s: float = 0.0
    """Age of the frame an observation comes from [s]: the observation at a step is the
    newest detector result available then (rounded to frames: a result counts from the
    first step at or after its arrival)."""
    actuator_latency_s: float = 0.0
    """Delay from an action to the car acting on it [s] (resolved at physics steps)."""
    frame_drop_probability: float = 0.0
    """Chance that a frame is lost [-]: the detector sees nothing, the observation stays
    the last one."""
    jitter_s: float = 0.0
    """Extra delay of each frame's result, uniform in [0, jitter_s] [s]."""
    speed_noise_m_s: float = 0.0
    """Standard deviation of the odometry's speed in an observation [m/s] (Gaussian,
    per frame)."""
    steer_noise_rad: float = 0.0
    """Standard deviation of the odometry's wheel angle in an observation [rad]."""
    servo: ServoParams = field(default_factory=ServoParams)
    """The steering servo's lag and dead band."""

    def __post_init__(self) -> None:
        for f in fields(self):
            if f.name == "servo":
                if not isinstance(self.servo, ServoParams):
                    raise TypeError(f"Timing.servo must be a ServoParams, got {self.servo!r}")
                continue
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not (
                    math.isfinite(value)):
                raise ValueError(f"Timing.{f.name} must be a finite number, got {value!r}")
            if f.name == "frame_drop_probability":
                if not 0.0 <= value < 1.0:
                    raise ValueError(f"Timing.{f.name} must lie in [0, 1), got {value!r}")
            elif f.name in _NOISE_BOUNDS:
                if not 0.0 <= value <= _NOISE_BOUNDS[f.name]:
                    raise ValueError(f"Timing.{f.name} must lie in [0, "
                                     f"{_NOISE_BOUNDS[f.name]}], got {value!r}")
            elif not 0.0 <= value <= MAX_LATENCY_S:
                raise ValueError(f"Timing.{f.name} must lie in [0, {MAX_LATENCY_S}] s, got "
                                 f"{value!r}")

    @property
    def ideal(self) -> bool:
        """No latency, drop, jitter or noise (the observation of a step is that step's,
        exactly)."""
        return (self.camera_latency_s == 0.0 and self.frame_drop_probability == 0.0
                and self.jitter_s == 0.0 and self.speed_noise_m_s == 0.0
                and self.steer_noise_rad == 0.0)



_KEYS = tuple(f.name for f in fields(Timing) if f.name != "servo")
_SERVO_KEYS = tuple(f.name for f in fields(ServoParams))


def load_timing(path: str | os.PathLike[str]) -> Timing:
    """A timing from a JSON file: any of the ``Timing`` fields in seconds (and
    ``frame_drop_probability``), ``servo`` an object with ``ServoParams``' fields;
    unknown keys refused."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except OSError as exc:
        raise ValueError(f"timing file {path}: {exc.strerror or exc}") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"timing file {path} is not JSON ({exc})") from None
    if not isinstance(doc, dict):
        raise ValueError(f"timing file {path} must hold one JSON object")
    unknown = sorted(set(doc) - set(_KEYS) - {"servo"})
    if unknown:
        raise ValueError(f"timing file {path}: unknown key {unknown[0]!r}; use "
                         f"{', '.join((*_KEYS, 'servo'))}")
    servo = doc.get("servo", {})
    if not isinstance(servo, dict) or set(servo) - set(_SERVO_KEYS):
        raise ValueError(f"timing file {path}: servo must be an object with "
                         f"{', '.join(_SERVO_KEYS)}")
    try:
        return Timing(**{k: doc[k] for k in _KEYS if k in doc}, servo=ServoParams(**servo))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"timing file {path}: {exc}") from None


def resolve_timing(spec: object) -> Timing | TimingRandomization:
    """A ``Timing``, a ``TimingRandomization`` (a timing drawn per episode), a name of
    ``TIMINGS`` or a JSON file's path."""
    if isinstance(spec, Timing | TimingRandomization):
        return spec
    if isinstance(spec, str) and spec in TIMINGS:
        return TIMINGS[spec]
    if isinstance(spec, str | os.PathLike) and str(spec).endswith(".json"):
        return load_timing(spec)
    raise ValueError(f"timing must be one of {', '.join(TIMINGS)}, a .json timing file or "
                     f"a tfalda_sim.timing.Timing, got {spec!r}")


@dataclass(frozen=True)
class TimingRandomization:
    """Ranges ``(low, high)`` from which ``sample`` draws a ``Timing`` per episode (the
    env's ``DomainRandomization.timing``): around the real car's, from none to about
    half again as much."""

    camera_latency_s: tuple[float, float] = (0.0, 0.06)
    actuator_latency_s: tuple[float, float] = (0.0, 0.02)
    frame_drop_probability: tuple[float, float] = (0.0, 0.05)
    jitter_s: tuple[float, float] = (0.0, 0.02)
    speed_noise_m_s: tuple[float, float] = (0.0, 0.05)
    steer_noise_rad: tuple[float, float] = (0.0, 0.01)
    servo_lag_s: tuple[float, float] = (0.0, 0.03)
    servo_dead_band_rad: tuple[float, float] = (0.0, 0.006)

    def __post_init__(self) -> None:
        for f in fields(self):
            low, high = getattr(self, f.name)
            if not (math.isfinite(low) and math.isfinite(high) and 0.0 <= low <= high):
                raise ValueError(f"TimingRandomization.{f.name} must be a range (low, high) "
                                 f"with 0 ≤ low ≤ high, got {(low, high)!r}")

    def sample(self, rng: np.random.Generator) -> Timing:
        """Draw one ``Timing`` with ``rng``, its fields in declaration order."""
        v = {f.name: float(rng.uniform(*getattr(self, f.name))) for f in fields(self)}
        servo = ServoParams(lag_s=v.pop("servo_lag_s"),
                            dead_band_rad=v.pop("servo_dead_band_rad"))
        return Timing(**v, servo=servo)


IDEAL_TIMING = Timing()
"""No latency, drop, jitter or noise: the observation of a step is that step's."""

TIMINGS: dict[str, Timing | TimingRandomization] = {
    "ideal": IDEAL_TIMING,
    "real-car": Timing(camera_latency_s=REAL_CAMERA_LATENCY_S,
                       actuator_latency_s=REAL_ACTUATOR_LATENCY_S,
                       jitter_s=REAL_JITTER_S, servo=REAL_SERVO),
    "randomized": TimingRandomization(),
}
"""Named timings: ``"ideal"`` (none), ``"real-car"`` (the thesis' car; no frame drops: its
prototype kept up, 70 frames/s processed against 50 taken) and ``"randomized"`` (a timing
drawn per episode from ``TimingRandomization``'s ranges: for training)."""
