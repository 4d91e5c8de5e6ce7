"""A lane segment: TFALDA's straight segment through one ROI, in image coordinates [px]
(not to be confused with ``tracks.Lane``, the right or left lane of the road)."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class LaneSegment:
    """The segment from ``(p, y_top)`` to ``(p + d, y_bottom)`` [px] with its features:
    ``p`` start x on the ROI's top row, ``d`` end x − start x, ``i`` the summed gradient
    along it (in resampled gradient units) and ``lam`` the distance function's value λ
    that chose it (NaN when the first-frame rule chose it)."""

    p: float
    d: float
    i: float
    y_top: float
    y_bottom: float
    lam: float = math.nan

    @property
    def x_top(self) -> float:
        return self.p

    @property
    def x_bottom(self) -> float:
        return self.p + self.d

    def with_top(self, x_top: float) -> LaneSegment:
        """The same lane with its upper end moved to ``x_top`` and its lower end kept."""
        return LaneSegment(x_top, self.x_bottom - x_top, self.i, self.y_top, self.y_bottom,
                           self.lam)
