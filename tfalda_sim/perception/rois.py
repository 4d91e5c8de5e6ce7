"""Where the ROIs go: the initial layout (table 2.4), following the last lanes (listing A.6
``adjust_total``) and the driving states that look into a curve (section 2.3.2).

The thesis asks for the driving states to become explicit state objects (section 3.4.2):
``StraightState``, ``LeftCurveState``, ``RightCurveState`` and ``LaneChangeState`` each
correct one row's pair of ROIs; ``classify`` picks the state from the ROIs as listing 3.5
does, and a state forced from outside overrides it.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

from .params import (
    INITIAL_ROIS,
    LEFT_CURVE_RIGHT_ROI_X_PX,
    RIGHT_CURVE_LEFT_ROI_END_PX,
    ROI_BORDER_PX,
    ROI_EXTRA_WIDTH_PX,
    ROI_MARGIN_LEFT_PX,
    ROI_MAX_WIDTH_PX,
    ROI_MIN_WIDTH_PX,
    RoiLayout,
)
from .segment import LaneSegment

ROI_BAND_TOP_PX: int = INITIAL_ROIS[0][1]
"""Top row of the ROI band [px] (table 2.4: 260)."""
ROI_BAND_BOTTOM_PX: int = INITIAL_ROIS[2][1] + INITIAL_ROIS[2][3]
"""One past the bottom row of the ROI band [px] (table 2.4: 340 + 85 = 425)."""
ROI_ROW_GAP_PX: int = INITIAL_ROIS[2][1] - INITIAL_ROIS[0][1] - INITIAL_ROIS[0][3]
"""Rows left free between two ROI rows [px] (table 2.4: 340 − 260 − 75 = 5)."""


@dataclass(frozen=True, slots=True)
class Roi:
    """A region of interest: top-left corner ``(x, y)`` and size [px]."""

    x: int
    y: int
    width: int
    height: int

    @property
    def end(self) -> int:
        """One past the right-most column [px]."""
        return self.x + self.width

    def window(self) -> tuple[int, int, int, int]:
        return self.x, self.y, self.width, self.height


class StateKind(Enum):
    """The driving states of section 2.3.2 (and the lane change of section 5.2)."""

    STRAIGHT = "straight"
    LEFT_CURVE = "left curve"
    RIGHT_CURVE = "right curve"
    LANE_CHANGE_LEFT = "lane change left"
    LANE_CHANGE_RIGHT = "lane change right"


def row_geometry(layout: RoiLayout) -> list[tuple[int, int]]:
    """``(y, height)`` [px] of each ROI row, top to bottom. Two rows are table 2.4; more
    rows split the same band evenly, keeping its 5 px gaps."""
    if layout.rows == 2:
        return [(INITIAL_ROIS[0][1], INITIAL_ROIS[0][3]), (INITIAL_ROIS[2][1], INITIAL_ROIS[2][3])]
    pitch = (ROI_BAND_BOTTOM_PX - ROI_BAND_TOP_PX + ROI_ROW_GAP_PX) / layout.rows
    tops = [ROI_BAND_TOP_PX + round(k * pitch) for k in range(layout.rows)]
    bottoms = [*(t - ROI_ROW_GAP_PX for t in tops[1:]), ROI_BAND_BOTTOM_PX]
    return [(t, b - t) for t, b in zip(tops, bottoms, strict=True)]


def initial_rois(layout: RoiLayout) -> list[tuple[Roi, Roi]]:
    """The start-up ROIs, (left, right) per row, top to bottom: table 2.4 for two rows;
    for more rows the table's x and width interpolated (and extrapolated) in y."""
    out = []
    ul, ur, ll, lr = INITIAL_ROIS
    for y, h in row_geometry(layout):
        t = (y - ul[1]) / (ll[1] - ul[1])
        left_x = round(ul[0] + t * (ll[0] - ul[0]))
        left_w = round(ul[2] + t * (ll[2] - ul[2]))
        right_x = round(ur[0] + t * (lr[0] - ur[0]))
        right_w = round(ur[2] + t * (lr[2] - ur[2]))
        out.append((clamp(Roi(left_x, y, left_w, h), layout.image_width),
                    clamp(Roi(right_x, y, right_w, h), layout.image_width)))
    return out


def clamp(roi: Roi, image_width: int) -> Roi:
    """``roi`` kept inside the image with ``ROI_BORDER_PX`` to spare on both sides and at
    least ``ROI_MIN_WIDTH_PX`` wide (whatever the lanes did)."""
    width = min(max(roi.width, ROI_MIN_WIDTH_PX), image_width - 2 * ROI_BORDER_PX)
    x = min(max(roi.x, ROI_BORDER_PX), image_width - ROI_BORDER_PX - width)
    return Roi(x, roi.y, width, roi.height)


def follow(lane: LaneSegment, roi: Roi, image_width: int) -> Roi:
    """The next ROI over ``lane`` (listing A.6): from 50 px left of its leftmost end,
    75 px + |D| wide, the width clamped to [100, 275] and the ROI into the image."""
    x = round(min(lane.x_top, lane.x_bottom)) - ROI_MARGIN_LEFT_PX
    width = min(max(ROI_EXTRA_WIDTH_PX + round(abs(lane.d)), ROI_MIN_WIDTH_PX), ROI_MAX_WIDTH_PX)
    return clamp(Roi(x, roi.y, width, roi.height), image_width)


class StraightState:
    """Straight driving (the thesis' default state): the ROIs stay where they follow the
    lanes."""

    kind = StateKind.STRAIGHT

    def correct(self, left: Roi, right: Roi, image_width: int) -> tuple[Roi, Roi]:
        return left, right


class LeftCurveState:
    """Looking into a left curve (listing A.6): the left ROI moves left and narrows by
    half the overlap of the row's two ROIs."""

    kind = StateKind.LEFT_CURVE

    def correct(self, left: Roi, right: Roi, image_width: int) -> tuple[Roi, Roi]:
        k = max(0, left.end - right.x) // 2
        x = max(ROI_BORDER_PX, left.x - k)
        return Roi(x, left.y, max(ROI_MIN_WIDTH_PX, left.width - k), left.height), right


class RightCurveState:
    """Looking into a right curve: the right ROI moves right and narrows by half the
    overlap, the mirror of ``LeftCurveState`` as section 2.3.2 describes it. (Listing A.6
    computes the shift from the right ROI's end instead of the overlap, a slip: that
    would move it by about half its width whatever the overlap.)"""

    kind = StateKind.RIGHT_CURVE

    def correct(self, left: Roi, right: Roi, image_width: int) -> tuple[Roi, Roi]:
        k = max(0, left.end - right.x) // 2
        x = right.x + k
        width = max(ROI_MIN_WIDTH_PX, right.width - k)
        width -= max(0, x + width - (image_width - ROI_BORDER_PX))
        return left, Roi(x, right.y, width, right.height)


class LaneChangeState:
    """Changing lanes (section 5.2, an improvement; off in the thesis preset). The ROIs
    follow the lanes as on a straight; the detector hands the lines over to the new lane
    once the car crosses the line it is changing over (``crossed``)."""

    def __init__(self, to_left: bool) -> None:
        self.to_left = to_left
        self.kind = StateKind.LANE_CHANGE_LEFT if to_left else StateKind.LANE_CHANGE_RIGHT

    def correct(self, left: Roi, right: Roi, image_width: int) -> tuple[Roi, Roi]:
        return left, right

    def crossed(self, left_bottom_x: float, right_bottom_x: float, image_width: int) -> bool:
        """Whether the line being crossed has passed the image centre (lowest row)."""
        centre = 0.5 * image_width
        return left_bottom_x > centre if self.to_left else right_bottom_x < centre


DrivingState = StraightState | LeftCurveState | RightCurveState | LaneChangeState


def state_of(kind: StateKind) -> DrivingState:
    """A fresh state object of ``kind``."""
    return {StateKind.STRAIGHT: StraightState, StateKind.LEFT_CURVE: LeftCurveState,
            StateKind.RIGHT_CURVE: RightCurveState,
            StateKind.LANE_CHANGE_LEFT: lambda: LaneChangeState(True),
            StateKind.LANE_CHANGE_RIGHT: lambda: LaneChangeState(False)}[kind]()


def classify(left: Roi, right: Roi) -> DrivingState:
    """The state listing 3.5 reads off one row's ROIs: they overlap and the right one
    starts left of x = 325 → left curve; they overlap and the left one ends right of
    x = 425 → right curve (the left curve is tested first, as in the listing); else
    straight."""
    overlap = left.end > right.x
    if overlap and right.x < LEFT_CURVE_RIGHT_ROI_X_PX:
        return LeftCurveState()
    if overlap and left.end > RIGHT_CURVE_LEFT_ROI_END_PX:
        return RightCurveState()
    return StraightState()


def windows(rois: list[tuple[Roi, Roi]]) -> list[tuple[int, int, int, int]]:
    """The ROIs as ``(x, y, w, h)`` windows, row by row (top first), left before right."""
    return [roi.window() for pair in rois for roi in pair]
