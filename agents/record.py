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
from types import TracebackType
from typing import Any

import numpy as np

from tfalda_sim.camera.ros_info import camera_info_of
from tfalda_sim.envs import TfaldaTrackEnv
from tfalda_sim.recording import (
    RecordedStep,
    Recorder,
    RecordingClock,
    RecordingFormat,
    polyline_segments,
)
from tfalda_sim.rendering.truth import ego_boundaries


def run_recorder(mcap: Path | None, rosbag: Path | None, source: str
                 ) -> RunRecorder | None:
    """The recorder of ``--mcap`` or ``--rosbag`` (None without either)."""
    if mcap is None and rosbag is None:
        return None
    if mcap is not None and rosbag is not None:
        raise ValueError("--mcap and --rosbag both record the run: give one")
    if mcap is not None:
        return RunRecorder(mcap, RecordingFormat.MCAP, source)
    assert rosbag is not None
    return RunRecorder(rosbag, RecordingFormat.ROSBAG, source)


class RunRecorder:
    """Records a run into ``path`` as ``fmt``: ``step(env, info)`` after the reset and
    each step writes the observed frame when it is a new one (the recording opens at the
    first, with the env's camera as its camera_info); ``close(keep)`` as ``Recorder``'s,
    and as a context manager."""

    def __init__(self, path: Path, fmt: RecordingFormat, source: str) -> None:
        self.path, self.fmt, self.source = Path(path), fmt, source
        self.recorder: Recorder | None = None
        self._last: object = None  # the frame recorded last (a new result is a new object)
        self._clock: RecordingClock | None = None  # a recovery's episode starts at step 0

    def step(self, env: TfaldaTrackEnv, info: dict[str, Any]) -> None:
        frame = env.last_frame
        if frame is self._last:
            return  # no new result arrived: nothing the detector did
        self._last = frame
        if self.recorder is None:
            self.recorder = Recorder(self.path, self.fmt, camera_info=camera_info_of(env.camera),
                                     source=self.source)
        rate = env.camera.frame_rate_hz
        self._clock = self._clock or RecordingClock(rate)
        t_s = self._clock.time(frame.step / rate)
        obs = frame.lanes
        left, right = ego_boundaries(env.track, env.camera, frame.camera_pose)
        truth = np.vstack([polyline_segments(left), polyline_segments(right)])
        self.recorder.write(RecordedStep(
            t_s=t_s, frame=env.camera_frame(),
            lanes=obs.lanes, accepted=obs.accepted, rois=obs.rois,
            fault_counter=int(obs.fault_count), roi_reset=bool(obs.roi_reset),
            state=obs.state.value, pose=env.car_pose, speed_m_s=float(info["speed_m_s"]),
            truth_lanes=truth, cross_track_m=float(info["cross_track_m"]),
            top_view=env.top_view()))

    @property
    def frames(self) -> int:
        """Frames recorded."""
        return self.recorder.frames if self.recorder is not None else 0

    def close(self, keep: bool = True) -> None:
        if self.recorder is not None:
            self.recorder.close(keep=keep)

    def __enter__(self) -> RunRecorder:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close(keep=exc_type is None)
