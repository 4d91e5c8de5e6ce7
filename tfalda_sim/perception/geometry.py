"""The thesis' pixel layout as ground-plane definitions, projected through any camera.

Every pixel number of TFALDA + LIS belongs to the thesis' camera: the ROIs (table 2.4),
the lane-width limits and the rows they apply at (table 2.3), the pixel sizes of ROI
placement (listing A.6), the curve thresholds (listing 3.5), the LIS's tolerances and λ's
weights. Here each is what it covers on the road — metres ahead of the camera and left of
the car's centre line, for a car centred in the right lane of a straight (lines at
±``LANE_WIDTH_M``/2) — found by back-projecting the thesis' numbers through the thesis
camera (``FisheyeCamera.default()``, ``docs/camera-calibration.md``) and rounded to
millimetres; ``camera_geometry`` projects them through another camera
(``DetectorConfig.for_camera``).
``for_camera(thesis camera)`` gives table 2.4 within ``THESIS_AGREEMENT_PX`` (tested).

Distances are measured along the ground from the point below the camera; lateral
positions from the car's centre line, left positive [m].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..camera import Camera
from ..tracks.dimensions import LANE_WIDTH_M

Rect = tuple[int, int, int, int]
"""An image rectangle (x, y, width, height) [px]."""


THESIS_AGREEMENT_PX: float = 2.0
"""Largest difference [px] between table 2.4 / listing A.6 / listing 3.5 and their ground
definitions projected back through the thesis camera (millimetre rounding: ≤ 1 px at the
lower row's 0.9 px/mm); table 2.3's limits agree within the same, the tolerance and λ
scales within 1 %."""


class CameraGeometryError(ValueError):
    """A camera that cannot see what the detector's layout needs; the message says what."""


@dataclass(frozen=True)
class GroundRoi:
    """What one ROI covers on the road: ``near_m``–``far_m`` ahead of the camera and
    ``right_m``–``left_m`` from the car's centre line [m]. Its image ROI is the bounding
    box of that ground patch's outline; its rows are those the car's centre line has at
    the two distances (shared by the row's two ROIs)."""

    near_m: float
    far_m: float
    right_m: float
    left_m: float


GROUND_ROIS: tuple[GroundRoi, GroundRoi, GroundRoi, GroundRoi] = (
    GroundRoi(0.423, 1.159, 0.131, 0.355),    # upper-left: (195, 260, 150, 75)
    GroundRoi(0.423, 1.159, -0.256, 0.018),   # upper-right: (365, 260, 150, 75)
    GroundRoi(0.206, 0.400, 0.196, 0.475),    # lower-left: (80, 340, 180, 85)
    GroundRoi(0.206, 0.400, -0.297, -0.087),  # lower-right: (429, 340, 180, 85)
)
"""Table 2.4's ROIs on the road. The upper row sees 0.42–1.16 m ahead, the lower row
0.21–0.40 m; each left ROI holds the centre line (+0.2 m) with more room outward, each
right ROI the right line (−0.2 m) with room inward — the thesis' trapezoidal road view
(fig. 2.6) turned into ground patches."""

WIDTH_LIMITS_M: tuple[tuple[float, float], ...] = (
    (0.195, 0.954), (0.355, 0.483), (0.340, 0.463), (0.359, 0.584))
"""Table 2.3's lane-width limits (min, max) as lateral lengths [m] at the four distances
the upper ROI row's far and near end and the lower row's (``GROUND_ROIS``: 1.159, 0.423,
0.400, 0.206 m; 45–220, 200–272, 200–272 and 320–520 px there on the thesis camera)."""

WIDTH_TOLERANCE_M: tuple[float, float, float, float] = (0.0477, 0.0195, 0.0187, 0.0123)
"""The LIS's largest width change (11 px, listing 2.2) as a lateral length [m] at
the distances of ``WIDTH_LIMITS_M``. The vertical check's 5 px (listing A.4) scales the same
way."""

PLACEMENT_DISTANCE_M: float = 0.633
"""Distance [m ahead] where listing A.6's ROI sizes and listing 3.5's curve thresholds are
measured: the middle of the upper ROI row (image row 297 on the thesis camera), which the
thesis' numbers were set by (its upper ROIs look into the curve first)."""

ROI_MARGIN_LEFT_M: float = 0.124
"""Listing A.6's 50 px left of the last lane [m at ``PLACEMENT_DISTANCE_M``]."""
ROI_EXTRA_WIDTH_M: float = 0.186
"""Listing A.6's 75 px + |D| ROI width [m at ``PLACEMENT_DISTANCE_M``]."""
ROI_MIN_WIDTH_M: float = 0.248
"""Listing A.6's narrowest ROI, 100 px [m at ``PLACEMENT_DISTANCE_M``]."""
ROI_MAX_WIDTH_M: float = 0.682
"""Listing A.6's widest ROI, 275 px [m at ``PLACEMENT_DISTANCE_M``]."""
LEFT_CURVE_RIGHT_ROI_Y_M: float = 0.123
"""Listing 3.5's left-curve threshold x = 325 px as a lateral position [m left of the
centre line, at ``PLACEMENT_DISTANCE_M``]: a right ROI starting left of it looks into a
left curve."""
RIGHT_CURVE_LEFT_ROI_END_Y_M: float = -0.120
"""Listing 3.5's right-curve threshold x = 425 px [m, at ``PLACEMENT_DISTANCE_M``]."""

LAMBDA_DISTANCES_M: tuple[float, float] = (0.633, 0.282)
"""The middles of the two ROI rows [m ahead] (image rows 297 and 382 on the thesis
camera), where λ's pixel weights (Kp, Kd per px, listing 3.1) are scaled."""
LAMBDA_REFERENCE_PX_PER_M: tuple[float, float] = (403.3, 748.2)
"""Lateral pixels per metre of the thesis camera at ``LAMBDA_DISTANCES_M``: a camera with
k times as many divides Kp and Kd by k there, so a metre of offset costs λ the same."""

HALF_ROW_DEPTH: float = 0.5
"""The bonnet may hide at most this share of a ROI row's depth [m/m] (its near end is
moved up to the bonnet's edge); a camera whose bonnet hides more is refused."""

_OUTLINE_STEPS: int = 16
"""Samples per side of a ground patch's outline for its image bounding box [1]."""


# --------------------------------------------------------------------------- projection
def ground_pixels(camera: Camera, ahead_m: np.ndarray, left_m: np.ndarray) -> np.ndarray:
    """``(N, 2)`` pixels of ground points ``ahead_m`` ahead of the camera and ``left_m``
    left of the car's centre line [m]; NaN where the camera does not see them."""
    ahead = np.asarray(ahead_m, dtype=np.float64).ravel()
    left = np.asarray(left_m, dtype=np.float64).ravel()
    pts = np.column_stack([ahead + camera.mount.forward_m, left, np.zeros(len(ahead))])
    return camera.project(camera.car_to_camera(pts))


def row_at(camera: Camera, ahead_m: float) -> float:
    """Image row [px] of the car's centre line ``ahead_m`` ahead (NaN: not seen)."""
    return float(ground_pixels(camera, np.array([ahead_m]), np.array([0.0]))[0, 1])


def px_per_m(camera: Camera, ahead_m: float) -> float:
    """Lateral pixels per metre on the ground ``ahead_m`` ahead: the ego lane's two lines'
    column difference over the lane width (NaN where a line is not seen)."""
    uv = ground_pixels(camera, np.array([ahead_m, ahead_m]),
                       np.array([LANE_WIDTH_M / 2, -LANE_WIDTH_M / 2]))
    return float((uv[1, 0] - uv[0, 0]) / LANE_WIDTH_M)


def _scale(camera: Camera, ahead_m: float, what: str) -> float:
    """``px_per_m`` where ``what`` needs it, refused when the camera does not see both
    lines of the ego lane there."""
    k = px_per_m(camera, ahead_m)
    uv = ground_pixels(camera, np.array([ahead_m, ahead_m]),
                       np.array([LANE_WIDTH_M / 2, -LANE_WIDTH_M / 2]))
    if not (math.isfinite(k) and k > 0 and _seen(camera, uv).all()):
        raise CameraGeometryError(
            f"the camera does not see both lines of the ego lane {ahead_m:.2f} m ahead "
            f"(needed for {what}): its field of view is too narrow or it is turned too far "
            "sideways")
    return k


def _seen(camera: Camera, uv: np.ndarray) -> np.ndarray:
    return (np.all(np.isfinite(uv), axis=1) & (uv[:, 0] >= -0.5)
            & (uv[:, 0] <= camera.width - 0.5) & (uv[:, 1] >= -0.5)
            & (uv[:, 1] <= camera.height - 0.5))


def _patch_columns(camera: Camera, roi: GroundRoi, near_m: float) -> tuple[float, float]:
    """Image column range of a ground patch's outline (its bounding box) [px]."""
    s = np.linspace(0.0, 1.0, _OUTLINE_STEPS + 1)
    ahead = np.concatenate([np.full_like(s, near_m), np.full_like(s, roi.far_m),
                            near_m + s * (roi.far_m - near_m), near_m + s * (roi.far_m - near_m)])
    left = np.concatenate([roi.right_m + s * (roi.left_m - roi.right_m),
                           roi.right_m + s * (roi.left_m - roi.right_m),
                           np.full_like(s, roi.right_m), np.full_like(s, roi.left_m)])
    u = ground_pixels(camera, ahead, left)[:, 0]
    return float(np.nanmin(u)), float(np.nanmax(u))


# --------------------------------------------------------------------------- layout
@dataclass(frozen=True)
class CameraGeometry:
    """The pixel layout of one camera (``params.RoiLayout`` and ``params.LisConfig`` take
    it through ``DetectorConfig.for_camera``)."""

    width: int
    height: int
    table_px: tuple[Rect, Rect, Rect, Rect]
    """Initial ROIs: upper-left, upper-right, lower-left, lower-right (table 2.4's order)."""
    margin_left_px: int
    extra_width_px: int
    min_width_px: int
    max_width_px: int
    left_curve_right_roi_x_px: int
    right_curve_left_roi_end_px: int
    lambda_scale: tuple[float, float]
    width_limits_px: tuple[tuple[float, float], ...]
    width_limit_rows_px: tuple[float, float, float, float]
    tolerance_scale: tuple[float, float, float, float]
    row_distances_m: tuple[tuple[float, float], tuple[float, float]]
    """(near, far) [m ahead] each ROI row covers (the lower row's near end moved up to the
    bonnet's edge where the bonnet hides it)."""


def _row_band(camera: Camera, near_m: float, far_m: float, name: str
              ) -> tuple[int, int, float]:
    """(top row, height [px], near distance used) of a ROI row, above the bonnet."""
    top, bottom = row_at(camera, far_m), row_at(camera, near_m)
    if not math.isfinite(top) or top < -0.5:
        raise CameraGeometryError(
            f"the camera does not see the road {far_m:.2f} m ahead (the far end of the {name} "
            f"ROI row{'' if not math.isfinite(top) else f': row {top:.0f}, above the image'}):"
            " is it pitched up, or mounted upside down?")
    if not math.isfinite(bottom) or bottom > camera.height - 0.5:
        where = "below the image" if math.isfinite(bottom) else "out of view"
        raise CameraGeometryError(
            f"the camera does not see the road {near_m:.2f} m ahead (the near end of the "
            f"{name} ROI row, {where}): it looks too far up or has too narrow a view")
    return round(top), round(bottom) - round(top) + 1, near_m


def _clear_of_bonnet(camera: Camera, top: int, height: int, near_m: float, far_m: float,
                     columns: tuple[int, int], name: str) -> tuple[int, float]:
    """The row's height and near distance with its bottom above the bonnet in
    ``columns`` (half-open) [px]; refused when the bonnet hides more than half its depth."""
    edge = camera.bonnet.edge(np.arange(columns[0], columns[1]), camera.width, camera.height)
    edge = edge[np.isfinite(edge)]
    if not len(edge):  # no body in these columns
        return height, near_m
    clear = math.ceil(float(np.min(edge))) - 1  # last row above the body in these columns
    if top + height - 1 <= clear:
        return height, near_m
    # The bonnet hides the row's near end: the nearest distance still seen there.
    lo, hi = near_m, far_m
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if row_at(camera, mid) <= clear else (mid, hi)
    new_near = hi
    if (new_near - near_m) > HALF_ROW_DEPTH * (far_m - near_m) or clear - top + 1 < 2:
        raise CameraGeometryError(
            f"the car's body hides the {name} ROI row: it covers {near_m:.2f}–{far_m:.2f} m "
            f"ahead, the camera sees the road from {new_near:.2f} m on above the bonnet (row "
            f"{clear}); mount the camera higher or further forward, or check the bonnet polygon")
    return clear - top + 1, new_near


def camera_geometry(camera: Camera, border_px: int, width_tolerance_px: float
                    ) -> CameraGeometry:
    """The thesis' ground-plane layout projected through ``camera`` (once per camera);
    ROIs keep ``border_px`` from the image's sides, and the tolerance scale is relative to
    the thesis' ``width_tolerance_px``."""
    names = ("upper", "lower")
    bands = []
    for r, name in enumerate(names):
        g = GROUND_ROIS[2 * r]
        bands.append(_row_band(camera, g.near_m, g.far_m, name))
    table: list[Rect] = []
    distances = []
    for r, name in enumerate(names):
        top, height, near = bands[r]
        pair = (GROUND_ROIS[2 * r], GROUND_ROIS[2 * r + 1])
        cols = [_patch_columns(camera, g, near) for g in pair]
        lo = max(0, math.floor(min(c[0] for c in cols)))
        hi = min(camera.width, math.ceil(max(c[1] for c in cols)))
        height, near = _clear_of_bonnet(camera, top, height, near, pair[0].far_m, (lo, hi),
                                        name)
        if near != bands[r][2]:  # columns of the shortened patches
            cols = [_patch_columns(camera, g, near) for g in pair]
        distances.append((near, pair[0].far_m))
        for side, (u0, u1) in zip(("left", "right"), cols, strict=True):
            line = (1 if side == "left" else -1) * LANE_WIDTH_M / 2
            mid = 0.5 * (near + pair[0].far_m)
            uv = ground_pixels(camera, np.array([mid]), np.array([line]))
            if not _seen(camera, uv)[0]:
                raise CameraGeometryError(
                    f"the camera does not see the ego lane's {side} line {mid:.2f} m ahead "
                    f"(the {name}-{side} ROI): its field of view is too narrow or it is "
                    "turned too far sideways")
            x0 = max(border_px, round(u0))
            x1 = min(camera.width - border_px, round(u1))
            table.append((x0, top, max(1, x1 - x0), height))
    if table[0][1] + table[0][3] > table[2][1]:
        raise CameraGeometryError("the camera's two ROI rows overlap in the image (rows "
                                  f"{table[0][1]}–{table[0][1] + table[0][3]} and "
                                  f"{table[2][1]}–…): its view of the road is too flat")

    k_ref = _scale(camera, PLACEMENT_DISTANCE_M, "the ROI sizes")
    ref_uv = ground_pixels(camera, np.full(2, PLACEMENT_DISTANCE_M),
                           np.array([LEFT_CURVE_RIGHT_ROI_Y_M, RIGHT_CURVE_LEFT_ROI_END_Y_M]))
    ul, ll = table[0], table[2]
    limit_rows = (float(ul[1]), float(ul[1] + ul[3] - 1), float(ll[1]), float(ll[1] + ll[3] - 1))
    limit_dist = (distances[0][1], distances[0][0], distances[1][1], distances[1][0])
    scale_px = [_scale(camera, d, "the lane-width limits") for d in limit_dist]
    # A near end moved up to the bonnet keeps its thesis limit and tolerance in metres,
    # converted at the distance actually seen.
    limits = tuple((lo * k, hi * k) for (lo, hi), k in zip(WIDTH_LIMITS_M, scale_px, strict=True))
    tol = tuple(t * k / width_tolerance_px
                for t, k in zip(WIDTH_TOLERANCE_M, scale_px, strict=True))
    return CameraGeometry(
        width=camera.width, height=camera.height,
        table_px=(table[0], table[1], table[2], table[3]),
        margin_left_px=round(ROI_MARGIN_LEFT_M * k_ref),
        extra_width_px=round(ROI_EXTRA_WIDTH_M * k_ref),
        min_width_px=max(1, round(ROI_MIN_WIDTH_M * k_ref)),
        max_width_px=min(round(ROI_MAX_WIDTH_M * k_ref),
                         camera.width // 2 - border_px),
        left_curve_right_roi_x_px=round(ref_uv[0, 0]),
        right_curve_left_roi_end_px=round(ref_uv[1, 0]),
        lambda_scale=tuple(_scale(camera, d, "λ's weights") / k  # type: ignore[arg-type]
                           for d, k in zip(LAMBDA_DISTANCES_M, LAMBDA_REFERENCE_PX_PER_M,
                                           strict=True)),
        width_limits_px=limits, width_limit_rows_px=limit_rows,  # type: ignore[arg-type]
        tolerance_scale=tol,  # type: ignore[arg-type]
        row_distances_m=(distances[0], distances[1]),
    )


__all__ = [
    "GROUND_ROIS", "CameraGeometry", "CameraGeometryError", "GroundRoi", "camera_geometry",
    "ground_pixels", "px_per_m", "row_at",
]
