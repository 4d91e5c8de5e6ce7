"""Carolo-Cup track rules: ``validate(track)`` checks a track against the rulebook's
dimensions (``tracks.dimensions``) and returns every violation.

The check's own numerical parameters (tolerances, sample step) are named constants here.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from .geometry import pose_at, project

if TYPE_CHECKING:
    from .model import Track

from .dimensions import (  # the rulebook's numbers; re-exported here for the checks
    CLOSURE_TOLERANCE_M,
    CLOSURE_TOLERANCE_RAD,
    INTERSECTION_ANGLE_TOLERANCE_RAD,
    INTERSECTION_APPROACH_M,
    LANE_WIDTH_M,
    LANE_WIDTH_RANGE_M,
    LINE_WIDTH_M,
    MAX_LINES_MISSING,
    MAX_MARKING_GAP_M,
    MIN_INNER_EDGE_RADIUS_M,
    OBSTACLE_HEIGHT_RANGE_M,
    OBSTACLE_MIN_LENGTH_M,
    OBSTACLE_MIN_SPACING_M,
    OBSTACLE_WIDTH_RANGE_M,
    PARALLEL_ROAD_MIN_GAP_M,
)

RADIUS_TOLERANCE_M: float = 1e-9
"""Numerical slack when comparing radii with the minimum [m], so that a curve drawn at
exactly the tightest legal radius validates."""

OVERLAP_SAMPLE_STEP_M: float = 0.05
"""Step [m] of the centre-line samples whose exact distance to the rest of the track is
measured by the overlap check. Between samples the distance can dip by at most
(step/2)²/(2·R_min) ≈ 0.2 mm, far below the 50 mm parallel-road gap."""


def road_width_m(lane_width_m: float = LANE_WIDTH_M) -> float:
    """Road width between the outer edges of the two side lines [m] (820 mm by default)."""
    return 2.0 * lane_width_m + LINE_WIDTH_M


def min_centre_radius_m(lane_width_m: float = LANE_WIDTH_M) -> float:
    """Tightest legal radius of the road's centre line [m] (≈ 1.41 m for 400 mm lanes).

    The inner edge of the inner side line lies one lane width plus half a line width
    inside the centre line and must stay at ``MIN_INNER_EDGE_RADIUS_M`` or more.
    """
    return MIN_INNER_EDGE_RADIUS_M + lane_width_m + 0.5 * LINE_WIDTH_M


def min_road_clearance_m(lane_width_m: float = LANE_WIDTH_M) -> float:
    """Smallest distance between the centre lines of two separate stretches of road [m]."""
    return road_width_m(lane_width_m) + PARALLEL_ROAD_MIN_GAP_M


@dataclass(frozen=True)
class Violation:
    """One broken rule.

    ``rule`` is a stable identifier (e.g. ``"min_radius"``), ``field`` the place in the
    track file (e.g. ``"segments[3].radius_m"``), ``s_m`` the arc length where it
    happens [m] if it has one.
    """

    rule: str
    field: str
    message: str
    s_m: float | None = None

    def to_dict(self) -> dict[str, object]:
        return {"rule": self.rule, "field": self.field, "message": self.message, "s_m": self.s_m}


# ---------------------------------------------------------------------------- checks


_PREFILTER_MARGIN_M = 1e-6
"""Slack [m] of the close-approach check's cheap distance bound (rounding)."""


@njit(cache=True)
def _close_approaches(
    samples: np.ndarray,
    x0: np.ndarray,
    y0: np.ndarray,
    h0: np.ndarray,
    kappa: np.ndarray,
    length: np.ndarray,
    s0: np.ndarray,
    total: float,
    closed: bool,
    exclude_m: float,
    clearance_m: float,
) -> list[tuple[float, float, float]]:
    """``(s_i, s_j, distance)`` for every sample ``s_i`` whose exact distance to a part of
    the track more than ``exclude_m`` away along the road is below ``clearance_m``."""
    hits = [(0.0, 0.0, 0.0)]
    hits.pop()
    # Every point of a segment lies within half its length of its midpoint: a segment whose
    # midpoint is farther than that plus the clearance (and a margin for rounding) cannot
    # give a hit, and is skipped before its pieces are cut (most of the cost).
    # Compared squared: no hypot per sample and segment (most of the cost before); the
    # margin dwarfs the squares' rounding, so no segment that can give a hit is skipped.
    n_seg = len(length)
    mid_x = np.empty(n_seg)
    mid_y = np.empty(n_seg)
    reach2 = np.empty(n_seg)
    for j in range(n_seg):
        mid_x[j], mid_y[j], _ = pose_at(x0[j], y0[j], h0[j], kappa[j], 0.5 * length[j])
        reach2[j] = (0.5 * length[j] + clearance_m + _PREFILTER_MARGIN_M) ** 2
    # The pieces of a segment left after cutting out the three windows (at most 4: each
    # window splits one piece at most), in two small arrays instead of lists.
    lo_a = np.empty(8)
    hi_a = np.empty(8)
    lo_b = np.empty(8)
    hi_b = np.empty(8)
    shifts = (-total, 0.0, total) if closed else (0.0, 0.0, 0.0)
    for i in range(samples.shape[0]):
        si = samples[i, 0]
        px = samples[i, 1]
        py = samples[i, 2]
        for j in range(n_seg):
            dx = px - mid_x[j]
            dy = py - mid_y[j]
            if dx * dx + dy * dy > reach2[j]:
                continue
            lo_a[0] = s0[j]
            hi_a[0] = s0[j] + length[j]
            n_p = 1
            for k in range(3):
                wlo = si - exclude_m + shifts[k]
                whi = si + exclude_m + shifts[k]
                m = 0
                for q in range(n_p):
                    lo = lo_a[q]
                    hi = hi_a[q]
                    if whi <= lo or wlo >= hi:
                        lo_b[m] = lo
                        hi_b[m] = hi
                        m += 1
                    else:
                        if lo < wlo:
                            lo_b[m] = lo
                            hi_b[m] = wlo
                            m += 1
                        if whi < hi:
                            lo_b[m] = whi
                            hi_b[m] = hi
                            m += 1
                for q in range(m):
                    lo_a[q] = lo_b[q]
                    hi_a[q] = hi_b[q]
                n_p = m
            best_d = math.inf
            best_s = 0.0
            for q in range(n_p):
                u, _, dist = project(x0[j], y0[j], h0[j], kappa[j], lo_a[q] - s0[j],
                                     hi_a[q] - s0[j], px, py)
                if dist < best_d:
                    best_d = dist
                    best_s = s0[j] + u
            if best_d < clearance_m:
                hits.append((si, best_s, best_d))
    return hits


def _cyclic_distance(a: float, b: float, total: float, closed: bool) -> float:
    d = abs(a - b)
    return min(d, total - d) if closed else d


def _in_range(track: Track, s: float, length: float = 0.0) -> bool:
    total = track.length_m
    if track.closed:
        return 0.0 <= s < total
    return 0.0 <= s and s + length <= total + 1e-9


def _check_geometry(track: Track) -> list[Violation]:
    out: list[Violation] = []
    lo, hi = LANE_WIDTH_RANGE_M
    if not lo <= track.lane_width_m <= hi:
        out.append(Violation(
            "lane_width", "lane_width_m",
            f"lane width {track.lane_width_m:.3f} m is outside the accepted {lo:.2f}–{hi:.2f} m "
            "(rules: ≈ 0.40 m)"))
    r_min = min_centre_radius_m(track.lane_width_m)
    s_at = track.table.s0
    for i, seg in enumerate(track.segments):
        if hasattr(seg, "radius_m") and seg.radius_m < r_min - RADIUS_TOLERANCE_M:
            out.append(Violation(
                "min_radius", f"segments[{i}].radius_m",
                f"arc radius {seg.radius_m:.3f} m is tighter than the minimum centre-line "
                f"radius {r_min:.3f} m (inner edge of the inner line must stay ≥ "
                f"{MIN_INNER_EDGE_RADIUS_M:.2f} m)", float(s_at[i])))
    if track.closed:
        dist, dh = track.closure_error()
        if dist > CLOSURE_TOLERANCE_M or dh > CLOSURE_TOLERANCE_RAD:
            out.append(Violation(
                "closure", "segments",
                f"loop does not close: end is {dist * 1000:.2f} mm and {math.degrees(dh):.3f}° "
                f"from the start (allowed {CLOSURE_TOLERANCE_M * 1000:.0f} mm, "
                f"{math.degrees(CLOSURE_TOLERANCE_RAD):.1f}°)", track.length_m))
    return out


def _check_overlap(track: Track) -> list[Violation]:
    total = track.length_m
    clearance = min_road_clearance_m(track.lane_width_m)
    s, pts = track.sample(OVERLAP_SAMPLE_STEP_M)
    samples = np.column_stack([s, pts])
    t = track.table
    # Two points of a legal road closer than this along it cannot be closer than the
    # clearance in space (curvature limit), so they are not compared.
    exclude = 0.5 * math.pi * clearance
    hits = _close_approaches(samples, t.x0, t.y0, t.h0, t.kappa, t.length, t.s0, total,
                             track.closed, exclude, clearance)
    zone = clearance + 0.01
    # One violation per stretch of close approach: (s_i, s_j, distance) at its closest,
    # and the last (s_i, s_j) seen, to tell whether the next hit continues the stretch.
    regions: list[tuple[float, float, float]] = []
    last = (-math.inf, -math.inf)
    for si, sj, dist in hits:
        if si > sj:
            continue  # each pair is seen from both sides
        exempt = any(
            (_cyclic_distance(si, a, total, track.closed) < zone
             and _cyclic_distance(sj, b, total, track.closed) < zone)
            for x in track.intersections for a, b in ((x.s1_m, x.s2_m), (x.s2_m, x.s1_m)))
        if exempt:
            continue
        continues = si - last[0] <= 2.5 * OVERLAP_SAMPLE_STEP_M and abs(sj - last[1]) < 1.0
        last = (si, sj)
        if continues:
            if dist < regions[-1][2]:
                regions[-1] = (si, sj, dist)
            continue
        regions.append((si, sj, dist))
    return [
        Violation(
            "overlap", "segments",
            f"road at s = {si:.2f} m comes within {dist:.3f} m of the road at s = {sj:.2f} m "
            f"(centre lines must be ≥ {clearance:.3f} m apart: road width + "
            f"{PARALLEL_ROAD_MIN_GAP_M * 1000:.0f} mm gap) and no intersection is declared there",
            si)
        for si, sj, dist in regions
    ]


def _check_intersections(track: Track) -> list[Violation]:
    out: list[Violation] = []
    total = track.length_m
    for k, x in enumerate(track.intersections):
        where = f"intersections[{k}]"
        if not (_in_range(track, x.s1_m) and _in_range(track, x.s2_m)):
            out.append(Violation("intersection_range", where,
                                 f"s1_m / s2_m must lie in [0, {total:.3f}) m"))
            continue
        p1 = track.position(x.s1_m)
        p2 = track.position(x.s2_m)
        gap = float(np.hypot(*(p1 - p2)))
        if gap > CLOSURE_TOLERANCE_M:
            out.append(Violation(
                "intersection_position", where,
                f"the road does not cross itself there: the points at s1 and s2 are "
                f"{gap * 1000:.1f} mm apart", x.s1_m))
        dh = float(track.heading(x.s1_m) - track.heading(x.s2_m))
        if abs(math.cos(dh)) > math.sin(INTERSECTION_ANGLE_TOLERANCE_RAD):
            angle = math.degrees(math.acos(min(1.0, abs(math.cos(dh)))))
            out.append(Violation(
                "intersection_angle", where,
                f"crossing angle {angle:.2f}° is not a right angle (±"
                f"{math.degrees(INTERSECTION_ANGLE_TOLERANCE_RAD):.0f}°)", x.s1_m))
        for s in (x.s1_m, x.s2_m):
            around = s + np.linspace(-INTERSECTION_APPROACH_M, INTERSECTION_APPROACH_M, 401)
            if not track.closed and (around[0] < 0 or around[-1] > total):
                out.append(Violation("intersection_approach", where,
                                     "crossing too close to the end of the open track", s))
                continue
            if np.any(track.curvature(around) != 0.0):
                out.append(Violation(
                    "intersection_approach", where,
                    f"the road must run straight for {INTERSECTION_APPROACH_M:.2f} m on both sides "
                    f"of the crossing at s = {s:.2f} m", s))
    return out


def _check_gaps(track: Track) -> list[Violation]:
    out: list[Violation] = []
    total = track.length_m
    for k, g in enumerate(track.gaps):
        where = f"gaps[{k}]"
        if not (math.isfinite(g.length_m) and g.length_m > 0):
            out.append(Violation("gap_length", f"{where}.length_m", "gap length must be > 0"))
            continue
        if g.length_m > MAX_MARKING_GAP_M + 1e-9:
            out.append(Violation(
                "gap_length", f"{where}.length_m",
                f"{g.line.value} line missing for {g.length_m:.3f} m (rules: ≤ "
                f"{MAX_MARKING_GAP_M:.2f} m)", g.s_m))
        if not _in_range(track, g.s_m, g.length_m):
            out.append(Violation("gap_range", f"{where}.s_m",
                                 f"gap at s = {g.s_m:.3f} m lies outside the track", g.s_m))
    # Sweep the gaps' ends: where does a line stay missing too long, or too many at once?
    events: list[tuple[float, int, object]] = []
    for g in track.gaps:
        for shift in ((-total, 0.0, total) if track.closed else (0.0,)):
            events.append((g.s_m + shift, +1, g.line))
            events.append((g.s_m + g.length_m + shift, -1, g.line))
    events.sort(key=lambda e: e[0])
    # Events at one place (within 1 µm) are applied together, openings first: gaps of one
    # line that touch end to end are one missing stretch, and a gap of one line that ends
    # where another line's begins does not count as two lines missing at once.
    groups: list[list[tuple[float, int, object]]] = []
    for e in events:
        if groups and e[0] - groups[-1][0][0] < 1e-6:
            groups[-1].append(e)
        else:
            groups.append([e])
    open_lines: dict[object, int] = {}
    since: dict[object, float] = {}
    joined: dict[object, int] = {}  # gaps that make up the current missing stretch
    reported: set[tuple[str, int]] = set()
    for group in groups:
        for s, step, line in sorted(group, key=lambda e: -e[1]):
            before = open_lines.get(line, 0)
            open_lines[line] = before + step
            if step > 0:
                joined[line] = 1 if before == 0 else joined[line] + 1
                if before == 0:
                    since[line] = s
            if step < 0 and open_lines[line] == 0 and joined[line] > 1:
                run = s - since[line]
                key = ("merged", round(since[line] % total if track.closed else since[line], 3))
                if run > MAX_MARKING_GAP_M + 1e-9 and key not in reported and \
                        0 <= since[line] < total:
                    reported.add(key)
                    out.append(Violation(
                        "gap_length", "gaps",
                        f"gaps of the {line.value} line, end to end or overlapping, leave it "
                        f"missing for {run:.3f} m from s = {since[line]:.3f} m (rules: ≤ "
                        f"{MAX_MARKING_GAP_M:.2f} m)", since[line]))
        s = group[0][0]
        missing = sum(1 for v in open_lines.values() if v > 0)
        if missing > MAX_LINES_MISSING and 0 <= s < total:
            key = ("many", round(s, 3))
            exempt = any(
                _cyclic_distance(s, a, total, track.closed) < INTERSECTION_APPROACH_M
                for x in track.intersections for a in (x.s1_m, x.s2_m))
            if key not in reported and not exempt:
                reported.add(key)
                out.append(Violation(
                    "lines_missing", "gaps",
                    f"{missing} lines missing at once at s = {s:.3f} m (rules: at most "
                    f"{MAX_LINES_MISSING})", s))
    return out


def _check_obstacles(track: Track) -> list[Violation]:
    out: list[Violation] = []
    total = track.length_m
    half_line = 0.5 * LINE_WIDTH_M
    w = track.lane_width_m
    for k, ob in enumerate(track.obstacles):
        where = f"obstacles[{k}]"
        if ob.length_m < OBSTACLE_MIN_LENGTH_M:
            out.append(Violation("obstacle_size", f"{where}.length_m",
                                 f"length {ob.length_m:.3f} m < {OBSTACLE_MIN_LENGTH_M:.2f} m",
                                 ob.s_m))
        lo, hi = OBSTACLE_WIDTH_RANGE_M
        if not lo <= ob.width_m <= hi:
            out.append(Violation("obstacle_size", f"{where}.width_m",
                                 f"width {ob.width_m:.3f} m outside {lo:.2f}–{hi:.2f} m", ob.s_m))
        lo, hi = OBSTACLE_HEIGHT_RANGE_M
        if not lo <= ob.height_m <= hi:
            out.append(Violation("obstacle_size", f"{where}.height_m",
                                 f"height {ob.height_m:.3f} m outside {lo:.2f}–{hi:.2f} m", ob.s_m))
        if ob.lane.value not in ("right", "left"):
            out.append(Violation("obstacle_lane", f"{where}.lane",
                                 "an obstacle stands in the right or the left lane"))
            continue
        if not _in_range(track, ob.s_m) or (not track.closed and not (
                0.5 * ob.length_m <= ob.s_m <= total - 0.5 * ob.length_m)):
            out.append(Violation("obstacle_range", f"{where}.s_m",
                                 f"obstacle at s = {ob.s_m:.3f} m lies outside the track", ob.s_m))
            continue
        # The box's four corners must stay inside its lane, so the other lane is free.
        sign = -1.0 if ob.lane.value == "right" else 1.0
        band = sorted((sign * half_line, sign * (w - half_line)))
        for corner in obstacle_corners(track, k):
            loc = track.locate(float(corner[0]), float(corner[1]), s_hint_m=ob.s_m)
            if not band[0] - 1e-6 <= loc.lateral_m <= band[1] + 1e-6:
                out.append(Violation(
                    "obstacle_blocks", where,
                    f"obstacle reaches {loc.lateral_m:+.3f} m from the centre line, outside its "
                    f"{ob.lane.value} lane ({band[0]:+.3f}…{band[1]:+.3f} m): one lane must stay "
                    "passable", ob.s_m))
                break
        for x in track.intersections:
            for a in (x.s1_m, x.s2_m):
                if _cyclic_distance(ob.s_m, a, total, track.closed) < INTERSECTION_APPROACH_M:
                    out.append(Violation("obstacle_intersection", where,
                                         "obstacle stands in an intersection", ob.s_m))
    order = sorted(range(len(track.obstacles)), key=lambda i: track.obstacles[i].s_m)
    pairs = list(itertools.pairwise(order))
    if track.closed and len(order) > 1:
        pairs.append((order[-1], order[0]))
    for a, b in pairs:
        oa, ob = track.obstacles[a], track.obstacles[b]
        ahead = (ob.s_m - oa.s_m) % total if track.closed else ob.s_m - oa.s_m
        free = ahead - 0.5 * (oa.length_m + ob.length_m)
        if free < OBSTACLE_MIN_SPACING_M - 1e-9:
            out.append(Violation(
                "obstacle_spacing", f"obstacles[{b}]",
                f"only {free:.3f} m of free road after obstacles[{a}] (rules: ≥ "
                f"{OBSTACLE_MIN_SPACING_M:.2f} m)", ob.s_m))
    return out


def obstacle_corners(track: Track, k: int) -> np.ndarray:
    """World corners ``(4, 2)`` [m] of obstacle ``k``'s footprint, aligned with the road
    (a copy of ``Track.obstacle_corners_m[k]``)."""
    return track.obstacle_corners_m[k].copy()


def _check_start_line(track: Track) -> list[Violation]:
    if track.start_line_s_m is None:
        if track.closed:
            return [Violation("start_line", "start_line_s_m", "a circuit needs a start line")]
        return []
    if not _in_range(track, track.start_line_s_m):
        return [Violation("start_line", "start_line_s_m",
                          f"start line at s = {track.start_line_s_m:.3f} m lies outside the track")]
    return []


def validate(track: Track) -> list[Violation]:
    """Every rule the track breaks (an empty list for a valid track), in a stable order:
    geometry, overlap, intersections, gaps, obstacles, start line."""
    return [
        *_check_geometry(track),
        *_check_overlap(track),
        *_check_intersections(track),
        *_check_gaps(track),
        *_check_obstacles(track),
        *_check_start_line(track),
    ]


def validate_elements(track: Track) -> list[Violation]:
    """The checks of ``validate`` that look at the road elements (gaps, obstacles, start
    line): for a track whose geometry and intersections ``validate`` already passed, its
    result is ``validate``'s (the generator adds elements to a valid road)."""
    return [*_check_gaps(track), *_check_obstacles(track), *_check_start_line(track)]
