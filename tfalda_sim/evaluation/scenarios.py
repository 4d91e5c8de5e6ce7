"""The thesis' test cases (section 4.1.1) and generated-track scenarios.

The seed is the scenario id: ``generated_scenario(seed)`` drives one lap of
``tfalda_sim.tracks.generate(seed)``, so evaluation splits are seed ranges.
"""

from __future__ import annotations

import dataclasses
import enum
import math
from dataclasses import dataclass

from tfalda_sim.tracks import Track, generate, load_named
from tfalda_sim.tracks.generator import GeneratorParams

from ..rendering import Effects
from .trajectory import FRAME_RATE_HZ, Trajectory, lane_length_m

THESIS_SPEED_M_S: float = 15 / 3.6
"""Speed of the thesis' recorded sequences [m/s]: 15 km/h (section 2.3.1; REFERENCE.md)."""

THESIS_START_S_M: float = 0.5
"""Arc length of the car at the first frame [m] (the named ``thesis`` track is laid out
for it: frames 0–80 straight, 81–160 curve, 161–182 straight)."""

STRAIGHT_FRAMES: int = 80
"""Frames of the thesis' straight drive (section 4.2.1)."""

CURVE_SEQ: tuple[int, int] = (80, 160)
"""First and last sequence number of the thesis' curve drive, a part of the track drive
(section 4.2.2)."""

TRACK_FRAMES: int = 183
"""Frames of the thesis' track drive (section 4.2.3, figure 4.6)."""

GENERATED_START_S_M: float = 0.0
"""Where a generated-track scenario starts [m]: at the start line."""


class ScenarioKind(enum.Enum):
    """The scenarios of ``tfalda-sim evaluate --scenario``."""

    STRAIGHT = "straight"
    CURVE = "curve"
    TRACK = "track"
    RANDOM = "random"


@dataclass(frozen=True, eq=False)
class Scenario:
    """A track, the poses to render it from, and how the frames look.

    ``first_seq`` numbers the frames as the thesis does (the curve drive starts at 80).
    The thesis' test cases exclude light disturbances and objects on the road (4.1.1):
    ``effects`` defaults to the nominal camera, and generated tracks lose their cartons.
    """

    name: str
    track: Track
    trajectory: Trajectory
    first_seq: int = 0
    effects: Effects = dataclasses.field(default_factory=Effects)
    scene_seed: int = 0
    """Seeds the scene's random layout (wall texture); frame noise is seeded per frame."""
    seed: int | None = None
    """The generated track's seed (scenario id), None for the thesis' tracks."""

    @property
    def seqs(self) -> range:
        return range(self.first_seq, self.first_seq + len(self.trajectory))


def thesis_scenario(kind: ScenarioKind, *, speed_m_s: float = THESIS_SPEED_M_S,
                    stride: int = 1, fps: float = FRAME_RATE_HZ) -> Scenario:
    """The thesis' straight (80 frames on the straight strip), curve (sequence 80–160 of
    the track drive) or track drive (183 frames on the named ``thesis`` track).

    At other speeds or strides the same sequence numbers cover a different stretch (the
    named track is laid out for 15 km/h, every frame); frames that would run past the
    track's end raise an error naming the limit."""
    if kind is ScenarioKind.STRAIGHT:
        track, first, n = load_named("straight"), 0, STRAIGHT_FRAMES
    elif kind is ScenarioKind.CURVE:
        track, first, n = load_named("thesis"), CURVE_SEQ[0], CURVE_SEQ[1] - CURVE_SEQ[0] + 1
    elif kind is ScenarioKind.TRACK:
        track, first, n = load_named("thesis"), 0, TRACK_FRAMES
    else:
        raise ValueError(f"{kind} is not a thesis scenario; use generated_scenario(seed)")
    step = speed_m_s * stride / fps
    trajectory = Trajectory.along_lane(track, n_frames=n, speed_m_s=speed_m_s, fps=fps,
                                       stride=stride, s_start_m=THESIS_START_S_M + first * step)
    return Scenario(kind.value, track, trajectory, first_seq=first)


MAX_SCENARIO_FRAMES: int = 10**6
"""Most frames of one scenario (5.5 hours of driving at 50 frames/s): its trajectory's
arrays are made up front."""


def generated_scenario(seed: int, *, params: GeneratorParams | None = None,
                       speed_m_s: float = THESIS_SPEED_M_S, stride: int = 1,
                       fps: float = FRAME_RATE_HZ, laps: float = 1.0,
                       max_frames: int | None = None) -> Scenario:
    """``laps`` laps of ``tfalda_sim.tracks.generate(seed, params)`` on the ideal line of the right
    lane from the start line, cartons removed (the thesis' test cases have no objects on
    the road); ``max_frames`` cuts the drive short."""
    if not (math.isfinite(laps) and laps > 0):
        raise ValueError(f"laps must be finite and > 0, got {laps}")
    track = generate(seed, params)
    track = track.with_elements(obstacles=())
    step = speed_m_s * stride / fps
    if not (math.isfinite(step) and step > 0):
        raise ValueError(f"speed_m_s × stride / fps must be a finite step > 0 m, got {step}")
    frames = laps * lane_length_m(track, -0.5 * track.lane_width_m) / step
    if max_frames is not None:
        frames = min(frames, max_frames)
    if frames > MAX_SCENARIO_FRAMES:  # checked before the trajectory's arrays exist
        raise ValueError(f"the drive would take {frames:.3g} frames, more than "
                         f"MAX_SCENARIO_FRAMES = {MAX_SCENARIO_FRAMES}; drive faster, fewer "
                         "laps or set max_frames")
    n = max(1, int(laps * lane_length_m(track, -0.5 * track.lane_width_m) / step))
    if max_frames is not None:
        if max_frames < 1:
            raise ValueError(f"max_frames must be ≥ 1, got {max_frames}")
        n = min(n, max_frames)
    trajectory = Trajectory.along_lane(track, n_frames=n, speed_m_s=speed_m_s, fps=fps,
                                       stride=stride, s_start_m=GENERATED_START_S_M)
    return Scenario(f"seed-{seed}", track, trajectory, scene_seed=seed, seed=seed)
