"""Faults injected into a closed-loop drive, to stress the lane detection and its LIS.

A fault schedule is a tuple of the frozen dataclasses below. Image faults act on the
camera pixels after rendering, each as a function of the pixel and the step only, so
the ROIs rendered on demand see exactly what the full frame shows. A marking gap is
painted out of the scene (the ground truth and the reward still use the real track); a
lateral kick moves the car; camera shake turns the camera, not the car.

Steps count env steps (camera frames) after ``reset``: step 1 is the first ``step()``.
``FaultInjector`` is the schedule of one episode, asked where faults act (the scene's
track, the world after the car moved, the rendered image).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Protocol

import numpy as np

from tfalda_sim.tracks import Gap, Line, Track
from tfalda_sim.tracks.model import MAX_TRACK_LENGTH_M

MAX_GAIN: float = 255.0
"""Largest overexposure gain [-]: every grey level ≥ 1 DN saturates at it already."""

MAX_DN: float = 255.0
"""Largest grey level of the 8-bit camera [DN]."""

MAX_GLARE_RADIUS_PX: float = 1000.0
"""Largest glare radius [px]: beyond the 752×480 frame's diagonal (893 px) a blob is a
uniform brightening (an image quantity: the glare lives on the sensor, not the ground)."""

MAX_SHAKE_RAD: float = math.pi
"""Largest camera-shake amplitude [rad]: half a turn either way."""

MAX_KICK_M: float = 1.0
"""Largest lateral kick [m]: beyond the 0.82 m road, a kick is a teleport."""

MAX_STEP: int = 10**9
"""Last step a fault may start at (a billion frames: 230 days at 50 frames/s)."""


def _within(name: str, value: float, low: float, high: float, unit: str = "") -> None:
    if isinstance(value, bool | str | bytes) or not hasattr(value, "__float__"):
        raise TypeError(f"{name} must be a real number, got {value!r}")
    if not (math.isfinite(float(value)) and low <= value <= high):
        raise ValueError(f"{name} must be finite and in [{low:g}, {high:g}]{unit}, got "
                         f"{value!r}")


def _check(fault: object) -> None:
    """Every number finite, steps ≥ 1, durations ≥ 1."""
    name = type(fault).__name__
    for f in fields(fault):  # type: ignore[arg-type]
        v = getattr(fault, f.name)
        if isinstance(v, bool) or not isinstance(v, int | float):
            continue
        if not math.isfinite(v):
            raise ValueError(f"{name}.{f.name} must be finite, got {v!r}")
        if f.name == "step" and not 1 <= v <= MAX_STEP:
            raise ValueError(f"{name}.step must be in [1, {MAX_STEP}] (the first step() is "
                             f"step 1), got {v}")
        if f.name == "duration" and not 1 <= v <= MAX_STEP:
            raise ValueError(f"{name}.duration must be in [1, {MAX_STEP}] steps, got {v}")


@dataclass(frozen=True)
class Blackout:
    """The camera delivers black frames (lens covered, exposure failure)."""

    step: int
    duration: int = 1

    def __post_init__(self) -> None:
        _check(self)


@dataclass(frozen=True)
class Overexposure:
    """The image is blown out: grey levels multiplied by ``gain`` [-] (saturating)."""

    step: int
    duration: int = 1
    gain: float = 4.0

    def __post_init__(self) -> None:
        _check(self)
        _within("Overexposure.gain", self.gain, 0.0, MAX_GAIN)


@dataclass(frozen=True)
class Glare:
    """A bright blob (sun or lamp reflection) centred at pixel ``(u_px, v_px)``: adds up
    to ``peak_dn`` [DN], Gaussian with ``radius_px`` [px] standard deviation."""

    step: int
    duration: int = 1
    u_px: float = 376.0
    v_px: float = 330.0
    radius_px: float = 60.0
    peak_dn: float = 200.0

    def __post_init__(self) -> None:
        _check(self)
        if self.radius_px <= 0:
            raise ValueError(f"Glare.radius_px must be > 0, got {self.radius_px!r}")
        _within("Glare.radius_px", self.radius_px, 0.0, MAX_GLARE_RADIUS_PX, " px")
        _within("Glare.peak_dn", self.peak_dn, 0.0, MAX_DN, " DN")
        # The centre may lie off the frame (a lamp just outside the view), not far off.
        _within("Glare.u_px", self.u_px, -MAX_GLARE_RADIUS_PX, 2 * MAX_GLARE_RADIUS_PX, " px")
        _within("Glare.v_px", self.v_px, -MAX_GLARE_RADIUS_PX, 2 * MAX_GLARE_RADIUS_PX, " px")


@dataclass(frozen=True)
class CameraShake:
    """The camera turns by a random yaw of up to ``amplitude_rad`` [rad] each frame (a
    loose mount on a bumpy floor); the car drives on unaffected."""

    step: int
    duration: int = 1
    amplitude_rad: float = 0.03

    def __post_init__(self) -> None:
        _check(self)
        _within("CameraShake.amplitude_rad", self.amplitude_rad, 0.0, MAX_SHAKE_RAD, " rad")


@dataclass(frozen=True)
class LateralKick:
    """At ``step`` the car is moved sideways by ``offset_m`` [m] (left positive), as if
    pushed; speed and heading stay."""

    step: int
    offset_m: float = 0.15

    def __post_init__(self) -> None:
        _check(self)
        _within("LateralKick.offset_m", self.offset_m, -MAX_KICK_M, MAX_KICK_M, " m")


@dataclass(frozen=True)
class MarkingGap:
    """``lines`` are not painted from arc length ``s_m`` [m] for ``length_m`` [m] (for the
    whole episode; the rules allow gaps of up to 1 m)."""

    s_m: float
    length_m: float = 1.0
    lines: tuple[Line, ...] = (Line.LEFT, Line.CENTRE, Line.RIGHT)

    def __post_init__(self) -> None:
        _check(self)
        if self.length_m <= 0:
            raise ValueError(f"MarkingGap.length_m must be > 0, got {self.length_m}")
        _within("MarkingGap.length_m", self.length_m, 0.0, MAX_TRACK_LENGTH_M, " m")
        _within("MarkingGap.s_m", self.s_m, -MAX_TRACK_LENGTH_M, MAX_TRACK_LENGTH_M, " m")
        if not self.lines or not all(isinstance(v, Line) for v in self.lines):
            raise ValueError(f"MarkingGap.lines must be tfalda_sim.tracks.Line members, got "
                             f"{self.lines}")


Fault = Blackout | Overexposure | Glare | CameraShake | LateralKick | MarkingGap
FAULT_TYPES: tuple[type, ...] = (Blackout, Overexposure, Glare, CameraShake, LateralKick,
                                 MarkingGap)
ImageFault = Blackout | Overexposure | Glare


def check_schedule(faults: Sequence[object]) -> tuple[Fault, ...]:
    """``faults`` as a tuple, each checked to be one of ``FAULT_TYPES``."""
    if isinstance(faults, str | bytes) or not isinstance(faults, Sequence):
        raise TypeError(f"the fault schedule must be a sequence of faults, got "
                        f"{type(faults).__name__}")
    for f in faults:
        if not isinstance(f, FAULT_TYPES):
            raise TypeError(f"unknown fault {f!r}; use one of "
                            f"{', '.join(t.__name__ for t in FAULT_TYPES)} from tfalda_sim.faults")
    return tuple(faults)  # type: ignore[arg-type]


def is_active(fault: Fault, step: int) -> bool:
    """``fault`` acts at ``step`` (a marking gap is there all episode)."""
    if isinstance(fault, MarkingGap):
        return True
    return fault.step <= step < fault.step + getattr(fault, "duration", 1)


def active(faults: Sequence[Fault], step: int, kind: type) -> list:
    """The faults of type ``kind`` acting at ``step``, in schedule order."""
    return [f for f in faults if isinstance(f, kind) and is_active(f, step)]


def with_gaps(track: Track, faults: Sequence[Fault]) -> Track:
    """``track`` with the schedule's marking gaps painted out (the track to render; the
    rasteriser wraps a gap over the start of a closed track)."""
    gaps = tuple(Gap(line, f.s_m % track.length_m if track.closed else f.s_m, f.length_m)
                 for f in faults if isinstance(f, MarkingGap) for line in f.lines)
    return track.with_elements(gaps=track.gaps + gaps) if gaps else track


def apply_image_faults(crops: list[np.ndarray], windows: Sequence[tuple[int, int, int, int]],
                       faults: Sequence[ImageFault]) -> None:
    """Apply the image faults, in schedule order, to the uint8 ``crops`` (in place), each
    the window ``(x, y, w, h)`` [px] of the frame: a crop of a faulted full frame equals
    the faulted crop."""
    for f in faults:
        for crop, (x0, y0, w, h) in zip(crops, windows, strict=True):
            if isinstance(f, Blackout):
                crop[:] = 0
            elif isinstance(f, Overexposure):
                crop[:] = np.clip(crop.astype(np.float32) * np.float32(f.gain)
                                  + np.float32(0.5), 0, 255).astype(np.uint8)
            elif isinstance(f, Glare):
                u = np.arange(x0, x0 + w, dtype=np.float32) - np.float32(f.u_px)
                v = np.arange(y0, y0 + h, dtype=np.float32) - np.float32(f.v_px)
                k = np.float32(-0.5 / f.radius_px**2)
                blob = (np.float32(f.peak_dn) * np.exp(k * v[:, None] ** 2)
                        * np.exp(k * u[None, :] ** 2))
                crop[:] = np.clip(crop + blob + np.float32(0.5), 0, 255).astype(np.uint8)


class Movable(Protocol):
    """What the injector moves: the car in the world (``tfalda_sim.world.World``)."""

    @property
    def pose(self) -> tuple[float, float, float]: ...

    def place(self, pose: tuple[float, float, float]) -> None: ...


class FaultInjector:
    """An episode's fault schedule, asked at the points where faults act.

    - ``track``: when the scene is built, the marking gaps are painted out;
    - ``world``: after the car moved, lateral kicks move it sideways, and camera shake
      turns the camera (the pose the frame is rendered from is returned);
    - ``image``: blackout, overexposure and glare change the rendered pixels.

    The shake's random angles come from ``rng`` (one draw per active shake per frame),
    so an episode's faults are a function of its seed."""

    def __init__(self, schedule: Sequence[object], rng: np.random.Generator) -> None:
        self.schedule: tuple[Fault, ...] = check_schedule(schedule)
        self.rng = rng
        self._sort_out()

    def _sort_out(self) -> None:
        # Each stage's faults, sorted out once: most episodes have none, and every step
        # asks (≈ 5 µs a step to find nothing).
        self._kicks = tuple(f for f in self.schedule if isinstance(f, LateralKick))
        self._shakes = tuple(f for f in self.schedule if isinstance(f, CameraShake))
        self._image_faults = tuple(f for f in self.schedule if isinstance(f, ImageFault))

    def __setstate__(self, state: dict[str, object]) -> None:
        self.__dict__.update(state)
        if "_image_faults" not in state:  # pickled before the stages' lists
            self._sort_out()

    def track(self, track: Track) -> Track:
        """The track to render: ``with_gaps``."""
        return with_gaps(track, self.schedule)

    def world(self, step: int, car: Movable) -> tuple[float, float, float]:
        """Apply the world faults of ``step`` to ``car``; the camera pose ``(x [m], y [m],
        yaw [rad])`` of this step's frame."""
        if not (self._kicks or self._shakes):
            return car.pose
        for kick in active(self._kicks, step, LateralKick):
            x, y, yaw = car.pose
            car.place((x - math.sin(yaw) * kick.offset_m, y + math.cos(yaw) * kick.offset_m,
                       yaw))
        x, y, yaw = car.pose
        for shake in active(self._shakes, step, CameraShake):
            yaw += float(self.rng.uniform(-shake.amplitude_rad, shake.amplitude_rad))
        return x, y, yaw

    def image(self, step: int, crops: list[np.ndarray],
              windows: Sequence[tuple[int, int, int, int]]) -> None:
        """Apply the image faults of ``step`` to ``crops`` (in place; see
        ``apply_image_faults``)."""
        if self._image_faults:
            apply_image_faults(crops, windows, active(self._image_faults, step, ImageFault))
