"""Scripted trajectories: the poses a scenario's camera frames are taken from."""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tfalda_sim.fileio import atomic_write
from tfalda_sim.tracks import Track

from ..camera import FRAME_RATE_HZ

TRAJECTORY_FORMAT = "tfalda-sim/trajectory"
"""The ``format`` tag of a trajectory file."""


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Car poses at the frames a scenario renders.

    ``poses`` (n, 3): x [m], y [m], yaw [rad] in the track frame; ``times_s`` (n,) [s];
    ``speeds_m_s`` (n,) [m/s] (for motion blur); ``s_m`` (n,) arc length along the track
    [m] where known (NaN otherwise; a hint for locating the car, never required).
    """

    poses: np.ndarray
    times_s: np.ndarray
    speeds_m_s: np.ndarray
    s_m: np.ndarray

    def __post_init__(self) -> None:
        poses = np.asarray(self.poses, np.float64)
        if poses.ndim != 2 or poses.shape[1] != 3 or len(poses) == 0:
            raise ValueError(f"poses must be (n, 3) with n ≥ 1 rows (x, y, yaw), got "
                             f"shape {poses.shape}")
        n = len(poses)
        arrays = {"times_s": self.times_s, "speeds_m_s": self.speeds_m_s, "s_m": self.s_m}
        for name, value in arrays.items():
            a = np.asarray(value, np.float64)
            if a.shape != (n,):
                raise ValueError(f"{name} must have one entry per pose ({n}), got shape {a.shape}")
            object.__setattr__(self, name, a)
        object.__setattr__(self, "poses", poses)
        if not np.all(np.isfinite(poses)) or not np.all(np.isfinite(self.times_s)):
            raise ValueError("poses and times_s must be finite")
        if np.any(np.diff(self.times_s) <= 0):
            raise ValueError("times_s must increase strictly from frame to frame")
        if not np.all(np.isfinite(self.speeds_m_s)) or np.any(self.speeds_m_s < 0):
            raise ValueError("speeds_m_s must be finite and ≥ 0")

    def __len__(self) -> int:
        return len(self.poses)

    def pose(self, k: int) -> tuple[float, float, float]:
        x, y, yaw = self.poses[k]
        return float(x), float(y), float(yaw)

    @classmethod
    def along_lane(cls, track: Track, *, n_frames: int, speed_m_s: float,
                   s_start_m: float = 0.0, lateral_m: float | None = None,
                   fps: float = FRAME_RATE_HZ, stride: int = 1) -> Trajectory:
        """The ideal line: ``n_frames`` frames along the lane centre (default: the right
        lane, ``lateral_m = -lane_width/2``) at constant speed, one frame in ``stride`` of
        a camera running at ``fps`` (stride 2: the thesis' every second frame)."""
        if n_frames < 1:
            raise ValueError(f"n_frames must be ≥ 1, got {n_frames}")
        if not (math.isfinite(speed_m_s) and speed_m_s > 0):
            raise ValueError(f"speed_m_s must be finite and > 0, got {speed_m_s}")
        if not (math.isfinite(fps) and fps > 0) or stride < 1:
            raise ValueError(f"fps must be > 0 and stride ≥ 1, got {fps} and {stride}")
        lateral = -0.5 * track.lane_width_m if lateral_m is None else lateral_m
        if abs(lateral) > track.half_road_m:
            raise ValueError(f"lateral_m = {lateral} m lies off the road (|d| ≤ "
                             f"{track.half_road_m} m)")
        dt = stride / fps
        times = np.arange(n_frames) * dt
        s = _centre_s(track, lateral, s_start_m, speed_m_s * times)
        x, y, yaw = track.pose(s, lateral)
        poses = np.column_stack([x, y, yaw])
        return cls(poses, times, np.full(n_frames, float(speed_m_s)), s)

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the trajectory as JSON (atomically: a failed write leaves no half file)."""
        path = Path(path)
        doc = {"format": TRAJECTORY_FORMAT, "version": 1,
               "frames": [{"t_s": float(t), "x_m": float(p[0]), "y_m": float(p[1]),
                           "yaw_rad": float(p[2]), "speed_m_s": float(v),
                           "s_m": None if not np.isfinite(s) else float(s)}
                          for t, p, v, s in zip(self.times_s, self.poses, self.speeds_m_s,
                                                self.s_m, strict=True)]}
        with atomic_write(path) as f:
            json.dump(doc, f)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Trajectory:
        """Read a trajectory file (e.g. a recorded drive); errors name the problem."""
        try:
            doc = json.loads(Path(path).read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
            raise ValueError(f"cannot read trajectory {path}: {e}") from e
        if not isinstance(doc, dict) or doc.get("format") != TRAJECTORY_FORMAT:
            raise ValueError(f"{path} is not a trajectory file (format must be "
                             f"{TRAJECTORY_FORMAT!r})")
        if doc.get("version") != 1:
            raise ValueError(f"{path}: unsupported trajectory version {doc.get('version')!r}")
        unknown = set(doc) - {"format", "version", "frames"}
        if unknown:
            raise ValueError(f"{path}: unknown keys {sorted(unknown)}")
        frames = doc.get("frames")
        if not isinstance(frames, list) or not frames:
            raise ValueError(f"{path}: 'frames' must be a non-empty list")
        keys = {"t_s", "x_m", "y_m", "yaw_rad", "speed_m_s", "s_m"}
        rows = []
        for k, fr in enumerate(frames):
            if not isinstance(fr, dict) or set(fr) != keys:
                raise ValueError(f"{path}: frame {k} must have exactly the keys {sorted(keys)}")
            try:
                rows.append([float(fr[key]) if fr[key] is not None else math.nan
                             for key in ("t_s", "x_m", "y_m", "yaw_rad", "speed_m_s", "s_m")])
            except (TypeError, ValueError) as e:
                raise ValueError(f"{path}: frame {k} has a non-numeric value: {e}") from e
        a = np.array(rows)
        return cls(a[:, 1:4], a[:, 0], a[:, 4], a[:, 5])


def lane_length_m(track: Track, lateral_m: float) -> float:
    """Length [m] of the line ``lateral_m`` beside the centre line, start to end (a lap)."""
    t = track.table
    return float(np.sum((1.0 - t.kappa * lateral_m) * t.length))


def _centre_s(track: Track, lateral_m: float, s_start_m: float, travelled_m: np.ndarray
              ) -> np.ndarray:
    """Centre-line arc lengths [m] at which a car that started at ``s_start_m`` has driven
    ``travelled_m`` along the line ``lateral_m`` beside the centre: an offset line is
    longer on the outside of a curve (factor 1 − κ·d per segment)."""
    t = track.table
    factor = 1.0 - t.kappa * lateral_m  # > 0: the offset stays on the road (|κ d| < 1)
    lane_s0 = np.concatenate([[0.0], np.cumsum(factor * t.length)])  # lane length at starts
    ends = np.append(t.s0, track.length_m)
    if not (0.0 <= s_start_m <= track.length_m):
        if not track.closed:
            raise ValueError(f"s_start_m = {s_start_m} m lies outside the open track's "
                             f"0–{track.length_m:.2f} m")
        s_start_m = float(np.mod(s_start_m, track.length_m))
    start = np.interp(s_start_m, ends, lane_s0)
    target = start + travelled_m
    lap = lane_s0[-1]
    if track.closed:
        target = np.mod(target, lap)
    elif target[-1] > lap + 1e-9:
        raise ValueError(f"the trajectory runs {travelled_m[-1]:.2f} m from s = "
                         f"{s_start_m:.2f} m, beyond the open track's end at "
                         f"{track.length_m:.2f} m; use fewer frames or a lower speed")
    return np.interp(target, lane_s0, ends)
