"""A recording's time stamps for frames whose own times start again: a replay's next loop
over a recording, a drive's next episode after a recovery. ``RecordedStep.t_s`` must
increase; the clock keeps the frames' own spacing and starts each restart one frame
interval after the last frame."""

from __future__ import annotations

import math


class RecordingClock:
    """``time(t_s)``: the recording's time [s] of a frame whose own time is ``t_s`` (NaN:
    none — one frame interval after the last); frames ``1 / rate_hz`` apart across a
    restart."""

    def __init__(self, rate_hz: float) -> None:
        self.dt_s = 1.0 / rate_hz
        self.last_s = -math.inf
        self.offset_s = 0.0

    def time(self, t_s: float) -> float:
        if not math.isfinite(t_s):
            t = self.last_s + self.dt_s if math.isfinite(self.last_s) else 0.0
        else:
            t = self.offset_s + t_s
            if t <= self.last_s:  # the frames' own times started again
                self.offset_s = self.last_s + self.dt_s - t_s
                t = self.offset_s + t_s
        self.last_s = t
        return t
