"""A closed-loop run as a recording (``--mcap FILE`` / ``--rosbag DIR`` of ``drive`` and
``stress``): each frame the detector processed, with its lanes, the LIS state, the car's
pose and speed, the ground-truth lanes and the cross-track error.

A frame is recorded once, when its result reaches the car (``env.last_frame`` changes):
with an ideal pipeline every step, with a late one the frames in the order they were
processed, and a dropped frame — which no detector saw — not at all. So a replay of the
recording feeds the detector exactly the frames of the live run, in the same order.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from tfalda_sim.camera.ros_info import camera_info_of
from tfalda_sim.envs import TfaldaTrackEnv
from tfalda_sim.recording import RecordedStep, Recorder, RecordingFormat
from tfalda_sim.rendering.truth import frame_truth


def open_recorder(mcap: Path | None, rosbag: Path | None, env: TfaldaTrackEnv,
                  source: str) -> Recorder | None:
    """The recorder of ``--mcap`` or ``--rosbag`` (None without either), with the env's
    camera as the recording's camera_info."""
    if mcap is None and rosbag is None:
        return None
    if mcap is not None and rosbag is not None:
        raise ValueError("--mcap and --rosbag both record the run: give one")
    path, fmt = ((mcap, RecordingFormat.MCAP) if mcap is not None
                 else (rosbag, RecordingFormat.ROSBAG))
    return Recorder(path, fmt, camera_info=camera_info_of(env.camera), source=source)


def _segments(polyline: np.ndarray) -> np.ndarray:
    """(N, 2) pixels → (N − 1, 4) segments, NaN points dropped."""
    pts = polyline[np.all(np.isfinite(polyline), axis=1)]
    if len(pts) < 2:
        return np.zeros((0, 4))
    return np.hstack([pts[:-1], pts[1:]]).astype(np.float64)


class RunRecorder:
    """Feeds a ``Recorder`` from an env after each step: ``step(env, info)`` writes the
    observed frame when it is a new one."""

    def __init__(self, recorder: Recorder) -> None:
        self.recorder = recorder
        self._last: object = None  # the frame recorded last (a new result is a new object)
        self._last_t_s = -1.0
        self._offset_s = 0.0  # the episodes before this one (a recovery starts at step 0)

    def step(self, env: TfaldaTrackEnv, info: dict[str, Any]) -> None:
        frame = env.last_frame
        if frame is self._last:
            return  # no new result arrived: nothing the detector did
        self._last = frame
        rate = env.camera.frame_rate_hz
        t_s = self._offset_s + frame.step / rate
        if t_s <= self._last_t_s:  # a new episode: its steps count from 0 again
            self._offset_s = self._last_t_s + 1.0 / rate - frame.step / rate
            t_s = self._offset_s + frame.step / rate
        self._last_t_s = t_s
        obs = frame.lanes
        t = frame_truth(env.track, env.camera, frame.camera_pose)
        truth = np.vstack([_segments(t.left_boundary_px), _segments(t.right_boundary_px)])
        finite = np.all(np.isfinite(obs.lanes), axis=1)
        self.recorder.write(RecordedStep(
            t_s=t_s, frame=env.camera_frame(),
            lanes=obs.lanes, accepted=finite & ~obs.replaced, rois=obs.rois,
            fault_counter=int(obs.fault_count), roi_reset=bool(obs.roi_reset),
            state=obs.state.value, pose=env.car_pose, speed_m_s=float(info["speed_m_s"]),
            truth_lanes=truth, cross_track_m=float(info["cross_track_m"]),
            top_view=env.top_view()))
