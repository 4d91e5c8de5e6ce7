"""Faults injected into a closed-loop drive, to stress the lane detection and its LIS.

A fault schedule is a tuple of the frozen dataclasses below, in the units of the world:
every time in seconds after ``reset`` (``start_s``, ``duration_s``), every place in metres
(arc length for a marking gap or a wet patch, a point on the floor relative to the car
for a glare). The ``FaultInjector`` of an episode turns them into the env's steps with
the camera's frame rate and projects the glare through the camera's lens, so one
schedule means the same on every camera profile and frame rate.

Steps: the reset's frame is step 0, taken at 0 s; step ``k`` is the frame taken ``k``
frame periods later (the first ``step()`` is step 1). A fault starts at the step nearest
``start_s`` and lasts the number of frames nearest ``duration_s``, at least one (a
blackout shorter than a frame still darkens the frame exposed then).

Where they act:

- the image (``Blackout``, ``Overexposure``, ``Glare``): on the camera pixels after
  rendering, each as a function of the pixel and the step only, so the ROIs rendered on
  demand see exactly what the full frame shows;
- the scene (``MarkingGap``): painted out of the track that is rendered (the ground
  truth and the reward still use the real track);
- the world after the car moved (``LateralKick`` moves the car; ``CameraShake`` turns the
  camera, not the car; ``WetPatch`` sets the world's ``mu_scale`` while the car is on it);
- the steering (``ServoOffset``: the servo holds the command plus an offset);
- the pipeline's delivery (``LatencySpike``: results arrive later; ``FrameDropBurst``:
  frames never reach the detector).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Protocol

import numpy as np

from tfalda_sim.camera import Camera
from tfalda_sim.timing import MAX_LATENCY_S
from tfalda_sim.tracks import Gap, Line, Track
from tfalda_sim.tracks.model import MAX_TRACK_LENGTH_M

MAX_GAIN: float = 255.0
"""Largest overexposure gain [-]: every grey level ≥ 1 DN saturates at it already."""

MAX_DN: float = 255.0
"""Largest grey level of the 8-bit camera [DN]."""

MAX_GLARE_DISTANCE_M: float = 10.0
"""Farthest a glare may lie from the camera's foot point, ahead or aside [m]: a
Carolo-Cup hall's mat is tens of metres across, and beyond 10 m the camera sees the
floor in a few rows at the horizon."""

MAX_GLARE_RADIUS_M: float = 5.0
"""Largest glare radius on the floor [m]: a reflection wider than the road many times
over is a uniform brightening."""

MAX_SHAKE_RAD: float = math.pi
"""Largest camera-shake amplitude [rad]: half a turn either way."""

MAX_KICK_M: float = 1.0
"""Largest lateral kick [m]: beyond the 0.82 m road, a kick is a teleport."""

MAX_SERVO_OFFSET_RAD: float = 0.5
"""Largest servo offset [rad]: beyond the steering range of a 1:10 chassis (0.44 rad,
``tfalda_sim.vehicle.MAX_STEER_RAD``), where the wheels stop at their end anyway."""

MAX_TIME_S: float = 1.0e7
"""Latest start and longest duration of a fault [s] (116 days of driving)."""

WET_MU_SCALE: float = 0.3
"""Default friction of a wet patch, a share of the dry floor's [-]. Road tyres keep
0.55–0.8 of their dry grip on wet asphalt and ≈ 0.25 on packed snow (J. Y. Wong, Theory
of Ground Vehicles, 4th ed., 2008, table 1.3: peak adhesion dry 0.8–0.9, wet 0.5–0.7,
packed snow 0.2); a water film on the smooth mat of a Carolo-Cup track, under a hard
model-car tyre, is taken to lie near the snow end."""


def _number(name: str, value: object) -> float:
    if isinstance(value, bool | str | bytes) or not hasattr(value, "__float__"):
        raise TypeError(f"{name} must be a real number, got {value!r}")
    return float(value)  # type: ignore[arg-type]


def _within(name: str, value: float, low: float, high: float, unit: str = "",
            hint: str = "") -> None:
    if not (math.isfinite(value) and low <= value <= high):
        raise ValueError(f"{name} must be finite and in [{low:g}, {high:g}]{unit}{hint}, got "
                         f"{value!r}")


_TIME_HINT = " (seconds after the reset; the injector counts them in camera frames)"


def _check(fault: object, bounds: dict[str, tuple[float, float, str]]) -> None:
    """Every number field a float (numpy scalars accepted), finite and within ``bounds``
    (name → (low, high, unit)); ``start_s`` ≥ 0 and ``duration_s`` > 0 in seconds."""
    kind = type(fault).__name__
    for f in fields(fault):  # type: ignore[arg-type]
        if f.name == "lines":
            continue
        name = f"{kind}.{f.name}"
        value = _number(name, getattr(fault, f.name))
        object.__setattr__(fault, f.name, value)
        if f.name == "start_s":
            _within(name, value, 0.0, MAX_TIME_S, " s", _TIME_HINT)
        elif f.name == "duration_s":
            if not (math.isfinite(value) and 0.0 < value <= MAX_TIME_S):
                raise ValueError(f"{name} must be > 0 and ≤ {MAX_TIME_S:g} s (a fault lasts "
                                 f"at least one frame), got {value!r}")
        elif f.name in bounds:
            low, high, unit = bounds[f.name]
            _within(name, value, low, high, unit)


@dataclass(frozen=True)
class Blackout:
    """The camera delivers black frames (lens covered, exposure failure) from ``start_s``
    for ``duration_s`` [s]."""

    start_s: float
    duration_s: float

    def __post_init__(self) -> None:
        _check(self, {})


@dataclass(frozen=True)
class Overexposure:
    """The image is blown out: grey levels multiplied by ``gain`` [-] (saturating)."""

    start_s: float
    duration_s: float
    gain: float = 4.0

    def __post_init__(self) -> None:
        _check(self, {"gain": (0.0, MAX_GAIN, "")})


@dataclass(frozen=True)
class Glare:
    """A reflection on the floor (a lamp's or the sun's): a bright Gaussian blob centred
    on the ground point ``ahead_m`` ahead of and ``left_m`` left of the camera's foot
    point (the floor under the lens, along the car's axes) [m], ``radius_m`` [m] its
    standard deviation on the floor, adding up to ``peak_dn`` [DN].

    The point is fixed relative to the car: the blob is projected through the camera
    each frame (its pixel centre and radius follow the lens and the mount) and stays in
    place in the image as the car drives. That is the reflection of a lamp the car
    carries, and near enough that of a room lamp: a mirror image moves with the viewer,
    and over the second or so of a fault the car's heading hardly changes. A camera
    shake turns the camera, not the car, so the blob moves in the image with it.

    The defaults: on the thesis camera, a blob at pixel (376, 330) with a 60 px radius,
    just ahead in the middle of the view."""

    start_s: float
    duration_s: float
    ahead_m: float = 0.44
    left_m: float = 0.0
    radius_m: float = 0.16
    peak_dn: float = 200.0

    def __post_init__(self) -> None:
        _check(self, {"ahead_m": (-MAX_GLARE_DISTANCE_M, MAX_GLARE_DISTANCE_M, " m"),
                      "left_m": (-MAX_GLARE_DISTANCE_M, MAX_GLARE_DISTANCE_M, " m"),
                      "radius_m": (0.0, MAX_GLARE_RADIUS_M, " m"),
                      "peak_dn": (0.0, MAX_DN, " DN")})
        if self.radius_m <= 0:
            raise ValueError(f"Glare.radius_m must be > 0 (the blob's radius on the floor "
                             f"[m]), got {self.radius_m!r}")


@dataclass(frozen=True)
class CameraShake:
    """The camera turns by a random yaw of up to ``amplitude_rad`` [rad] each frame (a
    loose mount on a bumpy floor); the car drives on unaffected."""

    start_s: float
    duration_s: float
    amplitude_rad: float = 0.03

    def __post_init__(self) -> None:
        _check(self, {"amplitude_rad": (0.0, MAX_SHAKE_RAD, " rad")})


@dataclass(frozen=True)
class LateralKick:
    """At ``start_s`` [s] the car is moved sideways by ``offset_m`` [m] (left positive),
    as if pushed; speed and heading stay."""

    start_s: float
    offset_m: float = 0.15

    def __post_init__(self) -> None:
        _check(self, {"offset_m": (-MAX_KICK_M, MAX_KICK_M, " m")})


@dataclass(frozen=True)
class MarkingGap:
    """``lines`` are not painted from arc length ``s_m`` [m] for ``length_m`` [m] (for the
    whole episode; the rules allow gaps of up to 1 m)."""

    s_m: float
    length_m: float = 1.0
    lines: tuple[Line, ...] = (Line.LEFT, Line.CENTRE, Line.RIGHT)

    def __post_init__(self) -> None:
        _check(self, {"s_m": (-MAX_TRACK_LENGTH_M, MAX_TRACK_LENGTH_M, " m"),
                      "length_m": (0.0, MAX_TRACK_LENGTH_M, " m")})
        if self.length_m <= 0:
            raise ValueError(f"MarkingGap.length_m must be > 0 [m], got {self.length_m}")
        if (isinstance(self.lines, str) or not isinstance(self.lines, tuple | list)
                or not self.lines or not all(isinstance(v, Line) for v in self.lines)):
            raise ValueError(f"MarkingGap.lines must be tfalda_sim.tracks.Line members, got "
                             f"{self.lines!r}")
        object.__setattr__(self, "lines", tuple(self.lines))


@dataclass(frozen=True)
class LatencySpike:
    """The pipeline stalls: the results of the frames taken from ``start_s`` for
    ``duration_s`` [s] arrive ``extra_s`` [s] later than the timing's camera latency (and
    the frames after them wait: a result never overtakes an earlier one)."""

    start_s: float
    duration_s: float
    extra_s: float

    def __post_init__(self) -> None:
        _check(self, {"extra_s": (0.0, MAX_LATENCY_S, " s")})
        if self.extra_s <= 0:
            raise ValueError(f"LatencySpike.extra_s must be > 0 and ≤ {MAX_LATENCY_S:g} s "
                             f"(the added delay), got {self.extra_s!r}")


@dataclass(frozen=True)
class FrameDropBurst:
    """The frames taken from ``start_s`` for ``duration_s`` [s] are lost: no frame reaches
    the detector, the observation stays the last one delivered."""

    start_s: float
    duration_s: float

    def __post_init__(self) -> None:
        _check(self, {})


@dataclass(frozen=True)
class WetPatch:
    """The floor's friction is ``mu_scale`` [-] of the dry floor's from arc length ``s_m``
    for ``length_m`` [m] (for the whole episode; the world's ``mu_scale`` while the car's
    rear axle is on it). It only matters for the dynamic car
    (``vehicle="dynamic"``): the kinematic car turns as its wheels point on any floor."""

    s_m: float
    length_m: float = 1.0
    mu_scale: float = WET_MU_SCALE

    def __post_init__(self) -> None:
        _check(self, {"s_m": (-MAX_TRACK_LENGTH_M, MAX_TRACK_LENGTH_M, " m"),
                      "length_m": (0.0, MAX_TRACK_LENGTH_M, " m"),
                      "mu_scale": (0.0, 1.0, "")})
        if self.length_m <= 0:
            raise ValueError(f"WetPatch.length_m must be > 0 [m], got {self.length_m}")


@dataclass(frozen=True)
class ServoOffset:
    """From ``start_s`` for ``duration_s`` [s] the wheels point ``offset_rad`` [rad] (left
    positive) off the command — a knocked servo horn: the servo holds the command plus the
    offset, within the steering range, reached at the servo's rate."""

    start_s: float
    duration_s: float
    offset_rad: float

    def __post_init__(self) -> None:
        _check(self, {"offset_rad": (-MAX_SERVO_OFFSET_RAD, MAX_SERVO_OFFSET_RAD, " rad")})


Fault = (Blackout | Overexposure | Glare | CameraShake | LateralKick | MarkingGap
         | LatencySpike | FrameDropBurst | WetPatch | ServoOffset)
FAULT_TYPES: tuple[type, ...] = (Blackout, Overexposure, Glare, CameraShake, LateralKick,
                                 MarkingGap, LatencySpike, FrameDropBurst, WetPatch,
                                 ServoOffset)
ImageFault = Blackout | Overexposure | Glare
TimedFault = (Blackout | Overexposure | Glare | CameraShake | LateralKick | LatencySpike
              | FrameDropBurst | ServoOffset)
"""The faults that act at steps (the others act at places: marking gaps, wet patches)."""


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


def frame_at(t_s: float, frame_rate_hz: float) -> int:
    """The step whose frame is taken nearest ``t_s`` [s] after the reset (halves round
    up)."""
    return math.floor(t_s * frame_rate_hz + 0.5)


def frames(fault: TimedFault, frame_rate_hz: float) -> range:
    """The steps at which ``fault`` acts on a camera of ``frame_rate_hz`` [1/s]: from the
    frame nearest ``start_s`` for the number of frames nearest ``duration_s``, at least
    one (a kick: the one frame)."""
    first = frame_at(fault.start_s, frame_rate_hz)
    duration = getattr(fault, "duration_s", None)
    count = 1 if duration is None else max(1, frame_at(duration, frame_rate_hz))
    return range(first, first + count)


def active(faults: Sequence[Fault], step: int, kind: type, frame_rate_hz: float) -> list:
    """The faults of type ``kind`` acting at ``step``, in schedule order (a marking gap
    or a wet patch is there all episode)."""
    return [f for f in faults if isinstance(f, kind) and (
        isinstance(f, MarkingGap | WetPatch) or step in frames(f, frame_rate_hz))]


def with_gaps(track: Track, faults: Sequence[Fault]) -> Track:
    """``track`` with the schedule's marking gaps painted out (the track to render; the
    rasteriser wraps a gap over the start of a closed track)."""
    gaps = tuple(Gap(line, f.s_m % track.length_m if track.closed else f.s_m, f.length_m)
                 for f in faults if isinstance(f, MarkingGap) for line in f.lines)
    return track.with_elements(gaps=track.gaps + gaps) if gaps else track


def on_patch(patch: WetPatch, track: Track, s_m: float) -> bool:
    """Arc length ``s_m`` [m] lies on ``patch`` (wrapped over the start of a closed
    track)."""
    if track.closed:
        return (s_m - patch.s_m) % track.length_m < patch.length_m
    return patch.s_m <= s_m < patch.s_m + patch.length_m


@dataclass(frozen=True)
class GlareBlob:
    """A glare in one frame's pixels: centre ``(u_px, v_px)``, standard deviation
    ``radius_px`` [px], ``peak_dn`` [DN]."""

    u_px: float
    v_px: float
    radius_px: float
    peak_dn: float


def glare_blob(glare: Glare, camera: Camera, shake_rad: float = 0.0) -> GlareBlob | None:
    """``glare`` projected through ``camera`` (turned by ``shake_rad`` [rad] on its mount,
    about the rear axle as the renderer turns it): the centre's pixel, and the radius the
    geometric mean of the half-axes of the floor circle's image (the circle of the same
    area). None if the lens does not see the reflection."""
    mount = camera.mount
    x0, y0 = mount.forward_m + glare.ahead_m, mount.lateral_m + glare.left_m
    r = glare.radius_m
    pts = np.array([[x0, y0], [x0 + r, y0], [x0 - r, y0], [x0, y0 + r], [x0, y0 - r]])
    if shake_rad:
        # The point stays on the car; the camera turned: seen from the turned camera the
        # point turned back by the shake.
        c, s = math.cos(shake_rad), math.sin(shake_rad)
        pts = pts @ np.array([[c, -s], [s, c]])
    px = camera.project(camera.car_to_camera(np.column_stack([pts, np.zeros(len(pts))])))
    if not np.all(np.isfinite(px)):
        return None
    along = 0.5 * float(np.linalg.norm(px[1] - px[2]))
    aside = 0.5 * float(np.linalg.norm(px[3] - px[4]))
    radius = math.sqrt(along * aside)
    if not radius > 0.0:
        return None
    return GlareBlob(float(px[0, 0]), float(px[0, 1]), radius, glare.peak_dn)


def apply_image_faults(crops: list[np.ndarray], windows: Sequence[tuple[int, int, int, int]],
                       faults: Sequence[Blackout | Overexposure | GlareBlob]) -> None:
    """Apply the image faults (a glare as its ``GlareBlob`` in this frame), in schedule
    order, to the uint8 ``crops`` (in place), each the window ``(x, y, w, h)`` [px] of the
    frame: a crop of a faulted full frame equals the faulted crop."""
    for f in faults:
        for crop, (x0, y0, w, h) in zip(crops, windows, strict=True):
            if isinstance(f, Blackout):
                crop[:] = 0
            elif isinstance(f, Overexposure):
                crop[:] = np.clip(crop.astype(np.float32) * np.float32(f.gain)
                                  + np.float32(0.5), 0, 255).astype(np.uint8)
            elif isinstance(f, GlareBlob):
                u = np.arange(x0, x0 + w, dtype=np.float32) - np.float32(f.u_px)
                v = np.arange(y0, y0 + h, dtype=np.float32) - np.float32(f.v_px)
                k = np.float32(-0.5 / f.radius_px**2)
                blob = (np.float32(f.peak_dn) * np.exp(k * v[:, None] ** 2)
                        * np.exp(k * u[None, :] ** 2))
                crop[:] = np.clip(crop + blob + np.float32(0.5), 0, 255).astype(np.uint8)


class Movable(Protocol):
    """What the injector acts on: the car in the world (``tfalda_sim.world.World``)."""

    track: Track
    mu_scale: float

    @property
    def pose(self) -> tuple[float, float, float]: ...

    def place(self, pose: tuple[float, float, float]) -> None: ...

    def position(self) -> object: ...


class FaultInjector:
    """An episode's fault schedule on ``camera`` (its frame rate turns seconds into
    steps, its lens places the glare), asked at the points where faults act:

    - ``track``: when the scene is built, the marking gaps are painted out;
    - ``steer_offset``: before the car moves, the servo offset added to the command;
    - ``world``: after the car moved, lateral kicks move it sideways, the wet patches set
      its ``mu_scale`` for the next move, and camera shake turns the camera (the pose the
      frame is rendered from is returned);
    - ``delivery``: whether the frame of a step is lost and how much later its result
      arrives;
    - ``image``: blackout, overexposure and glare change the rendered pixels.

    The shake's random angles come from ``rng`` (one draw per active shake per frame),
    so an episode's faults are a function of its seed."""

    def __init__(self, schedule: Sequence[object], rng: np.random.Generator,
                 camera: Camera) -> None:
        if not isinstance(camera, Camera):
            raise TypeError(f"camera must be a tfalda_sim.camera.Camera, got "
                            f"{type(camera).__name__}")
        self.schedule: tuple[Fault, ...] = check_schedule(schedule)
        self.rng = rng
        self.camera = camera
        rate = camera.frame_rate_hz
        # Each stage's faults with their steps, sorted out once: most episodes have none,
        # and every step asks (≈ 5 µs a step to find nothing).
        timed = [(f, frames(f, rate)) for f in self.schedule  # type: ignore[arg-type]
                 if not isinstance(f, MarkingGap | WetPatch)]
        self._kicks = tuple(x for x in timed if isinstance(x[0], LateralKick))
        self._shakes = tuple(x for x in timed if isinstance(x[0], CameraShake))
        self._image_faults = tuple(x for x in timed if isinstance(x[0], ImageFault))
        self._servo = tuple(x for x in timed if isinstance(x[0], ServoOffset))
        self._delivery = tuple(x for x in timed
                               if isinstance(x[0], LatencySpike | FrameDropBurst))
        self._wet = tuple(f for f in self.schedule if isinstance(f, WetPatch))
        # The shake of each step a glare may need again (a frame re-rendered later), and
        # each glare's blob without shake (the same every frame).
        self._shake_at: dict[int, float] = {}
        self._blobs: dict[Glare, GlareBlob | None] = {}

    @property
    def delivers(self) -> bool:
        """The schedule has faults of the pipeline's delivery (latency spikes, bursts of
        dropped frames)."""
        return bool(self._delivery)

    def track(self, track: Track) -> Track:
        """The track to render: ``with_gaps``."""
        return with_gaps(track, self.schedule)

    def steer_offset(self, step: int) -> float:
        """The servo offset [rad] of the move that ends at ``step`` (0.0: none)."""
        return sum((f.offset_rad for f, steps in self._servo if step in steps), 0.0)

    def world(self, step: int, car: Movable) -> tuple[float, float, float]:
        """Apply the world faults of ``step`` to ``car``; the camera pose ``(x [m], y [m],
        yaw [rad])`` of this step's frame."""
        for kick, steps in self._kicks:
            if step in steps:
                x, y, yaw = car.pose
                car.place((x - math.sin(yaw) * kick.offset_m,
                           y + math.cos(yaw) * kick.offset_m, yaw))
        if self._wet:  # where the car is now (after a kick) sets the next move's grip
            s_m = car.position().s_m  # type: ignore[attr-defined]
            car.mu_scale = min((p.mu_scale for p in self._wet
                                if on_patch(p, car.track, s_m)), default=1.0)
        if not self._shakes:
            return car.pose
        x, y, yaw = car.pose
        shake = 0.0
        for f, steps in self._shakes:
            if step in steps:
                shake += float(self.rng.uniform(-f.amplitude_rad, f.amplitude_rad))
        if not shake:
            return x, y, yaw
        if self._image_faults:
            self._shake_at[step] = shake
        return x, y, yaw + shake

    def delivery(self, step: int) -> tuple[bool, float]:
        """Whether the frame of ``step`` is lost, and the extra delay [s] of its result."""
        dropped, extra = False, 0.0
        for f, steps in self._delivery:
            if step in steps:
                if isinstance(f, FrameDropBurst):
                    dropped = True
                else:
                    extra += f.extra_s
        return dropped, extra

    def image(self, step: int, crops: list[np.ndarray],
              windows: Sequence[tuple[int, int, int, int]]) -> None:
        """Apply the image faults of ``step`` to ``crops`` (in place; see
        ``apply_image_faults``)."""
        if not self._image_faults:
            return
        faults: list[Blackout | Overexposure | GlareBlob] = []
        for f, steps in self._image_faults:
            if step not in steps:
                continue
            if isinstance(f, Glare):
                blob = self._blob(f, self._shake_at.get(step, 0.0))
                if blob is not None:
                    faults.append(blob)
            else:
                faults.append(f)
        if faults:
            apply_image_faults(crops, windows, faults)

    def _blob(self, glare: Glare, shake_rad: float) -> GlareBlob | None:
        if shake_rad:
            return glare_blob(glare, self.camera, shake_rad)
        if glare not in self._blobs:
            self._blobs[glare] = glare_blob(glare, self.camera)
        return self._blobs[glare]
