"""``TfaldaTrack-v0``: keep a 1:10 car in its lane on a Carolo-Cup track, from TFALDA + LIS
lane observations or from the fisheye camera image.

One step: action → car (pymunk) → camera pose → renderer → TFALDA → LIS → observation;
the reward comes from the track geometry. Every stage lives in ``tfalda_sim`` and
``tracks``; this module only wires them together.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields, replace
from enum import Enum
from typing import Any, ClassVar

import cv2
import gymnasium as gym
import numpy as np
from gymnasium import spaces

from tfalda_sim.camera import FRAME_RATE_HZ, FisheyeCamera
from tfalda_sim.evaluation.geometric import geometric_hit_rates
from tfalda_sim.faults import (
    Blackout,
    CameraShake,
    Fault,
    Glare,
    LateralKick,
    Overexposure,
    active,
    apply_image_faults,
    check_schedule,
    with_gaps,
)
from tfalda_sim.perception import DetectorConfig, LaneObservation, TfaldaDetector
from tfalda_sim.rendering import DomainRandomization, Effects, Renderer, Scene, build_scene
from tfalda_sim.rendering.overlay import draw_observation
from tfalda_sim.rendering.topdown import TopDownMap
from tfalda_sim.vehicle import CarParams
from tfalda_sim.world import TrackPosition, World
from tracks import NAMED_TRACKS, GeneratorParams, Track, generate, load_named

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


TrackSpec = str | int | Track | None


def resolve_track(spec: TrackSpec, obstacles: bool) -> Track:
    """A track from a name (``tracks.NAMED_TRACKS``), a generator seed or a ``Track``;
    generated tracks lose their cartons unless ``obstacles``."""
    if isinstance(spec, Track):
        return spec
    if isinstance(spec, bool) or spec is None:
        raise TypeError(f"track must be a name, a seed or a Track, got {spec!r}")
    if isinstance(spec, str):
        if spec not in NAMED_TRACKS:
            raise ValueError(f"unknown track {spec!r}; use one of {', '.join(NAMED_TRACKS)}, "
                             "a generator seed (int) or a tracks.Track")
        return load_named(spec)
    if isinstance(spec, int | np.integer):
        if spec < 0:
            raise ValueError(f"track seeds are ≥ 0, got {spec}")
        track = generate(int(spec), GeneratorParams())
        return track if obstacles else replace(track, obstacles=())
    raise TypeError(f"track must be a name, a seed or a Track, got {type(spec).__name__}")


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
      normalised; every index is documented in ``envs.observation`` (lane ends of the
      four ROIs, ROI positions, LIS flags, lane widths, fault counter, reset, driving
      state, speed and steering feedback).
    - ``"image"``: ``Box(0, 255, (480, 752, 1), uint8)``, the grayscale camera frame.
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
    ``(s_m, lateral_m, heading_error_rad)`` with ``lateral_m`` from the centre line,
    ``speed_m_s``, ``domain_randomization`` (bool) and ``faults`` (a schedule of
    ``tfalda_sim.faults``: blackout, overexposure, glare, camera shake, lateral kick,
    marking gap). Unknown keys raise ``ValueError``.

    ## Episode End
    Terminated when the centre of the car leaves the road (beyond a side line's outer
    edge) or the car touches a carton. Truncated after ``max_laps`` laps (if set) or at
    the end of an open track; ``gymnasium.make`` adds the step limit (3000 steps = 60 s
    by default, ``max_episode_steps=…``).

    ## Info
    ``cross_track_m``, ``heading_error_rad``, ``s_m``, ``lap`` (completed laps),
    ``distance_m`` (progress since reset), ``speed_m_s``, ``steer_rad``, ``off_road``,
    ``collision``, ``lis_fault_count``, ``lis_reset`` (this step), ``lis_resets`` (since
    reset), ``detector_hit_rate`` (the thesis' hit rate of the four lanes, from the track
    geometry: ``tfalda_sim.evaluation.geometric``), ``track`` (name or seed).

    ## Arguments
    ``render_mode``: ``None`` or ``"rgb_array"`` (the camera frame in colour with ROIs and
    lanes drawn, and a top-down inset). ``observation``: ``"lanes"``, ``"image"`` or
    ``"dict"``. ``throttle``: add the motor to the action. ``track``: a name
    (``tracks.NAMED_TRACKS``), a generator seed, a ``Track``, or ``None`` for a new
    generated track each reset with a seed drawn from ``track_seeds`` (the seed is the
    scenario id: train/test splits are seed ranges). ``obstacles``: keep the cartons of
    generated tracks. ``speed_m_s``: cruise speed (also the initial speed with
    throttle). ``domain_randomization``: draw the photometric effects and the room from
    ``randomization`` each reset. ``effects``: the effects without randomisation.
    ``detector``: the TFALDA + LIS configuration (default: the thesis').
    ``car``: ``CarParams``. ``reward``: ``RewardWeights``. ``max_laps``: 0 = no limit.
    ``faults``: a default fault schedule for every episode.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"],
                                          "render_fps": FRAME_RATE_HZ}

    def __init__(self, render_mode: str | None = None, *, observation: str = "lanes",
                 throttle: bool = False, track: TrackSpec = None,
                 track_seeds: tuple[int, int] = TRACK_SEEDS, obstacles: bool = False,
                 speed_m_s: float = DEFAULT_SPEED_M_S, domain_randomization: bool = False,
                 randomization: DomainRandomization | None = None,
                 effects: Effects | None = None, detector: DetectorConfig | None = None,
                 car: CarParams | None = None, reward: RewardWeights | None = None,
                 max_laps: int = 0, faults: Sequence[Fault] = ()) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"unknown render_mode {render_mode!r}; use None or 'rgb_array'")
        try:
            self.observation_mode = ObservationMode(observation)
        except ValueError:
            raise ValueError(f"unknown observation {observation!r}; use one of "
                             f"{', '.join(m.value for m in ObservationMode)}") from None
        lo, hi = track_seeds
        if not (isinstance(lo, int) and isinstance(hi, int) and 0 <= lo < hi):
            raise ValueError(f"track_seeds must be a range (low, high) of ints with "
                             f"0 ≤ low < high, got {track_seeds}")
        self.car = car or CarParams()
        if not (math.isfinite(speed_m_s) and 0 < speed_m_s <= self.car.max_speed_m_s):
            raise ValueError(f"speed_m_s must be in (0, {self.car.max_speed_m_s}] m/s, got "
                             f"{speed_m_s}")
        if max_laps < 0:
            raise ValueError(f"max_laps must be ≥ 0 (0: no limit), got {max_laps}")
        self.render_mode = render_mode
        self.throttle = bool(throttle)
        self.track_spec = track
        self.track_seeds = (lo, hi)
        self.obstacles = bool(obstacles)
        self.speed_m_s = float(speed_m_s)
        self.domain_randomization = bool(domain_randomization)
        self.randomization = randomization or DomainRandomization()
        self.effects = effects or Effects()
        self.detector_config = detector or DetectorConfig.thesis()
        self.reward_weights = reward or RewardWeights()
        self.max_laps = int(max_laps)
        self.default_faults = check_schedule(faults)
        if track is not None:
            resolve_track(track, self.obstacles)  # fail early on a bad track

        self.camera = FisheyeCamera.default()
        layout = self.detector_config.layout
        if (layout.image_width, layout.image_height) != (self.camera.width, self.camera.height):
            raise ValueError("the detector's image size must be the camera's 752×480")
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

    # ------------------------------------------------------------------ pickling
    def __getstate__(self) -> dict[str, Any]:
        # The renderer and the scene are caches (tens of MB), rebuilt from the rest.
        state = self.__dict__.copy()
        state.update(_renderer=None, _scene=None, _map=None)
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
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = sorted(set(options) - set(RESET_OPTIONS))
        if unknown:
            raise ValueError(f"unknown reset option(s) {', '.join(map(repr, unknown))}; "
                             f"known: {', '.join(RESET_OPTIONS)}")
        rng = self.np_random
        spec = options.get("track", self.track_spec)
        if spec is None:
            spec = int(rng.integers(*self.track_seeds))
        track = resolve_track(spec, self.obstacles)
        self._track_label = spec if isinstance(spec, str | int) else "custom"
        faults = check_schedule(options.get("faults", self.default_faults))
        randomize = options.get("domain_randomization", self.domain_randomization)
        if not isinstance(randomize, bool | np.bool_):
            raise TypeError(f"domain_randomization must be a bool, got {randomize!r}")
        speed = float(options.get("speed_m_s", self.speed_m_s))
        if not (math.isfinite(speed) and 0 <= speed <= self.car.max_speed_m_s):
            raise ValueError(f"speed_m_s must be in [0, {self.car.max_speed_m_s}] m/s, got "
                             f"{speed}")
        # Everything random flows from np_random, in a fixed order.
        effects = self.randomization.sample(rng) if randomize else self.effects
        scene_seed = int(rng.integers(2**63)) if randomize else 0
        self._noise_seed = int(rng.integers(2**31))
        self._fault_rng = np.random.default_rng(int(rng.integers(2**63)))

        if self._world is None or self._track != track:
            self._world = World(track, self.car)
            self._map = None
        self._track = track
        self._faults = faults
        key = (with_gaps(track, faults), effects, scene_seed)
        if key != self._scene_key:
            self._scene = self._build_scene(*key)
            self._scene_key = key
        self._detector = TfaldaDetector(self.detector_config)

        start = options.get("start")
        pose = self._start_pose(track, start, rng)
        self._world.reset(pose, speed)
        if self._world.collided:
            raise ValueError(f"the start pose {start} is inside a carton; choose another")
        self._step_count = 0
        self._distance_m = 0.0
        self._lis_resets = 0
        self._crashed = False
        self._position = self._world.position()
        self._s_prev = self._position.s_m
        self._last_frame: np.ndarray | None = None
        obs = self._observe()
        return obs, self._info(self._position, lis_reset=False)

    def _build_scene(self, track: Track, effects: Effects, scene_seed: int) -> Scene:
        return build_scene(track, effects, np.random.default_rng(scene_seed))

    def _start_pose(self, track: Track, start: object, rng: np.random.Generator
                    ) -> tuple[float, float, float]:
        if start is not None:
            try:
                s_m, lateral_m, heading_rad = (float(v) for v in start)  # type: ignore[union-attr]
            except (TypeError, ValueError):
                raise ValueError(f"start must be (s_m, lateral_m, heading_error_rad), got "
                                 f"{start!r}") from None
            if not all(math.isfinite(v) for v in (s_m, lateral_m, heading_rad)):
                raise ValueError(f"start must be finite, got {start!r}")
            if abs(lateral_m) > track.half_road_m:
                raise ValueError(f"start lateral_m {lateral_m} is off the road (|lateral| ≤ "
                                 f"{track.half_road_m:.3f} m)")
            x, y, h = (float(v) for v in track.pose(s_m, lateral_m))
            return x, y, h + heading_rad
        centre = -0.5 * track.lane_width_m
        world = self._world
        assert world is not None
        for _ in range(100):
            s_m = (float(rng.uniform(0.0, track.length_m)) if track.closed
                   else OPEN_TRACK_START_S_M)
            lateral = centre + float(rng.uniform(-START_NOISE_LATERAL_M, START_NOISE_LATERAL_M))
            heading = float(rng.uniform(-START_NOISE_HEADING_RAD, START_NOISE_HEADING_RAD))
            x, y, h = (float(v) for v in track.pose(s_m, lateral))
            world.reset((x, y, h + heading))
            if not world.collided:
                return x, y, h + heading
        raise RuntimeError("found no start pose clear of the cartons in 100 draws")

    # ------------------------------------------------------------------ step
    def _check_action(self, action: object) -> np.ndarray:
        a = np.asarray(action)
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
        return a

    def step(self, action: np.ndarray
             ) -> tuple[np.ndarray | dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        if self._world is None:
            raise RuntimeError("call reset() before step()")
        a = self._check_action(action)
        world = self._world
        world.step(float(a[0]) * self.car.max_steer_rad,
                   throttle=float(a[1]) if self.throttle else None)
        self._step_count += 1
        for kick in active(self._faults, self._step_count, LateralKick):
            x, y, yaw = world.pose
            world.place((x - math.sin(yaw) * kick.offset_m, y + math.cos(yaw) * kick.offset_m,
                         yaw))
        obs = self._observe()
        lis_reset = bool(self._obs.reset)
        self._lis_resets += lis_reset
        pos = world.position()
        track = self._world.track
        ds = pos.s_m - self._s_prev
        if track.closed:  # unwrap over the start line
            ds = (ds + 0.5 * track.length_m) % track.length_m - 0.5 * track.length_m
        self._s_prev = pos.s_m
        self._distance_m += ds
        self._position = pos
        w = self.reward_weights
        dt = world.frame_dt_s
        reward = (w.progress * ds / (self.speed_m_s * dt)
                  - w.lateral * (2.0 * pos.cross_track_m / track.lane_width_m) ** 2
                  - w.heading * (pos.heading_error_rad / (0.25 * math.pi)) ** 2)
        terminated = pos.off_road or world.collided
        if terminated:
            reward -= w.crash
        laps = self._laps()
        truncated = not terminated and (
            (self.max_laps > 0 and laps >= self.max_laps)
            or (not track.closed and pos.s_m >= track.length_m - 0.3))
        return obs, float(reward), bool(terminated), bool(truncated), self._info(pos, lis_reset)

    def _laps(self) -> int:
        track = self._world.track if self._world else None
        if track is None or not track.closed:
            return 0
        return max(0, math.floor(self._distance_m / track.length_m))

    def _camera_pose(self) -> tuple[float, float, float]:
        x, y, yaw = self._world.pose  # type: ignore[union-attr]
        for shake in active(self._faults, self._step_count, CameraShake):
            yaw += float(self._fault_rng.uniform(-shake.amplitude_rad, shake.amplitude_rad))
        return x, y, yaw

    def _image_faults(self) -> list[Fault]:
        """The image faults acting at this step, in schedule order."""
        return active(self._faults, self._step_count, Blackout | Overexposure | Glare)

    def _observe(self) -> np.ndarray | dict[str, np.ndarray]:
        world = self._world
        assert world is not None and self._scene is not None
        pose = self._camera_pose()
        frame_seed = self._noise_seed + self._step_count
        image_faults = self._image_faults()
        det = self._detector
        frame = None
        if self.observation_mode is ObservationMode.LANES:
            wins = det.rois
            crops = self.renderer.render_windows(self._scene, pose, wins,
                                                 speed_m_s=world.speed_m_s, frame_seed=frame_seed)
            apply_image_faults(crops, wins, image_faults)
            self._obs = det.process_crops(crops)
        else:
            frame = self.renderer.render(self._scene, pose, speed_m_s=world.speed_m_s,
                                         frame_seed=frame_seed)
            apply_image_faults([frame], [(0, 0, frame.shape[1], frame.shape[0])], image_faults)
            self._obs = det.process(frame)
        self._last_frame = frame
        self._camera_at = pose
        lanes = lane_vector(self._obs, image_width=self.camera.width,
                            image_height=self.camera.height,
                            fault_limit=self.detector_config.lis.fault_limit,
                            speed_ratio=world.speed_m_s / self.car.max_speed_m_s,
                            steer_ratio=world.steer_rad / self.car.max_steer_rad)
        if self.observation_mode is ObservationMode.LANES:
            return lanes
        image = frame[..., None]  # type: ignore[index]
        if self.observation_mode is ObservationMode.IMAGE:
            return image
        return {"lanes": lanes, "image": image}

    def _info(self, pos: TrackPosition, lis_reset: bool) -> dict[str, Any]:
        world = self._world
        assert world is not None
        obs: LaneObservation = self._obs
        hits = geometric_hit_rates(obs.lanes, self.renderer.geometry, world.track,
                                   self._camera_at)
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
            "lis_fault_count": obs.fault_count,
            "lis_reset": lis_reset,
            "lis_resets": self._lis_resets,
            "detector_hit_rate": float(hits.mean()),
            "track": self._track_label,
        }

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
        assert self._world is not None
        frame = self._last_frame
        if frame is None:
            frame = self.renderer.render(self._scene, self._camera_at,  # type: ignore[arg-type]
                                         speed_m_s=self._world.speed_m_s,
                                         frame_seed=self._noise_seed + self._step_count)
            apply_image_faults([frame], [(0, 0, frame.shape[1], frame.shape[0])],
                               self._image_faults())
            self._last_frame = frame
        return frame

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            gym.logger.warn("render() without a render_mode; create the env with "
                            "render_mode='rgb_array'")
            return None
        if self._world is None:
            raise RuntimeError("call reset() before render()")
        frame = self._full_frame()  # draw_observation copies it
        pos = self._position
        text = (f"{self._track_label}  lap {self._laps()}  e_y {pos.cross_track_m:+.3f} m  "
                f"v {self._world.speed_m_s:.2f} m/s")
        out = draw_observation(frame, self._obs, text=text)
        if self._map is None:
            self._map = TopDownMap.of(self._world.track, 180, self.car)
        inset = self._map.draw(self._world.pose)
        # Top right, over the walls: the ROIs and lanes stay visible.
        h, w = inset.shape[:2]
        x0 = out.shape[1] - w - 8
        out[8:8 + h, x0:x0 + w] = inset
        cv2.rectangle(out, (x0 - 1, 7), (x0 + w, 8 + h), (255, 255, 255), 1)
        return cv2.cvtColor(out, cv2.COLOR_BGR2RGB)
