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

from .params import RoiLayout
from .segment import LaneSegment


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
    """``(y, height)`` [px] of each ROI row, top to bottom. Two rows are the layout's table
    (table 2.4 on the thesis' camera); more rows split the same band evenly, keeping the
    gap between its rows (5 px in table 2.4)."""
    ul, _, ll, _ = layout.table_px
    if layout.rows == 2:
        return [(ul[1], ul[3]), (ll[1], ll[3])]
    top, bottom = ul[1], ll[1] + ll[3]
    gap = ll[1] - ul[1] - ul[3]
    pitch = (bottom - top + gap) / layout.rows
    tops = [top + round(k * pitch) for k in range(layout.rows)]
    bottoms = [*(t - gap for t in tops[1:]), bottom]
    return [(t, b - t) for t, b in zip(tops, bottoms, strict=True)]


def initial_rois(layout: RoiLayout) -> list[tuple[Roi, Roi]]:
    """The start-up ROIs, (left, right) per row, top to bottom: the layout's table for two
    rows; for more rows the table's x and width interpolated (and extrapolated) in y."""
    out = []
    ul, ur, ll, lr = layout.table_px
    for y, h in row_geometry(layout):
        t = (y - ul[1]) / (ll[1] - ul[1])
        left_x = round(ul[0] + t * (ll[0] - ul[0]))
        left_w = round(ul[2] + t * (ll[2] - ul[2]))
        right_x = round(ur[0] + t * (lr[0] - ur[0]))
        right_w = round(ur[2] + t * (lr[2] - ur[2]))
        out.append((clamp(Roi(left_x, y, left_w, h), layout),
                    clamp(Roi(right_x, y, right_w, h), layout)))
    return out


def row_lambda_scales(layout: RoiLayout) -> list[float]:
    """λ's weight divisor of each ROI row (``RoiLayout.lambda_scale`` interpolated over the
    rows' middles; 1 everywhere on the thesis' camera)."""
    upper, lower = layout.lambda_scale
    if upper == lower:
        return [upper] * layout.rows
    ul, _, ll, _ = layout.table_px
    y0, y1 = ul[1] + ul[3] / 2, ll[1] + ll[3] / 2
    return [upper + (lower - upper) * ((y + h / 2) - y0) / (y1 - y0)
            for y, h in row_geometry(layout)]


def clamp(roi: Roi, layout: RoiLayout) -> Roi:
    """``roi`` kept inside the image with ``border_px`` to spare on both sides and at
    least ``min_width_px`` wide (whatever the lanes did)."""
    return _clamped(roi.x, roi.y, roi.width, roi.height, layout)


def _clamped(x: int, y: int, width: int, height: int, layout: RoiLayout) -> Roi:
    """``clamp`` of the ROI ``(x, y, width, height)`` [px], made once."""
    border, image_width = layout.border_px, layout.image_width
    width = min(max(width, layout.min_width_px), image_width - 2 * border)
    return Roi(min(max(x, border), image_width - border - width), y, width, height)


def follow(lane: LaneSegment, roi: Roi, layout: RoiLayout) -> Roi:
    """The next ROI over ``lane`` (listing A.6): from ``margin_left_px`` (50 px) left of
    its leftmost end, ``extra_width_px`` (75 px) + |D| wide, the width clamped to
    [``min_width_px``, ``max_width_px``] ([100, 275] px) and the ROI into the image."""
    x = round(min(lane.x_top, lane.x_bottom)) - layout.margin_left_px
    width = min(max(layout.extra_width_px + round(abs(lane.d)), layout.min_width_px),
                layout.max_width_px)
    return _clamped(x, roi.y, width, roi.height, layout)  # runs per ROI and frame: one Roi


class StraightState:
    """Straight driving (the thesis' default state): the ROIs stay where they follow the
    lanes."""

    kind = StateKind.STRAIGHT

    def correct(self, left: Roi, right: Roi, layout: RoiLayout) -> tuple[Roi, Roi]:
        return left, right


class LeftCurveState:
    """Looking into a left curve (listing A.6): the left ROI moves left and narrows by
    half the overlap of the row's two ROIs."""

    kind = StateKind.LEFT_CURVE

    def correct(self, left: Roi, right: Roi, layout: RoiLayout) -> tuple[Roi, Roi]:
        k = max(0, left.end - right.x) // 2
        x = max(layout.border_px, left.x - k)
        return Roi(x, left.y, max(layout.min_width_px, left.width - k), left.height), right


class RightCurveState:
    """Looking into a right curve: the right ROI moves right and narrows by half the
    overlap, the mirror of ``LeftCurveState`` as section 2.3.2 describes it. (Listing A.6
    computes the shift from the right ROI's end instead of the overlap, a slip: that
    would move it by about half its width whatever the overlap.)"""

    kind = StateKind.RIGHT_CURVE

    def correct(self, left: Roi, right: Roi, layout: RoiLayout) -> tuple[Roi, Roi]:
        k = max(0, left.end - right.x) // 2
        x = right.x + k
        width = max(layout.min_width_px, right.width - k)
        width -= max(0, x + width - (layout.image_width - layout.border_px))
        return left, Roi(x, right.y, width, right.height)


class LaneChangeState:
    """Changing lanes (section 5.2, an improvement; off in the thesis preset). The ROIs
    follow the lanes as on a straight; the detector hands the lines over to the new lane
    once the car crosses the line it is changing over (``crossed``)."""

    def __init__(self, to_left: bool) -> None:
        self.to_left = to_left
        self.kind = StateKind.LANE_CHANGE_LEFT if to_left else StateKind.LANE_CHANGE_RIGHT

    def correct(self, left: Roi, right: Roi, layout: RoiLayout) -> tuple[Roi, Roi]:
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


def classify(left: Roi, right: Roi, layout: RoiLayout) -> DrivingState:
    """The state listing 3.5 reads off one row's ROIs: they overlap and the right one
    starts left of ``left_curve_right_roi_x_px`` (x = 325) → left curve; they overlap and
    the left one ends right of ``right_curve_left_roi_end_px`` (x = 425) → right curve (the
    left curve is tested first, as in the listing); else straight."""
    overlap = left.end > right.x
    if overlap and right.x < layout.left_curve_right_roi_x_px:
        return LeftCurveState()
    if overlap and left.end > layout.right_curve_left_roi_end_px:
        return RightCurveState()
    return StraightState()


def windows(rois: list[tuple[Roi, Roi]]) -> list[tuple[int, int, int, int]]:
    """The ROIs as ``(x, y, w, h)`` windows, row by row (top first), left before right."""
    return [roi.window() for pair in rois for roi in pair]
