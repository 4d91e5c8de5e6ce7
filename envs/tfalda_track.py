"""``TfaldaTrack-v0``: keep a 1:10 car in its lane on a Carolo-Cup track, from TFALDA + LIS
lane observations or from the fisheye camera image.

One step: action → car (pymunk) → camera pose → renderer → TFALDA → LIS → observation;
the reward comes from the track geometry. Every stage lives in ``tfalda_sim`` and
``tracks``; this module only wires them together.
"""

from __future__ import annotations

import functools
import math
import os
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, fields, replace
from enum import Enum
from typing import Any, ClassVar

import cv2
import gymnasium as gym
import numpy as np
from gymnasium import spaces

from tfalda_sim.camera import FRAME_RATE_HZ, NAMED_CAMERAS, Camera, load_camera
from tfalda_sim.dynamics import DynamicsParams
from tfalda_sim.evaluation.geometric import geometric_hit_rates
from tfalda_sim.faults import Fault, FaultInjector
from tfalda_sim.perception import DetectorConfig, LaneObservation, RoiLayout, TfaldaDetector
from tfalda_sim.perception.rois import initial_rois, windows
from tfalda_sim.rendering import DomainRandomization, Effects, Renderer, Scene, build_scene
from tfalda_sim.rendering.overlay import draw_observation
from tfalda_sim.rendering.topdown import TopDownMap
from tfalda_sim.timing import IDEAL_TIMING, Timing, TimingRandomization, resolve_timing
from tfalda_sim.tracks import (
    NAMED_TRACKS,
    GeneratorParams,
    Track,
    generate,
    load_named,
    seed_name,
)
from tfalda_sim.vehicle import MIN_CRUISE_SPEED_M_S, CarParams
from tfalda_sim.world import TrackPosition, World

from ._checks import (
    check_bool,
    check_choice,
    check_fault_schedule,
    check_int,
    check_optional,
    check_options,
    check_real,
    check_seed_range,
    check_triple,
    show,
)
from .observation import lane_vector, lane_vector_bounds

DEFAULT_SPEED_M_S: float = 1.5
"""Cruise speed of the car without throttle control [m/s]."""

START_NOISE_LATERAL_M: float = 0.05
"""Largest random lateral offset of the start from the right lane's centre [m]."""

START_NOISE_HEADING_RAD: float = 0.05
"""Largest random heading error at the start [rad]."""

OPEN_TRACK_START_S_M: float = 0.5
"""Start arc length on a track that is not a loop [m]."""

TRACK_SEEDS: tuple[int, int] = (0, 1000)
"""Default range ``[low, high)`` of generated track seeds (scenario ids) drawn at reset."""

RESET_OPTIONS: tuple[str, ...] = ("track", "start", "speed_m_s", "domain_randomization",
                                  "faults")
"""The keys ``reset(options=...)`` accepts."""

DETECTOR_PRESETS: dict[str, Callable[[], DetectorConfig]] = {
    "thesis": DetectorConfig.thesis,
    "improved": DetectorConfig.improved,
    "without_lis": DetectorConfig.without_lis,
}
"""The names ``detector=`` accepts for a ``DetectorConfig`` classmethod."""

MAX_TRACK_SEED_HIGH: int = 2**63
"""Largest ``track_seeds`` high bound (exclusive): the seeds are drawn as int64."""


class StartInCarton(ValueError):
    """``reset(options={"start": ...})`` would put the car inside a carton (an obstacle):
    choose another start (the env stays usable)."""


class ObservationMode(Enum):
    """What ``step`` returns."""

    LANES = "lanes"
    IMAGE = "image"
    DICT = "dict"


@dataclass(frozen=True)
class RewardWeights:
    """Weights of the reward terms (see ``TfaldaTrackEnv``'s docstring)."""

    progress: float = 1.0
    lateral: float = 0.5
    heading: float = 0.5
    crash: float = 10.0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"RewardWeights.{f.name} must be finite and ≥ 0, got {v!r}")


@dataclass
class ObservedFrame:
    """What one step saw: the detector's lanes, the camera pose [m, m, rad] and step the
    frame was rendered at, and its full image (None in "lanes" mode until ``render`` or
    ``camera_frame`` renders it — the same pixels, from the same noise seed)."""

    lanes: LaneObservation
    camera_pose: tuple[float, float, float]
    step: int
    image: np.ndarray | None = None


TrackSpec = str | int | Track | None


def resolve_track(spec: TrackSpec, obstacles: bool) -> Track:
    """A track from a name (``tfalda_sim.tracks.NAMED_TRACKS``), a generator seed or a ``Track``;
    generated tracks lose their cartons unless ``obstacles``."""
    if isinstance(spec, Track):
        return spec
    accepted = (f"a name ({', '.join(NAMED_TRACKS)}), a generator seed (int ≥ 0) or a "
                "tfalda_sim.tracks.Track")
    if isinstance(spec, str):
        if spec not in NAMED_TRACKS:
            raise ValueError(f"unknown track {show(spec)}; use {accepted}")
        return load_named(spec)
    # bool is an int, but track=True is a mistake, not seed 1.
    if isinstance(spec, int | np.integer) and not isinstance(spec, bool):
        if spec < 0:
            raise ValueError(f"track seeds are ≥ 0, got {show(spec)}; use {accepted}")
        track = generate(int(spec), GeneratorParams())
        return track if obstacles else track.with_elements(obstacles=())
    raise TypeError(f"track must be {accepted}, got {show(spec)}")


@functools.lru_cache(maxsize=8)
def _first_roi_windows(layout: RoiLayout) -> tuple[tuple[int, int, int, int], ...]:
    """The windows [px] of table 2.4's ROIs on ``layout`` (a detector's first frame),
    made once per layout (≈ 13 µs each time)."""
    return tuple(windows(initial_rois(layout)))


def resolve_camera(spec: object) -> Camera:
    """A ``Camera``, a profile name or a camera file; a clear error otherwise."""
    if isinstance(spec, Camera):
        return spec
    if not isinstance(spec, (str, os.PathLike)):
        raise TypeError(f"camera must be a profile name ({', '.join(NAMED_CAMERAS)}), a camera "
                        f"file or a tfalda_sim.camera.Camera, got {show(spec)}")
    return load_camera(spec)


def resolve_detector(spec: object) -> DetectorConfig:
    """A ``DetectorConfig``, a name of ``DETECTOR_PRESETS`` or None (the thesis')."""
    if spec is None:
        return DetectorConfig.thesis()
    if isinstance(spec, DetectorConfig):
        return spec
    names = ", ".join(map(repr, DETECTOR_PRESETS))
    if isinstance(spec, str):
        if spec not in DETECTOR_PRESETS:
            raise ValueError(f"unknown detector preset {show(spec)}; use one of {names}")
        return DETECTOR_PRESETS[spec]()
    raise TypeError(f"detector must be a tfalda_sim.perception.DetectorConfig, a preset name "
                    f"({names}) or None, got {show(spec)}")


_TIMING_STREAM = 0x7157
"""Second word of the timing generator's seed (beside the episode's noise seed): a
stream of its own."""

VEHICLES: tuple[str, ...] = ("kinematic", "dynamic")
"""The car models by name: the kinematic bicycle (the default) and the dynamic
single-track car with the F1TENTH gym's tyres (``tfalda_sim.dynamics``)."""


def resolve_vehicle(spec: object) -> DynamicsParams | None:
    """The env's ``vehicle``: a name of ``VEHICLES`` or a ``DynamicsParams``; None for the
    kinematic car."""
    if isinstance(spec, DynamicsParams):
        return spec
    if spec == "dynamic":
        return DYNAMIC_CAR
    check_choice("vehicle", spec, VEHICLES)
    return None


DYNAMIC_CAR = DynamicsParams()
"""The dynamic car of ``vehicle="dynamic"`` (one instance: envs share their world's
parameters by identity)."""


@dataclass(frozen=True)
class _ResetOptions:
    """``reset``'s options, checked (before any state of the env changes)."""

    track: Track | None  # None: draw a generated track from track_seeds
    spec: TrackSpec
    start: tuple[float, float, float] | None
    speed_m_s: float
    domain_randomization: bool
    faults: tuple[Fault, ...]


class TfaldaTrackEnv(gym.Env[np.ndarray | dict[str, np.ndarray], np.ndarray]):
    """Lane keeping for a 1:10 Carolo-Cup car seen through TFALDA + LIS.

    ## Description
    A kinematic bicycle car (wheelbase 0.26 m, servo-limited steering, pymunk) drives on
    a Carolo-Cup track (named, generated from a seed, or given). Each step is one camera
    frame (50 frames/s): the fisheye camera's image is rendered — in ``"lanes"`` mode
    only the ROIs the detector reads — and TFALDA with the Lane Inference System of the
    2008 thesis turns it into lane observations. The agent steers (and optionally
    accelerates) to stay in the middle of the right lane.

    ## Action Space
    ``Box(-1, 1, (1,), float32)``: steering command, −1 full right … +1 full left (the
    servo's target angle ``a · max_steer_rad``, reached at the servo's rate). With
    ``throttle=True``: ``Box(-1, 1, (2,), float32)``, the second entry the motor: +1 full
    acceleration (4 m/s²), −1 full braking (6 m/s²). A NaN, out-of-range or wrongly
    shaped action raises ``ValueError``.

    ## Observation Space
    - ``"lanes"`` (default): ``Box((42,), float32)``, the frame's ``LaneObservation``
      normalised; every index is documented in ``tfalda_sim.envs.observation`` (lane ends of the
      four ROIs, ROI positions, LIS flags, lane widths, fault counter, reset, driving
      state, speed and steering feedback).
    - ``"image"``: ``Box(0, 255, (height, width, 1), uint8)``, the grayscale camera frame
      (480×752 on the thesis camera; the ``camera``'s size otherwise).
    - ``"dict"``: ``Dict(lanes=…, image=…)``.

    ## Rewards
    Per step, with ``Δs`` the progress [m] of the car along the track in this step,
    ``v_ref`` the cruise speed, ``Δt`` = 1/50 s, ``e_y`` the offset from the right lane's
    centre [m], ``w`` the lane width and ``e_ψ`` the heading error [rad]:

    ``r = progress · Δs / (v_ref Δt) − lateral · (2 e_y / w)² − heading · (e_ψ / (π/4))²``

    and ``− crash`` on the step that leaves the road or hits a carton (weights in
    ``RewardWeights``: 1, 0.5, 0.5, 10). Driving centred at cruise speed earns ≈ 1 per step.

    ## Starting State
    The right lane's centre at an arc length drawn uniformly around the loop (0.5 m
    after the start on an open track), ± 0.05 m sideways and ± 0.05 rad in heading
    (uniform), at the cruise speed with straight wheels; never touching a carton.
    ``reset(options=...)`` overrides: ``track`` (name, seed or ``Track``), ``start``
    ``(s_m, lateral_m, heading_error_rad)`` with ``lateral_m`` from the centre line (on the
    road: ``|lateral_m| ≤ track.half_road_m``), ``s_m`` on an open track or within a lap
    of a closed one's start line, ``|heading_error_rad| ≤ π`` (``Track.check_place``),
    ``speed_m_s``, ``domain_randomization`` (bool) and ``faults`` (a schedule of
    ``tfalda_sim.faults``, in seconds and metres: blackout, overexposure, glare, camera
    shake, lateral kick, marking gap, latency spike, burst of dropped frames, wet patch,
    servo offset). Unknown keys raise ``ValueError``.

    ## Episode End
    Terminated when the centre of the car leaves the road (beyond a side line's outer
    edge) or the car touches a carton. Truncated after ``max_laps`` laps (if set) or at
    the end of an open track; ``gymnasium.make`` adds the step limit (3000 steps by
    default, 60 s at the thesis camera's 50 frames/s; ``max_episode_steps=…``).

    ## Info
    ``cross_track_m``, ``heading_error_rad``, ``s_m``, ``lap`` (completed laps),
    ``distance_m`` (progress since reset), ``speed_m_s``, ``steer_rad``, ``off_road``,
    ``collision``, ``lis_fault_count``, ``roi_reset`` (this step), ``roi_resets`` (since
    reset), ``detector_hit_rate`` (the thesis' hit rate of the four lanes, from the track
    geometry: ``tfalda_sim.evaluation.geometric``), ``track`` (name or seed).

    ## Arguments
    ``render_mode``: ``None`` or ``"rgb_array"`` (the camera frame in colour with ROIs and
    lanes drawn, and a top-down inset). ``observation``: ``"lanes"``, ``"image"`` or
    ``"dict"`` (or an ``ObservationMode``). ``throttle``: add the motor to the action.
    ``track``: a name (``tfalda_sim.tracks.NAMED_TRACKS``), a generator seed (int ≥ 0), a ``Track``,
    or ``None`` for a new generated track each reset with a seed drawn from
    ``track_seeds``, a pair ``(low, high)`` of ints, ``0 ≤ low < high ≤ 2**63`` (the seed
    is the scenario id: train/test splits are seed ranges). ``obstacles``: keep the
    cartons of generated tracks. ``speed_m_s``: cruise speed in
    ``[vehicle.MIN_CRUISE_SPEED_M_S, car.max_speed_m_s]`` (0.05–8.3 m/s; also the
    initial speed with throttle). ``domain_randomization``: draw the photometric
    effects and the room from ``randomization`` (a ``DomainRandomization``) each reset.
    ``effects``: the ``Effects`` without randomisation. ``detector``: the
    TFALDA + LIS configuration, a ``DetectorConfig`` or a preset name: ``"thesis"`` (the
    default), ``"improved"`` or ``"without_lis"`` (``DetectorConfig``'s classmethods).
    ``camera``: the car's camera — a profile name (``"thesis"``, the default, or
    ``"reference-car"``), a profile file, or a
    ``tfalda_sim.camera.Camera`` (any lens model and image size; the observation's image
    and the step rate follow it). On a camera other than the thesis', a preset or a
    ``DetectorConfig`` with the thesis' pixel layout gets its geometry derived for the
    camera (``DetectorConfig.for_camera``); a camera that cannot see the lane is refused.
    ``car``: ``CarParams``. ``vehicle``: ``"kinematic"`` (the default: it turns as sharply
    as its wheels point at any speed), ``"dynamic"`` (the single-track car with
    magic-formula tyres that slides beyond its grip, ``tfalda_sim.dynamics``) or a
    ``DynamicsParams``. ``timing``: the pipeline's timing and the steering servo,
    ``"ideal"`` (the default: the observation of a step comes from that step's frame, a
    command acts at once), ``"real-car"`` (the thesis' car: frames two periods old, a
    servo's lag, dead band and command delay), ``"randomized"`` (a timing drawn per
    episode, for training), a JSON file, a ``tfalda_sim.timing.Timing`` or a
    ``TimingRandomization``.
    ``reward``: ``RewardWeights``. ``max_laps``: an int ≥ 0, 0 =
    no limit (floats are refused, even 2.0). ``faults``: a default fault schedule for
    every episode, a list or tuple of ``tfalda_sim.faults`` faults.

    The flags (``throttle``, ``obstacles``, ``domain_randomization``) take only ``bool``
    or ``numpy.bool_``; numbers take ``int``, ``float`` or numpy scalars, never a bool;
    ``randomization``, ``effects``, ``detector``, ``car`` and ``reward`` may be ``None``
    for the default. A wrong type raises ``TypeError``, an impossible value
    ``ValueError``; the message names the argument and shows what was given. The same
    holds for ``reset``: ``options`` is ``None`` or a mapping; ``start`` three finite
    numbers (``None``: random), ``speed_m_s`` in ``[0, car.max_speed_m_s]``, a ``track``
    of ``None`` draws a generated one.

    ## Vectorized Environment
    ``gymnasium.make_vec("TfaldaTrack-v0", num_envs=N)`` steps the envs in this process and
    one worker process per further core (``tfalda_sim.envs.vector``); it works from any
    script, guarded by ``if __name__ == "__main__":`` or not.

    ## Version History
    - v0: the first release (tfalda-sim 0.1.0): kinematic car, thesis and profile
      cameras, ``"lanes"``/``"image"``/``"dict"`` observations, faults, domain
      randomisation; rollouts bit-identical for equal seeds.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"],
                                          "render_fps": FRAME_RATE_HZ}

    def __init__(self, render_mode: str | None = None, *,
                 observation: str | ObservationMode = "lanes",
                 throttle: bool = False, track: TrackSpec = None,
                 track_seeds: tuple[int, int] = TRACK_SEEDS, obstacles: bool = False,
                 speed_m_s: float = DEFAULT_SPEED_M_S, domain_randomization: bool = False,
                 randomization: DomainRandomization | None = None,
                 effects: Effects | None = None,
                 detector: DetectorConfig | str | None = None,
                 camera: Camera | str | os.PathLike[str] = "thesis",
                 car: CarParams | None = None, reward: RewardWeights | None = None,
                 max_laps: int = 0, faults: Sequence[Fault] = (),
                 vehicle: str | DynamicsParams = "kinematic",
                 timing: str | os.PathLike[str] | Timing = "ideal") -> None:
        if render_mode is not None:
            check_choice("render_mode", render_mode, self.metadata["render_modes"],
                         optional=True)
        self.observation_mode = (
            observation if isinstance(observation, ObservationMode) else
            ObservationMode(check_choice("observation", observation,
                                         [m.value for m in ObservationMode])))
        self.render_mode = render_mode
        self.throttle = check_bool("throttle", throttle)
        self.obstacles = check_bool("obstacles", obstacles)
        self.domain_randomization = check_bool("domain_randomization", domain_randomization)
        self.track_seeds = check_seed_range("track_seeds", track_seeds, MAX_TRACK_SEED_HIGH)
        self.car = check_optional("car", car, CarParams, "a tfalda_sim.vehicle.CarParams"
                                  ) or CarParams()
        self.speed_m_s = check_real("speed_m_s", speed_m_s, MIN_CRUISE_SPEED_M_S,
                                    self.car.max_speed_m_s, unit=" m/s")
        self.max_laps = check_int("max_laps", max_laps)
        self.dynamics = resolve_vehicle(vehicle)
        self.timing = resolve_timing(timing)
        # This episode's timing (drawn per episode from a TimingRandomization).
        self.episode_timing = (self.timing if isinstance(self.timing, Timing)
                               else IDEAL_TIMING)
        if self.dynamics is not None:
            self.dynamics.vector(self.car.wheelbase_m)  # its CoG between the car's axles
        self.randomization = check_optional(
            "randomization", randomization, DomainRandomization,
            "a tfalda_sim.rendering.DomainRandomization") or DomainRandomization()
        self.effects = check_optional("effects", effects, Effects,
                                      "a tfalda_sim.rendering.Effects") or Effects()
        self.detector_config = resolve_detector(detector)
        self.reward_weights = check_optional("reward", reward, RewardWeights,
                                             "an tfalda_sim.envs.RewardWeights") or RewardWeights()
        self.default_faults = check_fault_schedule("faults", faults)
        self.track_spec = track
        # Resolved once (fails early on a bad track): a reset on the default track must
        # not generate it again.
        self._default_track = (resolve_track(track, self.obstacles) if track is not None
                               else None)

        self.camera = resolve_camera(camera)
        self.detector_config = self.detector_config.on_camera(self.camera)
        layout = self.detector_config.layout
        if (layout.image_width, layout.image_height) != (self.camera.width, self.camera.height):
            raise ValueError(f"the detector's image size {layout.image_width}×"
                             f"{layout.image_height} must be the camera's {self.camera.width}×"
                             f"{self.camera.height}: use DetectorConfig.for_camera(camera)")
        self.metadata = {**self.metadata, "render_fps": self.camera.frame_rate_hz}
        self.action_space = spaces.Box(-1.0, 1.0, (2 if self.throttle else 1,), np.float32)
        low, high = lane_vector_bounds(layout.rows)
        lanes_space = spaces.Box(low, high, dtype=np.float32)
        image_space = spaces.Box(0, 255, (self.camera.height, self.camera.width, 1), np.uint8)
        self.observation_space = {
            ObservationMode.LANES: lanes_space, ObservationMode.IMAGE: image_space,
            ObservationMode.DICT: spaces.Dict({"lanes": lanes_space, "image": image_space}),
        }[self.observation_mode]
        self._renderer: Renderer | None = None
        self._scene: Scene | None = None
        self._scene_key: tuple | None = None
        self._map: TopDownMap | None = None
        self._world: World | None = None
        self._track: Track | None = None
        self._last: ObservedFrame | None = None
        self._detector: TfaldaDetector | None = None
        self._prepared: tuple[int, Track] | None = None  # prepare_reset's (seed, track)
        self._prepared_for: dict | None = None  # … for this state of np_random
        self._prepared_scene: tuple[tuple, Scene] | None = None  # … its (key, scene)
        # The scene before a prepared one: the next prepared scene takes over its memory.
        self._spare_scene: Scene | None = None

    # ------------------------------------------------------------------ pickling
    def __getstate__(self) -> dict[str, Any]:
        # The renderer and the scene are caches (tens of MB), rebuilt from the rest.
        state = self.__dict__.copy()
        state.update(_renderer=None, _scene=None, _map=None, _prepared_scene=None,
                     _spare_scene=None, _prepared_for=None)
        if self._last is not None:  # the full image is re-rendered bit for bit on demand
            state["_last"] = replace(self._last, image=None)
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        if self._scene_key is not None:
            self._scene = self._build_scene(*self._scene_key)

    @property
    def renderer(self) -> Renderer:
        if self._renderer is None:
            self._renderer = Renderer(self.camera)
        return self._renderer

    # ------------------------------------------------------------------ reset
    def reset(self, *, seed: int | None = None, options: Mapping[str, Any] | None = None
              ) -> tuple[np.ndarray | dict[str, np.ndarray], dict[str, Any]]:
        opts = self._check_reset_options(options)  # before the env changes
        super().reset(seed=seed)
        rng = self.np_random
        spec, track = opts.spec, opts.track
        if track is None:
            spec = int(rng.integers(*self.track_seeds))
            prepared, self._prepared = self._prepared, None
            track = (prepared[1] if prepared is not None and prepared[0] == spec
                     else resolve_track(spec, self.obstacles))
        if opts.start is not None:
            self._check_start(track, opts.start)
        # info["track"]: the name, the seed, or a given track's own name (a generated
        # track's is its seed's label, seed-N).
        self._track_label = spec if isinstance(spec, str | int) else (track.name or "custom")
        faults = opts.faults
        randomize = opts.domain_randomization
        speed = opts.speed_m_s
        effects, scene_seed, self._noise_seed, fault_seed = self._draw_episode(rng, randomize)

        world = self._world
        if (world is None or world.car is not self.car
                or world.frame_dt_s != 1.0 / self.camera.frame_rate_hz
                or world.dynamics is not self.dynamics):
            self._track = None  # set below, once the world is on the track
            self._world = World(track, self.car, frame_rate_hz=self.camera.frame_rate_hz,
                                dynamics=self.dynamics)
            self._map = None
        elif self._track != track:
            # The same car in its space: cheaper than a new one. A reset interrupted inside
            # leaves no track current, so the next one puts the world on its track again.
            self._track = None
            world.set_track(track)
            self._map = None
        self._track = track
        self._faults = FaultInjector(faults, np.random.default_rng(fault_seed), self.camera)
        key = (self._faults.track(track), effects, scene_seed)
        prepared, self._prepared_scene = self._prepared_scene, None
        if key != self._scene_key:
            self._scene_key = None  # a build that fails must not leave the old scene current
            if prepared is not None and prepared[0] == key:
                # Kept as it is: the next prepared scene takes over its memory.
                self._spare_scene, self._scene = self._scene, prepared[1]
            else:
                # The old scene is ours alone (a private cache): its memory goes to the
                # new one.
                self._scene = self._build_scene(*key, reuse=self._scene)
            self._scene_key = key
        detector = getattr(self, "_detector", None)  # None: unpickled from before it
        if detector is not None and detector.config is self.detector_config:
            detector.restart()  # as a new one (tested), without building one
        else:
            self._detector = TfaldaDetector(self.detector_config)

        start = opts.start
        pose = self._start_pose(track, start, rng)
        # This episode's timing (drawn with domain randomisation) and its generator,
        # seeded from this episode's draw: an ideal timing draws nothing.
        timing_ranges = (self.timing if isinstance(self.timing, TimingRandomization) else
                         self.randomization.timing if randomize else None)
        base = self.timing if isinstance(self.timing, Timing) else IDEAL_TIMING
        self._timing_rng = (
            None if base.ideal and timing_ranges is None else
            np.random.default_rng([self._noise_seed, _TIMING_STREAM]))
        self.episode_timing = (base if timing_ranges is None else
                               timing_ranges.sample(self._timing_rng))
        self._world.servo = self.episode_timing.servo
        self._world.actuator_latency_s = self.episode_timing.actuator_latency_s
        self._world.reset(pose, speed)
        if self._world.collided:
            raise StartInCarton(f"the start pose {start} is inside a carton; choose another")
        self._step_count = 0
        self._distance_m = 0.0
        self._roi_resets = 0
        position = self._world.position()
        self._s_prev = position.s_m
        obs, frame = self._observe(self._faults.world(0, self._world))
        self._last, self._position = frame, position
        # The pipeline's results in flight (arrival time [s], observation, frame) and the
        # one the agent sees.
        self._in_flight: deque[tuple[float, Any, ObservedFrame]] = deque()
        self._delivered = (obs, frame)
        return obs, self._info(frame, position)

    def _draw_episode(self, rng: np.random.Generator, randomize: bool
                      ) -> tuple[Effects, int, int, int]:
        """What a reset draws from ``np_random`` after the track, in a fixed order (so
        that ``prepare_reset`` can draw the same on a copy): the effects, the scene's
        seed, the frames' noise seed and the faults' seed."""
        effects = self.randomization.sample(rng) if randomize else self.effects
        scene_seed = int(rng.integers(2**63)) if randomize else 0
        noise_seed = int(rng.integers(2**31))
        return effects, scene_seed, noise_seed, int(rng.integers(2**63))

    def prepare_reset(self, stop: Callable[[], bool] | None = None) -> bool:
        """Do now what the next ``reset()`` without options will do first, for a caller
        with time to spare (a vector env's lane waiting for another lane's reset), in three
        stages: generate the track it draws (a new generated track per reset, no new seed;
        ≈ 0.6 ms), build its scene (≈ 0.3 ms) on the memory of the scene before the current
        one, and paint what the first frame reads at the start pose it draws (≈ 0.3 ms).
        ``stop``, if given, is asked after each stage: True ends the preparation there
        (the spare time is over), and the next call goes on where this one ended.
        Nothing observable changes: the reset draws the same from ``np_random`` and takes
        what was prepared only if it is what it drew (else it generates and builds as
        always; a tile painted ahead holds what the frame would have painted). Holds at
        most one scene besides the current one. Returns whether anything was done."""
        if self._default_track is not None or self._np_random is None:
            return False
        state = self._np_random.bit_generator.state
        if self._prepared_for == state:
            return False  # prepared already, all stages, for this state of np_random
        # A copy of np_random to draw from as the reset will (a new bit generator given
        # the state costs a tenth of a deepcopy's ≈ 0.2 ms in context).
        bits = type(self._np_random.bit_generator)(0)
        bits.state = state
        peek = np.random.Generator(bits)
        spec = int(peek.integers(*self.track_seeds))
        if self._prepared is None or self._prepared[0] != spec:
            track = resolve_track(spec, self.obstacles)
            track.index  # noqa: B018  (the spatial index is built on first use: now)
            self._prepared = (spec, track)
            if stop is not None and stop():
                return True
        track = self._prepared[1]
        effects, scene_seed, _, fault_seed = self._draw_episode(peek,
                                                                self.domain_randomization)
        faults = FaultInjector(self.default_faults, np.random.default_rng(fault_seed),
                               self.camera)
        key = (faults.track(track), effects, scene_seed)
        if self._prepared_scene is None or self._prepared_scene[0] != key:
            spare, self._spare_scene = self._spare_scene, None
            self._prepared_scene = None  # a build that fails leaves nothing prepared
            self._prepared_scene = (key, self._build_scene(*key, reuse=spare))
            if stop is not None and stop():
                return True
        # The first frame's view, from the start pose's first draw (a reset draws again
        # only if that one is in a carton: then this paint is merely not used).
        self.renderer.prefill(self._prepared_scene[1], self._start_draw(track, peek),
                              self._first_windows())
        self._prepared_for = state  # only now: an unfinished preparation goes on later
        return True

    def _first_windows(self) -> list[tuple[int, int, int, int]]:
        """The windows [px] an episode's first frame renders: the detector's first ROIs
        (table 2.4's) in "lanes" mode, else the whole image."""
        if self.observation_mode is not ObservationMode.LANES:
            return [(0, 0, self.camera.width, self.camera.height)]
        return list(_first_roi_windows(self.detector_config.layout))

    def _check_reset_options(self, options: object) -> _ResetOptions:
        given = check_options(options)
        unknown = sorted(set(given) - set(RESET_OPTIONS), key=repr)  # keys of any type
        if unknown:
            raise ValueError(f"unknown reset option(s) {', '.join(map(show, unknown))}; "
                             f"known: {', '.join(RESET_OPTIONS)}")
        spec = given.get("track", self.track_spec)
        start = given.get("start")
        if "track" not in given:
            track = self._default_track
        else:
            track = None if spec is None else resolve_track(spec, self.obstacles)
        return _ResetOptions(
            track=track,
            spec=spec,
            start=None if start is None else check_triple(
                "start", start, "(s_m, lateral_m, heading_error_rad)"),
            speed_m_s=check_real("speed_m_s", given.get("speed_m_s", self.speed_m_s), 0.0,
                                 self.car.max_speed_m_s, unit=" m/s"),
            domain_randomization=check_bool(
                "domain_randomization",
                given.get("domain_randomization", self.domain_randomization)),
            faults=(check_fault_schedule("faults", given["faults"]) if "faults" in given
                    else self.default_faults))

    def _build_scene(self, track: Track, effects: Effects, scene_seed: int,
                     reuse: Scene | None = None) -> Scene:
        return build_scene(track, effects, np.random.default_rng(scene_seed), reuse=reuse)

    @staticmethod
    def _check_start(track: Track, start: tuple[float, float, float]) -> None:
        """A start on ``track`` (three finite floats already): ``Track.check_place``'s
        bounds."""
        track.check_place(*start, names=("start s_m", "start lateral_m",
                                         "start heading_error_rad"))

    def _start_pose(self, track: Track, start: tuple[float, float, float] | None,
                    rng: np.random.Generator) -> tuple[float, float, float]:
        if start is not None:  # checked by _check_start
            s_m, lateral_m, heading_rad = start
            x, y, h = (float(v) for v in track.pose(s_m, lateral_m))
            return x, y, h + heading_rad
        world = self._world
        assert world is not None
        for _ in range(100):
            pose = self._start_draw(track, rng)
            if not world.obstacle_shapes:  # nothing to run into: no trial placement
                return pose
            world.reset(pose)
            if not world.collided:
                return pose
        raise RuntimeError("found no start pose clear of the cartons in 100 draws")

    @staticmethod
    def _start_draw(track: Track, rng: np.random.Generator) -> tuple[float, float, float]:
        """One random start pose ``(x [m], y [m], yaw [rad])`` on ``track``: anywhere on a
        closed track (the open one's start), in the right lane, with a little lateral and
        heading noise."""
        s_m = (float(rng.uniform(0.0, track.length_m)) if track.closed
               else OPEN_TRACK_START_S_M)
        lateral = -0.5 * track.lane_width_m + float(
            rng.uniform(-START_NOISE_LATERAL_M, START_NOISE_LATERAL_M))
        heading = float(rng.uniform(-START_NOISE_HEADING_RAD, START_NOISE_HEADING_RAD))
        x, y, h = (float(v) for v in track.pose(s_m, lateral))
        return x, y, h + heading

    # ------------------------------------------------------------------ step
    def _check_action(self, action: object) -> tuple[float, ...]:
        """The action as Python floats (steering[, throttle]), checked."""
        # The common case on Python floats: numpy's abs, compare and all cost ≈ 4 µs on
        # one or two values. A NaN fails the comparison too; the checks below name what is
        # wrong.
        if (type(action) is np.ndarray and action.shape == self.action_space.shape
                and action.dtype.char in "fd"):  # float32, float64: tolist gives floats
            values = action.tolist()
            if all(-1.0 <= v <= 1.0 for v in values):
                return tuple(values)
        try:
            a = np.asarray(action)
        except (TypeError, ValueError) as exc:  # ragged lists, bytes mixed with str, …
            raise ValueError(f"action must be an array of shape {self.action_space.shape} "
                             f"of real numbers, got {show(action)} ({exc})") from None
        shape = self.action_space.shape
        if a.shape != shape:
            raise ValueError(f"action must have shape {shape} (steering"
                             f"{', throttle' if self.throttle else ''}), got {a.shape}")
        if not np.issubdtype(a.dtype, np.number) or np.issubdtype(a.dtype, np.complexfloating):
            raise ValueError(f"action must be real numbers, got dtype {a.dtype}")
        a = a.astype(np.float64)
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action must be finite, got {a.tolist()}")
        if np.any(np.abs(a) > 1.0):
            raise ValueError(f"action must lie in [-1, 1], got {a.tolist()}; clip it or scale "
                             "the policy's output (e.g. tanh)")
        return tuple(a.tolist())

    def step(self, action: np.ndarray
             ) -> tuple[np.ndarray | dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        if self._world is None:
            raise RuntimeError("call reset() before step()")
        camera_pose = self._simulate(self._check_action(action))
        obs, frame = self._deliver(camera_pose)
        new_frame = frame is not self._last
        position = self._world.position()
        progress_m = self._progress(position)
        terminated = self._is_terminated(position)
        truncated = self._is_truncated(position, terminated)
        reward = self._reward(position, progress_m, terminated)
        self._roi_resets += bool(frame.lanes.roi_reset) and new_frame
        self._last, self._position = frame, position
        return obs, reward, terminated, truncated, self._info(frame, position, new_frame)

    # The stages of a step, in data-flow order; each takes what it needs and returns what
    # it made.
    def _simulate(self, action: tuple[float, ...]) -> tuple[float, float, float]:
        """The car drives one frame (action → pymunk; a servo offset added to the
        command), then the world faults act; the camera pose of this step's frame."""
        world = self._world
        assert world is not None
        steer = action[0] * self.car.max_steer_rad
        offset = self._faults.steer_offset(self._step_count + 1)
        world.step(steer + offset if offset else steer,
                   throttle=action[1] if self.throttle else None)
        self._step_count += 1
        return self._faults.world(self._step_count, world)

    def _deliver(self, camera_pose: tuple[float, float, float]
                 ) -> tuple[np.ndarray | dict[str, np.ndarray], ObservedFrame]:
        """The observation the agent gets at this step (``timing``): this step's frame
        (ideal timing), or the newest result that has arrived — frames take
        ``camera_latency_s`` plus up to ``jitter_s`` through the pipeline, in the order
        they were taken, and a dropped frame never arrives. The delivery faults act here:
        a frame of a burst is dropped, a latency spike adds to the delay."""
        timing, faults = self.episode_timing, self._faults
        if timing.ideal and not faults.delivers:
            return self._observe(camera_pose)
        world, rng = self._world, self._timing_rng
        assert world is not None
        now = self._step_count * world.frame_dt_s
        dropped = (timing.frame_drop_probability > 0.0
                   and rng.random() < timing.frame_drop_probability)  # type: ignore[union-attr]
        lost, extra_s = faults.delivery(self._step_count)
        if not (dropped or lost):
            obs, frame = self._observe(camera_pose)
            delay = timing.camera_latency_s + extra_s + (
                rng.uniform(0.0, timing.jitter_s)  # type: ignore[union-attr]
                if timing.jitter_s > 0.0 else 0.0)
            if self._in_flight:  # one pipeline: a result never overtakes an earlier one
                delay = max(delay, self._in_flight[-1][0] - now)
            self._in_flight.append((now + delay, obs, frame))
        while self._in_flight and self._in_flight[0][0] <= now + 1e-9:
            _, obs, frame = self._in_flight.popleft()
            self._delivered = (obs, frame)
        obs, frame = self._delivered
        # An observation seen before is handed out again as a new copy (Gymnasium: the
        # user keeps what a step returned).
        if isinstance(obs, dict):
            return {key: value.copy() for key, value in obs.items()}, frame
        return obs.copy(), frame

    def _observe(self, camera_pose: tuple[float, float, float]
                 ) -> tuple[np.ndarray | dict[str, np.ndarray], ObservedFrame]:
        """Camera pose → renderer (the ROIs only in "lanes" mode) → image faults →
        TFALDA + LIS → the observation, and the frame's record."""
        world = self._world
        assert world is not None and self._scene is not None
        step = self._step_count
        frame_seed = self._noise_seed + step
        det = self._detector
        image = None
        if self.observation_mode is ObservationMode.LANES:
            wins = det.rois
            crops = self.renderer.render_windows(self._scene, camera_pose, wins,
                                                 speed_m_s=world.speed_m_s,
                                                 frame_seed=frame_seed)
            self._faults.image(step, crops, wins)
            lanes = det.process_crops(crops)
        else:
            image = self.renderer.render(self._scene, camera_pose, speed_m_s=world.speed_m_s,
                                         frame_seed=frame_seed)
            self._faults.image(step, [image], [(0, 0, image.shape[1], image.shape[0])])
            lanes = det.process(image)
        frame = ObservedFrame(lanes=lanes, camera_pose=camera_pose, step=step, image=image)
        speed, steer = world.speed_m_s, world.steer_rad
        timing = self.episode_timing
        if timing.speed_noise_m_s > 0.0 or timing.steer_noise_rad > 0.0:
            rng = self._timing_rng
            assert rng is not None
            speed += timing.speed_noise_m_s * float(rng.standard_normal())
            steer += timing.steer_noise_rad * float(rng.standard_normal())
        vector = lane_vector(lanes, image_width=self.camera.width,
                             image_height=self.camera.height,
                             fault_limit=self.detector_config.lis.fault_limit,
                             speed_ratio=speed / self.car.max_speed_m_s,
                             steer_ratio=steer / self.car.max_steer_rad)
        if self.observation_mode is ObservationMode.LANES:
            return vector, frame
        pixels = image[..., None]  # type: ignore[index]
        if self.observation_mode is ObservationMode.IMAGE:
            return pixels, frame
        return {"lanes": vector, "image": pixels}, frame

    def _progress(self, position: TrackPosition) -> float:
        """Arc length driven since the last step [m] (unwrapped over the start line)."""
        track = self._world.track  # type: ignore[union-attr]
        ds = position.s_m - self._s_prev
        if track.closed:
            ds = (ds + 0.5 * track.length_m) % track.length_m - 0.5 * track.length_m
        self._s_prev = position.s_m
        self._distance_m += ds
        return ds

    def _reward(self, position: TrackPosition, progress_m: float, terminated: bool) -> float:
        """The docstring's reward: progress, minus lateral and heading penalties, minus the
        crash penalty on the terminating step."""
        w = self.reward_weights
        track = self._world.track  # type: ignore[union-attr]
        dt = self._world.frame_dt_s  # type: ignore[union-attr]
        reward = (w.progress * progress_m / (self.speed_m_s * dt)
                  - w.lateral * (2.0 * position.cross_track_m / track.lane_width_m) ** 2
                  - w.heading * (position.heading_error_rad / (0.25 * math.pi)) ** 2)
        if terminated:
            reward -= w.crash
        return float(reward)

    def _is_terminated(self, position: TrackPosition) -> bool:
        """Off the road or into a carton."""
        return bool(position.off_road or self._world.collided)  # type: ignore[union-attr]

    def _is_truncated(self, position: TrackPosition, terminated: bool) -> bool:
        """``max_laps`` laps done, or the end of an open track (the step limit is
        Gymnasium's TimeLimit)."""
        track = self._world.track  # type: ignore[union-attr]
        return bool(not terminated and (
            (self.max_laps > 0 and self._laps() >= self.max_laps)
            or (not track.closed and position.s_m >= track.length_m - 0.3)))

    def _laps(self) -> int:
        track = self._world.track if self._world else None
        if track is None or not track.closed:
            return 0
        return max(0, math.floor(self._distance_m / track.length_m))

    def _info(self, frame: ObservedFrame, pos: TrackPosition, new_frame: bool = True
              ) -> dict[str, Any]:
        world = self._world
        assert world is not None
        lanes = frame.lanes
        hits = geometric_hit_rates(lanes.lanes, self.renderer.geometry, world.track,
                                   frame.camera_pose)
        return {
            "cross_track_m": pos.cross_track_m,
            "heading_error_rad": pos.heading_error_rad,
            "s_m": pos.s_m,
            "lap": self._laps(),
            "distance_m": self._distance_m,
            "speed_m_s": world.speed_m_s,
            "steer_rad": world.steer_rad,
            "off_road": pos.off_road,
            "collision": world.collided,
            "lis_fault_count": lanes.fault_count,
            "roi_reset": bool(lanes.roi_reset) and self._step_count > 0 and new_frame,
            "roi_resets": self._roi_resets,
            # np.mean's own sum and division, without its ~10 µs of checks on 8 values
            "detector_hit_rate": float(hits.sum()) / len(hits) if len(hits) else math.nan,
            "track": self._track_label,
        }

    # ------------------------------------------------------------------ what was seen
    @property
    def last_frame(self) -> ObservedFrame:
        """The frame of the last observation: the detector's lanes, its camera pose and
        the step it was taken at (with timing, an older step's; a frame that stays the
        newest arrived keeps its step), for recordings and diagnostics; the image with
        ``camera_frame``."""
        if self._world is None or self._last is None:
            raise RuntimeError("call reset() before last_frame")
        return self._last

    @property
    def track(self) -> Track:
        """The episode's track."""
        if self._world is None:
            raise RuntimeError("call reset() before track")
        return self._world.track

    @property
    def car_pose(self) -> tuple[float, float, float]:
        """The car's pose now: x [m], y [m], yaw [rad] in the track's frame."""
        if self._world is None:
            raise RuntimeError("call reset() before car_pose")
        return self._world.pose

    def top_view(self) -> np.ndarray:
        """The top-down map with the car where it is now, BGR uint8 (the render's inset)."""
        if self._world is None:
            raise RuntimeError("call reset() before top_view()")
        if self._map is None:
            self._map = TopDownMap.of(self._world.track, 180, self.car)
        return self._map.draw(self._world.pose)

    # ------------------------------------------------------------------ render
    def camera_frame(self) -> np.ndarray:
        """A copy of the camera's full grey frame of the last observation, (480, 752)
        uint8, faults included — what the detector saw (in "lanes" mode, where only the
        ROIs are rendered, the full frame is rendered here with the same noise)."""
        if self._world is None:
            raise RuntimeError("call reset() before camera_frame()")
        return self._full_frame().copy()

    def _full_frame(self) -> np.ndarray:
        """The last observation's full frame (rendered once in "lanes" mode), not copied."""
        assert self._world is not None and self._last is not None
        frame = self._last
        if frame.image is None:
            image = self.renderer.render(self._scene, frame.camera_pose,  # type: ignore[arg-type]
                                         speed_m_s=self._world.speed_m_s,
                                         frame_seed=self._noise_seed + frame.step)
            self._faults.image(frame.step, [image], [(0, 0, image.shape[1], image.shape[0])])
            frame.image = image
        return frame.image

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            gym.logger.warn("render() without a render_mode; create the env with "
                            "render_mode='rgb_array'")
            return None
        if self._world is None:
            raise RuntimeError("call reset() before render()")
        frame = self._full_frame()  # draw_observation copies it
        pos = self._position
        label = (seed_name(self._track_label) if isinstance(self._track_label, int)
                 else self._track_label)
        text = (f"{label}  lap {self._laps()}  e_y {pos.cross_track_m:+.3f} m  "
                f"v {self._world.speed_m_s:.2f} m/s")
        out = draw_observation(frame, self._last.lanes, text=text)
        inset = self.top_view()
        # Top right, over the walls: the ROIs and lanes stay visible.
        h, w = inset.shape[:2]
        x0 = out.shape[1] - w - 8
        out[8:8 + h, x0:x0 + w] = inset
        cv2.rectangle(out, (x0 - 1, 7), (x0 + w, 8 + h), (255, 255, 255), 1)
        return cv2.cvtColor(out, cv2.COLOR_BGR2RGB)
