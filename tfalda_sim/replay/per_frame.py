"""A replay's per-frame results as JSON lines (``replay --per-frame F.jsonl``): one object a
frame, written as the frame is done, so the file of a replay of any length is streamed and
a Ctrl-C keeps the lines of the frames finished.

TFALDA + LIS, keys: ``frame`` (the frame's index in the recording), ``loop``, ``t_s`` (the
recording's time stamp [s], null when it has none), ``lanes`` (the four ROIs' lanes
``[x_top, y_top, x_bottom, y_bottom]`` [px], null where the ROI gave none), ``accepted``
(which lanes the LIS kept — False where it put last frame's in its place), ``fault_counter``,
``roi_reset``, ``state`` (the driving state). Hough baseline: ``frame``, ``loop``, ``t_s``
and ``segments`` (``[x1, y1, x2, y2]`` [px]).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..perception import LaneObservation
from ..perception.hough import HoughResult


def _time(t_s: float) -> float | None:
    return round(float(t_s), 6) if math.isfinite(t_s) else None


def _segment(row: np.ndarray) -> list[float] | None:
    if not np.all(np.isfinite(row)):
        return None
    return [round(float(v), 3) for v in row]


def lanes_record(index: int, loop: int, t_s: float, obs: LaneObservation) -> dict[str, Any]:
    """The JSON line of one TFALDA + LIS frame."""
    lanes = [_segment(row) for row in obs.lanes]
    return {"frame": index, "loop": loop, "t_s": _time(t_s), "lanes": lanes,
            "accepted": [bool(a) for a in obs.accepted],
            "fault_counter": int(obs.fault_count), "roi_reset": bool(obs.roi_reset),
            "state": obs.state.value}


def segments_record(index: int, loop: int, t_s: float, result: HoughResult
                    ) -> dict[str, Any]:
    """The JSON line of one Hough baseline frame."""
    return {"frame": index, "loop": loop, "t_s": _time(t_s),
            "segments": [[round(float(v), 3) for v in row] for row in result.segments]}
