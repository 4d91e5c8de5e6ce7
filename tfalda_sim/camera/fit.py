"""Fit a camera's mount from one frame of a straight road with the rules' markings.

Geometry: a straight marking line on flat ground and the camera centre span a plane, so
the line's pixels, taken back to rays through the intrinsics, lie on a great circle of
the ray sphere with normal n. Parallel lines share their direction r (the vanishing
point): r ⟂ every n. In the plane ⟂ r, a line ``y`` [m] left of the camera seen from
height ``h`` [m] has its normal at the angle ``φ + atan(y / h)``, φ being the roll. The
dashed centre line (``y0``), the lane's right line (``y0 − w``) and the left lane's left
line (``y0 + w``), w = 0.4 m apart (Carolo-Cup rules), give three angles for the three
unknowns φ, h and y0. r and the ground normal make the rotation (pitch, roll, yaw); h is
the height; y0 − w/2 the lateral offset from the lane's centre. With only two lines (the
centre line and one neighbour) roll cannot be told from height: it is taken as 0 and the
result says so.

Markings are found by themselves: a white top-hat keeps bright structures narrower than
``MAX_MARKING_WIDTH_PX``, their pixels go back to rays, and RANSAC finds great circles
among them; the largest set of circles through one vanishing point below the camera is
the road, the circle whose support has the most gaps the dashed centre line. A list of
marked pixels per line (``--points``) can replace the search.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from ..tracks.dimensions import LANE_WIDTH_M
from .models import Camera, FisheyeCamera
from .mount import CameraMount

MAX_MARKING_WIDTH_PX: int = 31
"""Widest marking the top-hat keeps [px]: a 20 mm line seen from 0.1 m at 300 px/rad is
60 mm wide at most ~ 30 px in the near field."""

MIN_LINE_PIXELS: int = 40
"""A great circle needs this many marking pixels (one per row and line) to count as a
line [px]."""

RANSAC_ITERATIONS: int = 1500
"""Pairs of marking pixels tried per line [1]."""

INLIER_PX: float = 2.0
"""A marking pixel lies on a line when its ray is within this many pixels' angle of the
line's great circle [px, at the focal length]."""

VANISHING_TOLERANCE_RAD: float = math.radians(1.0)
"""Lines are parallel on the ground when their great circles pass within this angle of a
common vanishing point [rad]."""

RESIDUAL_OUTLIER_PX: float = 10.0
"""Marking pixels farther than this from their fitted model line are left out of the
residual [px]: they belong to other structures on the same great circle (5 × the inlier
band)."""

MAX_ROLL_RAD: float = math.radians(30.0)
"""Largest roll the fit searches [rad]."""

DASHED_COVERAGE: float = 0.8
"""A line whose pixels cover less than this share of its length (in bins along it) is
dashed [1]: the rules' centre line is 0.2 m dash, 0.2 m gap."""

FOCAL_RANGE: tuple[float, float] = (0.25, 0.75)
"""``--fit-focal`` searches the equidistant focal length in this range × the image
diagonal [px / rad]: 90°–270° diagonal fields of view."""


class MountFitError(ValueError):
    """A frame the mount cannot be fitted from; the message says why."""


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


def _rot_to_angles(M: np.ndarray) -> tuple[float, float, float]:
    """(pitch, roll, yaw) [rad] of M = Rz(roll) · Rx(pitch) · Ry(yaw) (``CameraMount``)."""
    pitch = math.asin(max(-1.0, min(1.0, M[2, 1])))
    yaw = math.atan2(-M[2, 0], M[2, 2])
    roll = math.atan2(-M[0, 1], M[1, 1])
    return pitch, roll, yaw


_BASE = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])


def marking_pixels(frame: np.ndarray) -> np.ndarray:
    """``(n, 2)`` pixels of bright structures narrower than ``MAX_MARKING_WIDTH_PX``."""
    k = cv2.getStructuringElement(cv2.MORPH_RECT, (MAX_MARKING_WIDTH_PX, 1))
    hat_h = cv2.morphologyEx(frame, cv2.MORPH_TOPHAT, k)
    hat_v = cv2.morphologyEx(frame, cv2.MORPH_TOPHAT, k.T)
    hat = np.maximum(hat_h, hat_v)
    level, _ = cv2.threshold(hat, 0, 255, cv2.THRESH_BINARY | cv2.THRESH_OTSU)
    level = max(level, 25.0)  # a flat frame's Otsu level is noise
    mask = (hat > level).astype(np.int8)
    # One pixel per marking and row: the middle of each run of bright pixels (a line's
    # width would otherwise split it into two great circles, one per edge).
    padded = np.pad(mask, ((0, 0), (1, 1)))
    step = np.diff(padded, axis=1)
    ys, starts = np.nonzero(step == 1)
    ye, ends = np.nonzero(step == -1)
    assert np.array_equal(ys, ye)
    keep = (ends - starts) <= MAX_MARKING_WIDTH_PX
    mid = 0.5 * (starts + ends - 1)
    return np.column_stack([mid[keep], ys[keep]]).astype(np.float64)


def _great_circles(rays: np.ndarray, tol_rad: float,
                   rng: np.random.Generator, max_lines: int = 8) -> list[tuple[np.ndarray,
                                                                               np.ndarray]]:
    """Sequential RANSAC: (normal, inlier index) of up to ``max_lines`` great circles."""
    remaining = np.arange(len(rays))
    found = []
    for _ in range(max_lines):
        if len(remaining) < MIN_LINE_PIXELS:
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
        if inl.sum() < MIN_LINE_PIXELS:
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
    """(φ, h, y0, rms) with tan(α_i − φ) = (y0 + offsets_i) / h, α_i the normals' angles."""
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
    if b <= 0:
        raise MountFitError("the lines' spacing does not fit a camera above the road (the "
                            "fitted height is negative): are these the lane's markings?")
    h = 1.0 / b
    return phi, h, a * h, rms


def fit_mount(frame: np.ndarray, camera: Camera, *, points: list[np.ndarray] | None = None,
              forward_m: float | None = None, seed: int = 0) -> MountFit:
    """Fit ``camera``'s mount (its intrinsics kept) from ``frame``, a straight road seen by
    a car parallel to it; ``points`` (pixel arrays of the centre line, then its left and
    right neighbours, ``None`` for one not marked) replaces the marking search.
    ``forward_m`` (the camera ahead of the rear axle) cannot be seen in one frame: the
    camera's own is kept unless given."""
    if frame.ndim != 2 or frame.dtype != np.uint8:
        raise MountFitError(f"the frame must be 8-bit grey, got {frame.dtype} {frame.shape}")
    if frame.shape != (camera.height, camera.width):
        raise MountFitError(f"the frame is {frame.shape[1]}×{frame.shape[0]}, the camera's "
                            f"intrinsics are for {camera.width}×{camera.height}")
    f_px = float(np.sqrt(camera.K[0, 0] * camera.K[1, 1]))
    tol = INLIER_PX / f_px
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
            _, _, vt = np.linalg.svd(r, full_matrices=False)
            lines.append((vt[-1], p, role))
        if not any(role == "centre" for _, _, role in lines) or len(lines) < 2:
            raise MountFitError("--points needs the centre line and at least one neighbour")
        direction = _vanishing([n for n, _, _ in lines])
        fits = [LineFit(n, p, 1.0, role) for n, p, role in lines]
    else:
        pix = marking_pixels(frame)
        if len(pix) > 60000:  # bounded work: a random subset of the bright pixels
            pix = pix[rng.choice(len(pix), 60000, replace=False)]
        if len(pix) < 2 * MIN_LINE_PIXELS:
            raise MountFitError("no markings found in the frame: it needs two parallel lines "
                                "of a straight road (the dashed centre line and a solid line)")
        rays = camera.unproject(pix)
        ok = np.all(np.isfinite(rays), axis=1)
        rays, pix = rays[ok], pix[ok]
        circles = _great_circles(rays, tol, rng)
        fits, direction = _road_lines(circles, rays, pix)
    return _finish(camera, fits, direction, forward_m, f_px)


def _vanishing(normals: list[np.ndarray]) -> np.ndarray:
    _, _, vt = np.linalg.svd(np.array(normals), full_matrices=False)
    r = vt[-1]
    return r if r[2] > 0 else -r


def _road_lines(circles: list[tuple[np.ndarray, np.ndarray]], rays: np.ndarray,
                pix: np.ndarray) -> tuple[list[LineFit], np.ndarray]:
    """The circles through one forward vanishing point, with the dashed centre line and
    its nearest neighbours on each side marked."""
    if len(circles) < 2:
        raise MountFitError(f"found {len(circles)} straight line(s) in the frame, need two "
                            "parallel lines of a straight road (the dashed centre line and a "
                            "solid line)")
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
                            "lines share a vanishing point ahead): is the road straight?")
    direction = _vanishing([circles[k][0] for k in best])
    # Below the horizon only: a great circle's other half (walls, the hall) is not the
    # road's line.
    up = _up_guess(direction)
    below = {k: circles[k][1][rays[circles[k][1]] @ up < -math.sin(math.radians(0.5))]
             for k in best}
    sel = [k for k in best if len(below[k]) >= MIN_LINE_PIXELS]
    if len(sel) < 2:
        raise MountFitError("found no two parallel lines below the horizon")
    circles = [(n, below.get(k, idx)) for k, (n, idx) in enumerate(circles)]
    cov = {k: _coverage(rays[circles[k][1]], circles[k][0], direction) for k in sel}
    order = sorted(sel, key=lambda k: _lateral_angle(circles[k][0], direction))  # left first
    dashed = [k for k in order if cov[k] < DASHED_COVERAGE]
    if not dashed:
        raise MountFitError("found parallel lines but no dashed one: the fit needs the "
                            "dashed centre line in view (or give --points)")
    centre = min(dashed, key=lambda k: cov[k])
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


def _finish(camera: Camera, fits: list[LineFit], direction: np.ndarray,
            forward_m: float | None, f_px: float) -> MountFit:
    used = [f for f in fits if f.role != "other"]
    offsets = {"left": LANE_WIDTH_M, "centre": 0.0, "right": -LANE_WIDTH_M}
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
        if b_ <= 0:
            raise MountFitError("the two lines' order does not fit a camera above the road")
        phi, h, y0 = 0.0, 1.0 / b_, (t[0] - b_ * offs[0]) / b_
    e_lat = math.cos(phi) * a + math.sin(phi) * b
    g = -math.sin(phi) * a + math.cos(phi) * b
    # Camera-frame images of the car's axes → the mount's rotation (car → camera).
    R = np.column_stack([direction, e_lat, g])
    pitch, roll, yaw = _rot_to_angles(R @ _BASE.T)
    lateral = -(y0 - LANE_WIDTH_M / 2)  # camera left of the lane centre
    try:
        mount = CameraMount(height_m=h, forward_m=camera.mount.forward_m if forward_m is None
                            else forward_m, lateral_m=lateral, pitch_rad=pitch,
                            roll_rad=roll, yaw_rad=yaw)
    except ValueError as exc:  # lines that fit no camera on a car
        raise MountFitError(f"the lines fit no camera on a 1:10 car ({exc}): are these the "
                            "lane's markings, 0.4 m apart?") from None
    fitted = camera.replace(mount=mount)
    residual = _residual(fitted, used, y0 + lateral)  # the centre line in the car frame
    return MountFit(fitted, tuple(fits), residual, roll_fitted, f_px)


def _residual(camera: Camera, used: list[LineFit], centre_y_car: float) -> float:
    """RMS pixel distance of the used lines' pixels to their model lines' images."""
    offsets = {"left": LANE_WIDTH_M, "centre": 0.0, "right": -LANE_WIDTH_M}
    sq = []
    # from beside and behind the camera (a fisheye sees there) to far ahead [m]
    ahead = camera.mount.forward_m + np.concatenate([np.linspace(-1.0, 0.05, 1000),
                                                     np.geomspace(0.05, 40.0, 3000)])
    for f in used:
        y = centre_y_car + offsets[f.role]
        uv = camera.project(camera.car_to_camera(np.column_stack(
            [ahead, np.full_like(ahead, y), np.zeros_like(ahead)])))
        uv = uv[np.all(np.isfinite(uv), axis=1)]
        if not len(uv):
            return math.inf
        for start in range(0, len(f.pixels), 500):
            p = f.pixels[start:start + 500]
            d2 = np.min(np.sum((p[:, None, :] - uv[None, :, :]) ** 2, axis=2), axis=1)
            sq.append(d2)
    d2 = np.concatenate(sq)
    # Pixels far off every model line are other structures on the same great circle.
    d2 = d2[d2 <= (RESIDUAL_OUTLIER_PX) ** 2]
    return float(np.sqrt(np.mean(d2))) if len(d2) else math.inf


def fit_focal(frame: np.ndarray, width: int, height: int, *, seed: int = 0) -> MountFit:
    """``fit_mount`` with an equidistant fisheye whose focal length is fitted too
    (principal point at the image centre): the focal length whose lines are straightest
    on the ground (least residual)."""
    diag = math.hypot(width, height)

    def attempt(f: float) -> MountFit | None:
        K = np.array([[f, 0.0, (width - 1) / 2], [0.0, f, (height - 1) / 2], [0.0, 0.0, 1.0]])
        try:
            return fit_mount(frame, FisheyeCamera(K, np.zeros(4), width=width, height=height),
                             seed=seed)
        except (MountFitError, ValueError):
            return None

    lo, hi = FOCAL_RANGE[0] * diag, FOCAL_RANGE[1] * diag
    grid = np.geomspace(lo, hi, 13)
    results = [(f, attempt(f)) for f in grid]
    scored = [(r.residual_px, f) for f, r in results if r is not None]
    if not scored:
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
"""The polygon is moved up by the blur's half height [px], so no body pixel is road."""

BONNET_VERTICES: int = 17
"""Vertices along the fitted body edge [1]."""


def detect_bonnet(frame: np.ndarray) -> np.ndarray:
    """``(n, 2)`` polygon [px] of the car's body at the bottom of ``frame``: per column the
    first strong darkening in the lowest quarter, a smooth curve fitted through them,
    closed along the bottom border."""
    h, w = frame.shape
    blur = cv2.blur(frame.astype(np.float32), (9, 5))
    d = 3
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
    vs = np.clip(np.polyval(coef, us) - BONNET_MARGIN_PX, 0.0, h - 1.0)
    return np.array([[0.0, h - 1.0], *np.column_stack([us, vs]), [w - 1.0, h - 1.0]])
