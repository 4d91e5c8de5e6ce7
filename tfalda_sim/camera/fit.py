"""Fit a camera's mount from one frame of a straight road with the rules' markings.

Geometry: a straight marking line on flat ground and the camera centre span a plane, so
the line's pixels, taken back to rays through the intrinsics, lie on a great circle of
the ray sphere with normal n. Parallel lines share their direction r (the vanishing
point): r ⟂ every n. In the plane ⟂ r, a line ``y`` [m] left of the camera seen from
height ``h`` [m] has its normal at the angle ``φ + atan(y / h)``, φ being the roll. The
dashed centre line (``y0``), the lane's right line (``y0 − w``) and the left lane's left
line (``y0 + w``), w apart (``lane_width_m``, the Carolo-Cup rules' 0.4 m by default),
give three angles for the three unknowns φ, h and y0. r and the ground normal make the
rotation (pitch, roll, yaw); h is the height; y0 − w/2 the lateral offset from the lane's
centre. With only two lines (the centre line and one neighbour) roll cannot be told from
height: it is taken as 0 and the result says so.

Markings are found by themselves: a white top-hat keeps bright structures narrower than
a marking can be (an angle × the focal length, or a share of the image diagonal when the
focal length is being fitted), off the car's body (``mask``); their pixels go back to
rays, and RANSAC finds great circles among them (inlier band and least pixels per line
scaled with the image); the largest set of circles through one vanishing point below the
camera is the road, the circle whose support has the most gaps the dashed centre line. A
list of marked pixels per line (``--points``) can replace the search. A fitted mount no
camera on a 1:10 car has (``plausible``) is refused, naming the parameter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from ..tracks.dimensions import LANE_WIDTH_M
from .models import Camera, FisheyeCamera
from .mount import SENSOR_HEIGHT_PX, SENSOR_WIDTH_PX, CameraMount
from .plausible import ImplausibleMount, check_fitted_mount

THESIS_DIAGONAL_PX: float = math.hypot(SENSOR_WIDTH_PX, SENSOR_HEIGHT_PX)
"""The thesis sensor's diagonal [px] (752×480): the search's pixel sizes below are given
for it and scale with an image's diagonal."""

MARKING_WIDTH_RAD: float = 0.25
"""Widest marking the top-hat keeps, as an angle [rad] (× the focal length: pixels): a
20 mm line seen from 0.2 m is 0.1 rad wide on the optical axis, and a wide pinhole lens
stretches it up to 1/cos² of its angle off the axis (× 2.5 at 50°) in the corners."""

MARKING_WIDTH_THESIS_PX: int = 31
"""The same on a 752×480 frame when the focal length is not known (``fit_focal``) [px],
scaled with the diagonal: 0.1 rad at a 157° lens' 310 px focal length."""

MIN_MARKING_WIDTH_PX: int = 5
"""Narrowest top-hat [px]: a narrower one keeps a line's edges, not the line."""

MIN_LINE_ROW_SHARE: float = 1.0 / 12.0
"""A great circle needs marking pixels (one per row and line) in this share of the
image's rows to count as a line [1]: 40 on a 480-row frame."""

MIN_LINE_PIXELS_FLOOR: int = 12
"""…and at least this many [px], however small the image."""

RANSAC_ITERATIONS: int = 1500
"""Pairs of marking pixels tried per line [1]."""

INLIER_THESIS_PX: float = 2.0
"""A marking pixel lies on a line when its ray is within this many pixels' angle of the
line's great circle [px at the focal length, on a 752×480 frame; scaled with the
diagonal]: a marking's middle found to a pixel, blur and sensor grow with the image."""

MIN_INLIER_PX: float = 1.5
"""…and at least this many [px]: a small image's markings are a pixel or two wide."""

RESIDUAL_OUTLIER_BANDS: float = 5.0
"""Marking pixels farther than this many inlier bands from their fitted model line are
left out of the residual [1]: they belong to other structures on the same great circle."""

MAX_SEARCH_PIXELS: int = 60000
"""Most marking pixels the line search takes [px]: a random subset beyond (bounded
work)."""

BODY_MARGIN_SHARE: float = 0.005
"""Marking pixels this close above the car's body are left out too [share of the image
height]: the top-hat's response spills a few pixels past a bright body edge."""

MAX_LINE_SHARE_ON_BODY: float = 0.5
"""A fitted line with more than this share of its pixels on the car's body is refused
[1]: a marking ends at the body's edge, it does not run over it."""

VANISHING_TOLERANCE_RAD: float = math.radians(1.0)
"""Lines are parallel on the ground when their great circles pass within this angle of a
common vanishing point [rad]."""

MAX_REACH_GAP_RAD: float = math.radians(20.0)
"""A straight road's lines are found up to near their vanishing point: the median of the
used lines' gaps — the angle between the line's pixel nearest the vanishing point and
the nearest point of its great circle the image shows — may be at most this [rad]. A
curve's lines leave their tangent's circle early (gaps of 25–40° on the oval track's
curves, 5–15° on its straights; the far left line is often lost at 15–30°)."""

MAX_ROLL_RAD: float = math.radians(30.0)
"""Largest roll the fit searches [rad] (a fit beyond ``plausible.MAX_FIT_ROLL_RAD`` is
refused after)."""

DASHED_COVERAGE: float = 0.8
"""A line whose pixels cover less than this share of its length (in bins along it) is
dashed [1]: the rules' centre line is 0.2 m dash, 0.2 m gap."""

DASHED_COVERAGE_RELATIVE: tuple[float, float] = (0.9, 0.1)
"""…or less than the first share when that is the second below every other line's [1]:
far dashes, their gaps below a bin, fill more of a line seen at a slant (a car heading
off the lane's direction)."""

LANE_WIDTH_FIT_RANGE_M: tuple[float, float] = (0.1, 1.0)
"""Lane widths (line centre to line centre) the fit takes [m]: a model car's track, from
a quarter to two and a half times the Carolo-Cup's 0.4 m."""

FOCAL_RANGE: tuple[float, float] = (0.25, 0.75)
"""``--fit-focal`` searches the equidistant focal length in this range × the image
diagonal [px / rad]: 90°–270° diagonal fields of view."""


class MountFitError(ValueError):
    """A frame the mount cannot be fitted from; the message says why. ``lines`` are the
    lines found (for an overlay), ``camera`` the refused fit's camera when it can be
    built, ``parameter`` the mount's parameter that was out of range (or None)."""

    def __init__(self, message: str, *, lines: tuple[LineFit, ...] = (),
                 camera: Camera | None = None, parameter: str | None = None,
                 lane_width_m: float = LANE_WIDTH_M) -> None:
        super().__init__(message)
        self.lines = lines
        self.camera = camera
        self.parameter = parameter
        self.lane_width_m = lane_width_m


@dataclass(frozen=True)
class LineFit:
    """One marking line found in the frame."""

    normal: np.ndarray  # unit normal of its great circle, camera frame
    pixels: np.ndarray  # (n, 2) its marking pixels [px]
    coverage: float  # share of its extent covered by pixels [1]
    role: str  # "left", "centre", "right" or "other"


@dataclass(frozen=True)
class MountFit:
    """The result: the fitted camera, the lines it used and its residual."""

    camera: Camera
    lines: tuple[LineFit, ...]
    residual_px: float
    """RMS distance of the used lines' pixels from the fitted model's lines [px]."""
    roll_fitted: bool
    """False when only two lines were found and the roll was taken as 0."""
    focal_px: float
    lane_width_m: float = LANE_WIDTH_M
    """The lane width the lines were fitted with [m]."""

    @property
    def camera_offset_m(self) -> float:
        """The camera's offset left of the right lane's centre in this frame [m] (the
        fitted mount's lateral offset: one frame cannot tell the car's place in the lane
        from the camera's on the car)."""
        return self.camera.mount.lateral_m


@dataclass(frozen=True)
class SearchScale:
    """The marking search's sizes for one image: the top-hat's width [px], the fewest
    pixels of a line [px] and the inlier band [px at the focal length]."""

    marking_width_px: int
    min_line_pixels: int
    inlier_px: float

    @classmethod
    def for_image(cls, width: int, height: int, focal_px: float | None = None
                  ) -> SearchScale:
        """The sizes for a ``width``×``height`` image [px] seen through a lens of focal
        length ``focal_px`` [px/rad] (None: not known, scaled with the diagonal)."""
        ratio = math.hypot(width, height) / THESIS_DIAGONAL_PX
        wide = (MARKING_WIDTH_THESIS_PX * ratio if focal_px is None
                else MARKING_WIDTH_RAD * focal_px)
        return cls(marking_width_px=max(MIN_MARKING_WIDTH_PX, int(round(wide)) | 1),
                   min_line_pixels=max(MIN_LINE_PIXELS_FLOOR,
                                       int(round(MIN_LINE_ROW_SHARE * height))),
                   inlier_px=max(MIN_INLIER_PX, INLIER_THESIS_PX * ratio))


def _rot_to_angles(M: np.ndarray) -> tuple[float, float, float]:
    """(pitch, roll, yaw) [rad] of M = Rz(roll) · Rx(pitch) · Ry(yaw) (``CameraMount``)."""
    pitch = math.asin(max(-1.0, min(1.0, M[2, 1])))
    yaw = math.atan2(-M[2, 0], M[2, 2])
    roll = math.atan2(-M[0, 1], M[1, 1])
    return pitch, roll, yaw


_BASE = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])


def marking_mask(frame: np.ndarray, width_px: int) -> np.ndarray:
    """``(H, W)`` bool: bright structures of ``frame`` narrower than ``width_px`` [px]
    (a white top-hat along rows and columns, thresholded by Otsu's level)."""
    k = cv2.getStructuringElement(cv2.MORPH_RECT, (width_px, 1))
    hat_h = cv2.morphologyEx(frame, cv2.MORPH_TOPHAT, k)
    hat_v = cv2.morphologyEx(frame, cv2.MORPH_TOPHAT, k.T)
    hat = np.maximum(hat_h, hat_v)
    level, _ = cv2.threshold(hat, 0, 255, cv2.THRESH_BINARY | cv2.THRESH_OTSU)
    level = max(level, 25.0)  # a flat frame's Otsu level is noise
    return hat > level


def body_search_mask(body: np.ndarray) -> np.ndarray:
    """``(H, W)`` bool: the car's body (``body``, True on it) and a margin above it
    (``BODY_MARGIN_SHARE``), where the marking search takes no pixels."""
    margin = int(math.ceil(BODY_MARGIN_SHARE * body.shape[0]))
    if margin <= 0 or not body.any():
        return body.copy()
    k = np.ones((2 * margin + 1, 1), np.uint8)
    return cv2.dilate(body.astype(np.uint8), k).astype(bool)


def marking_pixels(frame: np.ndarray, width_px: int | None = None,
                   mask: np.ndarray | None = None) -> np.ndarray:
    """``(n, 2)`` pixels [px] of bright structures narrower than ``width_px`` (default:
    scaled with the image's diagonal), one per row and structure (its middle), none
    where ``mask`` is True (the car's body)."""
    if width_px is None:
        width_px = SearchScale.for_image(frame.shape[1], frame.shape[0]).marking_width_px
    mask_hat = marking_mask(frame, width_px).astype(np.int8)
    # One pixel per marking and row: the middle of each run of bright pixels (a line's
    # width would otherwise split it into two great circles, one per edge).
    padded = np.pad(mask_hat, ((0, 0), (1, 1)))
    step = np.diff(padded, axis=1)
    ys, starts = np.nonzero(step == 1)
    ye, ends = np.nonzero(step == -1)
    assert np.array_equal(ys, ye)
    keep = (ends - starts) <= width_px
    mid = 0.5 * (starts + ends - 1)
    pix = np.column_stack([mid[keep], ys[keep]]).astype(np.float64)
    if mask is not None and len(pix):
        cols = np.clip(np.rint(pix[:, 0]).astype(np.int64), 0, frame.shape[1] - 1)
        pix = pix[~mask[pix[:, 1].astype(np.int64), cols]]
    return pix


def _great_circles(rays: np.ndarray, tol_rad: float, rng: np.random.Generator,
                   min_pixels: int, max_lines: int = 8
                   ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Sequential RANSAC: (normal, inlier index) of up to ``max_lines`` great circles of
    at least ``min_pixels`` rays each."""
    remaining = np.arange(len(rays))
    found = []
    for _ in range(max_lines):
        if len(remaining) < min_pixels:
            break
        r = rays[remaining]
        i = rng.integers(0, len(r), RANSAC_ITERATIONS)
        j = rng.integers(0, len(r), RANSAC_ITERATIONS)
        n = np.cross(r[i], r[j])
        norm = np.linalg.norm(n, axis=1)
        ok = norm > 1e-3
        n = n[ok] / norm[ok, None]
        if not len(n):
            break
        counts = np.zeros(len(n), np.int64)
        for start in range(0, len(n), 100):
            counts[start:start + 100] = np.sum(np.abs(n[start:start + 100] @ r.T) < tol_rad,
                                               axis=1)
        best = n[int(np.argmax(counts))]
        inl = np.abs(r @ best) < tol_rad
        for _ in range(3):  # refine: the smallest singular vector of the inliers
            if inl.sum() < 3:
                break
            _, _, vt = np.linalg.svd(r[inl], full_matrices=False)
            best = vt[-1]
            inl = np.abs(r @ best) < tol_rad
        if inl.sum() < min_pixels:
            break
        found.append((best, remaining[inl]))
        remaining = remaining[~inl]
    return found


def _coverage(rays: np.ndarray, normal: np.ndarray, direction: np.ndarray) -> float:
    """Share of a line's extent (angle along its great circle, 1° bins) its pixels fill."""
    e1 = direction - (direction @ normal) * normal
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    ang = np.degrees(np.arctan2(rays @ e2, rays @ e1))
    lo, hi = np.percentile(ang, [2, 98])
    if hi - lo < 3.0:
        return 1.0
    bins = np.histogram(ang, bins=int(math.ceil(hi - lo)), range=(lo, hi))[0]
    return float(np.mean(bins > 0))


def _solve_roll_height(tangent_angles: np.ndarray, offsets_m: np.ndarray
                       ) -> tuple[float, float, float, float]:
    """(φ, h, y0, rms) with tan(α_i − φ) = (y0 + offsets_i) / h, α_i the normals' angles;
    h ≤ 0 (lines in an order no camera above the road sees) is returned as is."""
    def fit(phi: float) -> tuple[float, float, float]:
        t = np.tan(tangent_angles - phi)
        A = np.column_stack([np.ones_like(offsets_m), offsets_m])  # t = a + b·c_i
        sol, *_ = np.linalg.lstsq(A, t, rcond=None)
        res = float(np.sqrt(np.mean((A @ sol - t) ** 2)))
        return res, float(sol[0]), float(sol[1])

    grid = np.linspace(-MAX_ROLL_RAD, MAX_ROLL_RAD, 601)
    res = [fit(p)[0] for p in grid]
    k = int(np.argmin(res))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
    for _ in range(60):  # golden section
        m1, m2 = lo + 0.382 * (hi - lo), lo + 0.618 * (hi - lo)
        if fit(m1)[0] < fit(m2)[0]:
            hi = m2
        else:
            lo = m1
    phi = 0.5 * (lo + hi)
    rms, a, b = fit(phi)
    h = 1.0 / b if b != 0 else math.inf
    return phi, h, a * h, rms


def _check_frame(frame: np.ndarray, camera: Camera) -> None:
    if frame.ndim != 2 or frame.dtype != np.uint8:
        raise MountFitError(f"the frame must be 8-bit grey, got {frame.dtype} {frame.shape}")
    if frame.shape != (camera.height, camera.width):
        raise MountFitError(f"the frame is {frame.shape[1]}×{frame.shape[0]}, the camera's "
                            f"intrinsics are for {camera.width}×{camera.height}")


def _check_lane_width(lane_width_m: float) -> None:
    lo, hi = LANE_WIDTH_FIT_RANGE_M
    if not (math.isfinite(lane_width_m) and lo <= lane_width_m <= hi):
        raise MountFitError(f"the lane width must be {lo:g}–{hi:g} m, got {lane_width_m}")


def fit_mount(frame: np.ndarray, camera: Camera, *, points: list[np.ndarray] | None = None,
              forward_m: float | None = None, seed: int = 0,
              lane_width_m: float = LANE_WIDTH_M, mask: np.ndarray | None = None,
              pixels: np.ndarray | None = None, lateral_m: float | None = None) -> MountFit:
    """Fit ``camera``'s mount (its intrinsics kept) from ``frame``, a straight road seen by
    a car parallel to it; ``points`` (pixel arrays of the centre line, then its left and
    right neighbours, ``None`` for one not marked) replaces the marking search, ``mask``
    (``(H, W)`` bool, True on the car's body) keeps it off the body, ``pixels`` gives its
    marking pixels found already (``marking_pixels``). ``lane_width_m`` [m] is the lines'
    spacing. ``forward_m`` (the camera ahead of the rear axle) cannot be seen in one frame:
    the camera's own is kept unless given; ``lateral_m`` [m] replaces the fitted lateral
    offset (which takes the car as centred in the right lane). A mount outside
    ``plausible``'s ranges is refused (``MountFitError`` naming the parameter)."""
    _check_frame(frame, camera)
    _check_lane_width(lane_width_m)
    f_px = float(np.sqrt(camera.K[0, 0] * camera.K[1, 1]))
    scale = SearchScale.for_image(camera.width, camera.height, f_px)
    rng = np.random.default_rng(seed)
    if points is not None:
        lines = []
        for role, pts in zip(("centre", "left", "right"), points, strict=False):
            if pts is None or len(pts) == 0:
                continue
            p = np.asarray(pts, dtype=np.float64)
            if len(p) < 2:
                raise MountFitError(f"the {role} line needs at least 2 marked pixels")
            if ((p < -0.5) | (p > [camera.width - 0.5, camera.height - 0.5])).any():
                raise MountFitError(f"a marked pixel of the {role} line lies outside the "
                                    f"{camera.width}×{camera.height} frame")
            r = camera.unproject(p)
            if not np.all(np.isfinite(r)):
                raise MountFitError(f"a marked pixel of the {role} line is outside what "
                                    "the lens sees")
            lines.append((_circle_normal(r), p, role))
        if not any(role == "centre" for _, _, role in lines) or len(lines) < 2:
            raise MountFitError("--points needs the centre line and at least one neighbour")
        direction = _vanishing([n for n, _, _ in lines])
        fits = [LineFit(n, p, 1.0, role) for n, p, role in lines]
    else:
        pix = marking_pixels(frame, scale.marking_width_px, mask) if pixels is None else pixels
        if len(pix) > MAX_SEARCH_PIXELS:  # bounded work: a random subset
            pix = pix[rng.choice(len(pix), MAX_SEARCH_PIXELS, replace=False)]
        if len(pix) < 2 * scale.min_line_pixels:
            raise MountFitError("no markings found in the frame: it needs two parallel lines "
                                "of a straight road (the dashed centre line and a solid line)"
                                + (" off the car's body" if mask is not None and mask.any()
                                   else ""))
        rays = camera.unproject(pix)
        ok = np.all(np.isfinite(rays), axis=1)
        rays, pix = rays[ok], pix[ok]
        circles = _great_circles(rays, scale.inlier_px / f_px, rng, scale.min_line_pixels)
        fits, direction = _road_lines(circles, rays, pix, scale.min_line_pixels)
        gaps = [reach_gap(camera, f, direction) for f in fits if f.role != "other"]
        if float(np.median(gaps)) > MAX_REACH_GAP_RAD:
            raise MountFitError(f"the lines end {math.degrees(float(np.median(gaps))):.0f}° "
                                "before their vanishing point: a curve, not a straight road",
                                lines=tuple(fits))
    return _finish(camera, fits, direction, forward_m, f_px, lane_width_m, scale.inlier_px,
                   lateral_m)


def road_direction(frame: np.ndarray, camera: Camera, *, mask: np.ndarray | None = None,
                   seed: int = 0) -> np.ndarray | None:
    """The road's direction (its vanishing point) in the camera frame, a unit vector, from
    the markings of ``frame`` seen through ``camera`` — two parallel lines suffice, no
    mount is fitted — or None where the frame shows no straight road."""
    _check_frame(frame, camera)
    f_px = float(np.sqrt(camera.K[0, 0] * camera.K[1, 1]))
    scale = SearchScale.for_image(camera.width, camera.height, f_px)
    rng = np.random.default_rng(seed)
    pix = marking_pixels(frame, scale.marking_width_px, mask)
    if len(pix) > MAX_SEARCH_PIXELS:
        pix = pix[rng.choice(len(pix), MAX_SEARCH_PIXELS, replace=False)]
    if len(pix) < 2 * scale.min_line_pixels:
        return None
    rays = camera.unproject(pix)
    ok = np.all(np.isfinite(rays), axis=1)
    rays, pix = rays[ok], pix[ok]
    circles = _great_circles(rays, scale.inlier_px / f_px, rng, scale.min_line_pixels)
    try:
        fits, direction = _road_lines(circles, rays, pix, scale.min_line_pixels)
    except MountFitError:
        return None
    gaps = [reach_gap(camera, f, direction) for f in fits if f.role != "other"]
    return None if float(np.median(gaps)) > MAX_REACH_GAP_RAD else direction


def reach_gap(camera: Camera, line: LineFit, direction: np.ndarray) -> float:
    """How far short of the vanishing point ``direction`` a line's pixels stop [rad]: the
    angle of its pixel nearest to it, less that of the nearest point of its great circle
    inside the image (a straight marking is seen up to where resolution ends)."""
    rays = camera.unproject(line.pixels)
    rays = rays[np.all(np.isfinite(rays), axis=1)]
    if not len(rays):
        return math.pi
    nearest = float(np.min(np.arccos(np.clip(rays @ direction, -1.0, 1.0))))
    side = np.cross(line.normal, direction)
    if float(np.mean(rays @ side)) < 0:
        side = -side
    t = np.radians(np.arange(0.0, 90.0, 0.25))
    uv = camera.project(np.outer(np.cos(t), direction) + np.outer(np.sin(t), side))
    inside = (np.all(np.isfinite(uv), axis=1) & (uv[:, 0] >= 0) & (uv[:, 1] >= 0)
              & (uv[:, 0] <= camera.width - 1) & (uv[:, 1] <= camera.height - 1))
    shown = float(t[inside].min()) if inside.any() else 0.0
    return max(0.0, nearest - shown)


def _circle_normal(rays: np.ndarray) -> np.ndarray:
    """The unit normal of the great circle through ``rays`` (least squares)."""
    _, _, vt = np.linalg.svd(rays, full_matrices=False)
    return vt[-1]


def _vanishing(normals: list[np.ndarray]) -> np.ndarray:
    """The direction ⟂ every normal (their common vanishing point), ahead (z > 0)."""
    # full_matrices: with two normals the third right-singular vector is the one ⟂ both
    _, _, vt = np.linalg.svd(np.array(normals), full_matrices=True)
    r = vt[-1]
    return r if r[2] > 0 else -r


def _road_lines(circles: list[tuple[np.ndarray, np.ndarray]], rays: np.ndarray,
                pix: np.ndarray, min_pixels: int) -> tuple[list[LineFit], np.ndarray]:
    """The circles through one forward vanishing point, with the dashed centre line and
    its nearest neighbours on each side marked."""
    found = tuple(LineFit(n, pix[idx], 1.0, "other") for n, idx in circles)
    if len(circles) < 2:
        raise MountFitError(f"found {len(circles)} straight line(s) in the frame, need two "
                            "parallel lines of a straight road (the dashed centre line and a "
                            "solid line)", lines=found)
    best: list[int] = []
    best_r = None
    for a in range(len(circles)):
        for b in range(a + 1, len(circles)):
            r = np.cross(circles[a][0], circles[b][0])
            if np.linalg.norm(r) < 1e-6:
                continue
            r /= np.linalg.norm(r)
            if r[2] < 0:
                r = -r
            members = [k for k, (n, _) in enumerate(circles)
                       if abs(n @ r) < math.sin(VANISHING_TOLERANCE_RAD)]
            size = sum(len(circles[k][1]) for k in members)
            if len(members) > len(best) or (len(members) == len(best) and best_r is not None
                                            and size > sum(len(circles[k][1]) for k in best)):
                best, best_r = members, r
    if len(best) < 2 or best_r is None:
        raise MountFitError("found no two parallel lines in the frame (no two straight "
                            "lines share a vanishing point ahead): is the road straight?",
                            lines=found)
    direction = _vanishing([circles[k][0] for k in best])
    # Below the horizon only: a great circle's other half (walls, the hall) is not the
    # road's line.
    up = _up_guess(direction)
    below = {k: circles[k][1][rays[circles[k][1]] @ up < -math.sin(math.radians(0.5))]
             for k in best}
    sel = [k for k in best if len(below[k]) >= min_pixels]
    if len(sel) < 2:
        raise MountFitError("found no two parallel lines below the horizon", lines=found)
    circles = [(n, below.get(k, idx)) for k, (n, idx) in enumerate(circles)]
    cov = {k: _coverage(rays[circles[k][1]], circles[k][0], direction) for k in sel}
    order = sorted(sel, key=lambda k: _lateral_angle(circles[k][0], direction))  # left first
    dashed = [k for k in order if cov[k] < DASHED_COVERAGE]
    if not dashed:
        most, below_others = DASHED_COVERAGE_RELATIVE
        dashed = [k for k in order if cov[k] < most
                  and all(cov[k] <= cov[j] - below_others for j in order if j != k)]
    if not dashed:
        raise MountFitError("found parallel lines but no dashed one: the fit needs the "
                            "dashed centre line in view (or give --points)",
                            lines=tuple(LineFit(circles[k][0], pix[circles[k][1]], cov[k],
                                                "other") for k in order))
    # the best supported dashed line (a short circle through a few dash pixels is
    # gappier than the centre line itself)
    centre = max(dashed, key=lambda k: len(circles[k][1]))
    i = order.index(centre)
    roles = {centre: "centre"}
    if i > 0:
        roles[order[i - 1]] = "left"
    if i + 1 < len(order):
        roles[order[i + 1]] = "right"
    fits = [LineFit(circles[k][0], pix[circles[k][1]], cov[k], roles.get(k, "other"))
            for k in order]
    return fits, direction


def _up_guess(direction: np.ndarray) -> np.ndarray:
    """Up in the camera frame for a camera with little roll: −y made ⟂ the road."""
    up = np.array([0.0, -1.0, 0.0])
    up = up - (up @ direction) * direction
    return up / np.linalg.norm(up)


def _plane_basis(direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(a, b) ⟂ the road direction: a ≈ left (−x of the camera), b = r × a ≈ up."""
    a = np.array([-1.0, 0.0, 0.0])
    a = a - (a @ direction) * direction
    a /= np.linalg.norm(a)
    return a, np.cross(direction, a)


def _lateral_angle(normal: np.ndarray, direction: np.ndarray) -> float:
    """tan of a line's normal angle in the plane ⟂ r (≈ y/h: larger is further left),
    sorted descending by callers via the sign."""
    a, b = _plane_basis(direction)
    ang = math.atan2(normal @ b, normal @ a)
    ang = (ang + math.pi / 2) % math.pi - math.pi / 2
    return -math.tan(ang)


def _offsets(lane_width_m: float) -> dict[str, float]:
    """Each role's line left of the centre line [m]."""
    return {"left": lane_width_m, "centre": 0.0, "right": -lane_width_m}


def _finish(camera: Camera, fits: list[LineFit], direction: np.ndarray,
            forward_m: float | None, f_px: float, lane_width_m: float, inlier_px: float,
            lateral_m: float | None) -> MountFit:
    used = [f for f in fits if f.role != "other"]
    offsets = _offsets(lane_width_m)
    a, b = _plane_basis(direction)
    alphas = []
    for f in used:
        ang = math.atan2(f.normal @ b, f.normal @ a)
        alphas.append((ang + math.pi / 2) % math.pi - math.pi / 2)
    alphas_arr = np.array(alphas)
    offs = np.array([offsets[f.role] for f in used])
    roll_fitted = len(used) >= 3
    if roll_fitted:
        phi, h, y0, _ = _solve_roll_height(alphas_arr, offs)
    else:
        t = np.tan(alphas_arr)
        b_ = (t[0] - t[1]) / (offs[0] - offs[1])
        phi, h = 0.0, (1.0 / b_ if b_ != 0 else math.inf)
        y0 = (t[0] - b_ * offs[0]) * h
    if not (math.isfinite(h) and h > 0):
        raise MountFitError("the lines' order does not fit a camera above the road (the "
                            "fitted height is negative): are these the lane's markings?",
                            lines=tuple(fits), parameter="height", lane_width_m=lane_width_m)
    e_lat = math.cos(phi) * a + math.sin(phi) * b
    g = -math.sin(phi) * a + math.cos(phi) * b
    # Camera-frame images of the car's axes → the mount's rotation (car → camera).
    R = np.column_stack([direction, e_lat, g])
    pitch, roll, yaw = _rot_to_angles(R @ _BASE.T)
    if not roll_fitted:
        roll = 0.0  # taken as 0, not the rotation's rounding of it
    h, y0 = float(h), float(y0)
    fitted_lateral = -(y0 - lane_width_m / 2)  # camera left of the lane centre
    forward = camera.mount.forward_m if forward_m is None else forward_m
    try:
        mount: CameraMount | None = CameraMount(
            height_m=h, forward_m=forward, lateral_m=fitted_lateral, pitch_rad=pitch,
            roll_rad=roll, yaw_rad=yaw)
    except ValueError:  # beyond even a profile's ranges: drawn without a model
        mount = None
    try:
        check_fitted_mount(h, pitch, roll, yaw)
        if abs(fitted_lateral) > lane_width_m / 2:
            side = "left" if fitted_lateral > 0 else "right"
            raise ImplausibleMount(
                "lateral", f"the camera would be {abs(fitted_lateral) * 1000:.0f} mm {side} of "
                           "the right lane's centre, outside the lane: the lines found are not "
                           "the dashed centre line and its neighbours around the car")
        if mount is None:  # a lateral offset beyond the car
            raise ImplausibleMount("lateral", f"the camera {fitted_lateral:+.2f} m off the "
                                   "lane's centre is not on a car in the lane: the lines "
                                   "found are not the road's markings")
    except ImplausibleMount as exc:
        raise MountFitError(str(exc), lines=tuple(fits), parameter=exc.parameter,
                            camera=None if mount is None else camera.replace(mount=mount),
                            lane_width_m=lane_width_m) from None
    fitted = camera.replace(mount=mount)
    residual = _residual(fitted, used, y0 + fitted_lateral, lane_width_m, inlier_px)
    if lateral_m is not None:
        fitted = fitted.with_mount(lateral_m=lateral_m)
    return MountFit(fitted, tuple(fits), residual, roll_fitted, f_px, lane_width_m)


def lines_off_body(lines: tuple[LineFit, ...], body: np.ndarray) -> None:
    """Refuse (``MountFitError``) a fit whose used line lies mostly on the car's body
    (``body``: ``(H, W)`` bool), more than ``MAX_LINE_SHARE_ON_BODY`` of its pixels."""
    h, w = body.shape
    for line in lines:
        if line.role == "other" or not len(line.pixels):
            continue
        cols = np.clip(np.rint(line.pixels[:, 0]).astype(np.int64), 0, w - 1)
        rows = np.clip(np.rint(line.pixels[:, 1]).astype(np.int64), 0, h - 1)
        share = float(np.mean(body[rows, cols]))
        if share > MAX_LINE_SHARE_ON_BODY:
            raise MountFitError(f"the {line.role} line lies on the car's body ({share:.0%} of "
                                "its pixels): the lines found are not the road's markings; "
                                "outline the body (--bonnet FILE)", lines=lines,
                                parameter="body")


def model_line_pixels(camera: Camera, centre_y_car: float, offset_m: float,
                      ahead_m: np.ndarray) -> np.ndarray:
    """``(n, 2)`` pixels of a marking line ``offset_m`` [m] left of the centre line, which
    lies ``centre_y_car`` [m] left of the car's axis and parallel to it, at ``ahead_m``
    [m] ahead of the rear axle; points the lens does not see are left out."""
    y = centre_y_car + offset_m
    uv = camera.project(camera.car_to_camera(np.column_stack(
        [ahead_m, np.full_like(ahead_m, y), np.zeros_like(ahead_m)])))
    return uv[np.all(np.isfinite(uv), axis=1)]


def residual_px(camera: Camera, lines: tuple[LineFit, ...] | list[LineFit],
                centre_y_car: float, lane_width_m: float, inlier_px: float) -> float:
    """RMS pixel distance [px] of the used lines' pixels to their model lines' images
    (the centre line ``centre_y_car`` [m] left of the car's axis); pixels farther than
    ``RESIDUAL_OUTLIER_BANDS`` × ``inlier_px`` are other structures on the same circle."""
    offsets = _offsets(lane_width_m)
    sq = []
    # from beside and behind the camera (a fisheye sees there) to far ahead [m]
    ahead = camera.mount.forward_m + np.concatenate([np.linspace(-1.0, 0.05, 1000),
                                                     np.geomspace(0.05, 40.0, 3000)])
    for f in lines:
        if f.role not in offsets:
            continue
        uv = model_line_pixels(camera, centre_y_car, offsets[f.role], ahead)
        if not len(uv):
            return math.inf
        for start in range(0, len(f.pixels), 500):
            p = f.pixels[start:start + 500]
            d2 = np.min(np.sum((p[:, None, :] - uv[None, :, :]) ** 2, axis=2), axis=1)
            sq.append(d2)
    if not sq:
        return math.inf
    d2 = np.concatenate(sq)
    d2 = d2[d2 <= (RESIDUAL_OUTLIER_BANDS * inlier_px) ** 2]
    return float(np.sqrt(np.mean(d2))) if len(d2) else math.inf


_residual = residual_px


def fit_focal(frame: np.ndarray, width: int, height: int, *, seed: int = 0,
              lane_width_m: float = LANE_WIDTH_M, mask: np.ndarray | None = None,
              lateral_m: float | None = None) -> MountFit:
    """``fit_mount`` with an equidistant fisheye whose focal length is fitted too
    (principal point at the image centre): the focal length whose lines are straightest
    on the ground (least residual), among those that give a plausible mount. The marking
    pixels are found once (the top-hat scaled with the image diagonal)."""
    _check_lane_width(lane_width_m)
    diag = math.hypot(width, height)
    pixels = marking_pixels(frame, SearchScale.for_image(width, height).marking_width_px,
                            mask)
    refusals: list[MountFitError] = []

    def attempt(f: float) -> MountFit | None:
        K = np.array([[f, 0.0, (width - 1) / 2], [0.0, f, (height - 1) / 2], [0.0, 0.0, 1.0]])
        try:
            return fit_mount(frame, FisheyeCamera(K, np.zeros(4), width=width, height=height),
                             seed=seed, lane_width_m=lane_width_m, mask=mask,
                             pixels=pixels, lateral_m=lateral_m)
        except MountFitError as exc:
            refusals.append(exc)
            return None
        except ValueError:
            return None

    lo, hi = FOCAL_RANGE[0] * diag, FOCAL_RANGE[1] * diag
    grid = np.geomspace(lo, hi, 13)
    results = [(f, attempt(f)) for f in grid]
    scored = [(r.residual_px, f) for f, r in results if r is not None]
    if not scored:
        named = [e for e in refusals if e.parameter is not None]
        if named:  # lines found, but at no focal length a camera on a car
            raise named[len(named) // 2]
        if refusals:
            raise refusals[len(refusals) // 2]
        raise MountFitError("no focal length in the searched range finds two parallel lines")
    _, f_best = min(scored)
    step = grid[1] / grid[0]
    a, b = f_best / step, f_best * step
    for _ in range(12):
        m1, m2 = a + 0.382 * (b - a), a + 0.618 * (b - a)
        r1, r2 = attempt(m1), attempt(m2)
        s1 = r1.residual_px if r1 else math.inf
        s2 = r2.residual_px if r2 else math.inf
        if s1 < s2:
            b = m2
        else:
            a = m1
    best = attempt(0.5 * (a + b))
    if best is None:
        raise MountFitError("the focal-length search lost the lines")
    return best


BONNET_SEARCH_FROM: float = 0.75
"""The car's body is searched in the lowest quarter of the frame [share of its height]."""

BONNET_DROP: float = 0.65
"""A column's body edge is where the grey level drops below this share of the road's
just above it [1]: a dark bonnet under a lit road (the rules' black road is lighter than
a car's shadowed body)."""

BONNET_MARGIN_PX: int = 3
"""The polygon is moved up by the blur's half height [px on a 480-row frame, scaled with
the height], so no body pixel is road."""

BONNET_BLUR_PX: tuple[int, int] = (9, 5)
"""The box blur before the edge search (width, height) [px on a 480-row frame, scaled
with the height]: a marking's reflection is not an edge."""

BONNET_STEP_PX: int = 3
"""The edge compares the rows this far above and below [px on a 480-row frame, scaled
with the height]."""

BONNET_VERTICES: int = 17
"""Vertices along the fitted body edge [1]."""


def _scaled(px: int, height: int) -> int:
    """``px`` [px on a 480-row frame] for a ``height``-row frame, at least 1."""
    return max(1, int(round(px * height / SENSOR_HEIGHT_PX)))


def detect_bonnet(frame: np.ndarray) -> np.ndarray:
    """``(n, 2)`` polygon [px] of the car's body at the bottom of ``frame``: per column the
    first strong darkening in the lowest quarter, a smooth curve fitted through them,
    closed along the bottom border."""
    h, w = frame.shape
    bw, bh = BONNET_BLUR_PX
    blur = cv2.blur(frame.astype(np.float32), (_scaled(bw, h) | 1, _scaled(bh, h) | 1))
    d = _scaled(BONNET_STEP_PX, h)
    start = int(BONNET_SEARCH_FROM * h)
    above, below = blur[start - d:h - 2 * d], blur[start + d:h]
    drop = (below < BONNET_DROP * above) & (above > 8.0)
    has = drop.any(axis=0)
    if has.sum() < w // 4:
        raise MountFitError("no car body found at the bottom of the frame: give the bonnet "
                            "polygon yourself (--bonnet FILE) or none (--bonnet none)")
    edge = (start + np.argmax(drop, axis=0)).astype(np.float64)
    cols = np.arange(w, dtype=np.float64)
    # A body's edge is smooth: a quartic in the column, fitted with the outliers (line
    # reflections, markings ending at the edge) dropped in turn.
    keep = has.copy()
    for _ in range(4):
        coef = np.polyfit(cols[keep], edge[keep], 4)
        res = edge - np.polyval(coef, cols)
        scale = max(2.0, 2.5 * float(np.median(np.abs(res[keep]))))
        keep = has & (np.abs(res) < scale)
    us = np.linspace(0, w - 1, BONNET_VERTICES)
    vs = np.clip(np.polyval(coef, us) - _scaled(BONNET_MARGIN_PX, h), 0.0, h - 1.0)
    return np.array([[0.0, h - 1.0], *np.column_stack([us, vs]), [w - 1.0, h - 1.0]])
