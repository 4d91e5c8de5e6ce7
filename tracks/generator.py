"""Procedural Carolo-Cup circuits: ``generate(seed, params)`` → a valid closed ``Track``.

The seed is the scenario id (as in MetaDrive): equal seeds and parameters give equal
tracks, so train/test splits are seed ranges. All randomness comes from one
``numpy.random.Generator`` seeded with it.

Method: draw a polygon of control points, round every corner with a circular arc
(radius ≥ the rules' minimum) tangent to both edges, and keep the straight rest of each
edge. Loops use a star-shaped polygon (simple by construction; dented corners give
right-hand curves, the "turn mix"); figure-eights use two lobes whose closing edges
cross at a right angle, the crossing becoming a declared intersection. Candidates that
break a rule (roads too close) are redrawn from the same generator.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, fields, replace

import numpy as np

from . import dimensions, rules
from .model import Arc, Gap, Intersection, Lane, Line, Obstacle, Pose, Straight, Track

MAX_TURN_RAD = math.radians(150.0)
"""Sharpest corner of a control polygon [rad]; sharper corners need very long tangents."""



def seed_name(seed: int) -> str:
    """The name of seed ``seed``'s generated track, and how every output labels a track
    given as a seed: ``seed-7``."""
    return f"seed-{int(seed)}"

@dataclass(frozen=True)
class GeneratorParams:
    """Every range the generator draws from, in one place.

    Ranges are ``(low, high)``. ``difficulty`` in [0, 1] skews the fillet radii toward
    the tightest legal one and scales the rates of dented corners, marking gaps and
    obstacles from 0 (at difficulty 0) to their ``*_max`` values (at difficulty 1).
    """

    difficulty: float = 0.5
    lane_width_m: float = dimensions.LANE_WIDTH_M
    loop_corners: tuple[int, int] = (5, 9)
    """Number of control points of a simple loop."""
    lobe_corners: tuple[int, int] = (2, 4)
    """Control points between the two legs of a figure-eight lobe."""
    lobe_leg_m: tuple[float, float] = (2.4, 3.6)
    """Distance from the crossing to a lobe's first and last control point [m]."""
    extent_m: tuple[float, float] = (3.0, 6.0)
    """Distance of a control point from the loop's centre (or the crossing) [m]."""
    radius_m: tuple[float, float] = (rules.min_centre_radius_m(), 4.0)
    """Fillet (curve) radius of the centre line [m]; the low end is the rules' minimum."""
    min_straight_m: float = 0.3
    """Shortest straight kept between two curves [m]."""
    dent_probability_max: float = 0.5
    """Share of a loop's corners pulled inward (right-hand curves in a left loop)."""
    dent_factor: tuple[float, float] = (0.45, 0.75)
    """A dented corner's distance from the centre, relative to the drawn extent."""
    clockwise_probability: float = 0.5
    """Chance that the circuit is mirrored (clockwise: mostly right-hand curves)."""
    figure_eight_probability: float = 0.25
    """Chance of a figure-eight with an intersection instead of a simple loop."""
    gap_rate_max_per_m: float = 0.08
    """Expected marking gaps per metre of track [1/m] at difficulty 1."""
    gap_length_m: tuple[float, float] = (0.2, dimensions.MAX_MARKING_GAP_M)
    """Length of one marking gap [m]."""
    obstacle_rate_max_per_m: float = 0.05
    """Expected obstacles per metre of track [1/m] at difficulty 1."""
    obstacle_length_m: tuple[float, float] = (dimensions.OBSTACLE_MIN_LENGTH_M, 0.4)
    obstacle_width_m: tuple[float, float] = (dimensions.OBSTACLE_WIDTH_RANGE_M[0], 0.3)
    obstacle_height_m: tuple[float, float] = dimensions.OBSTACLE_HEIGHT_RANGE_M
    start_clear_m: float = 1.5
    """Road kept free of gaps and obstacles around the start line [m]."""
    max_attempts: int = 500
    """Redraws allowed before giving up (never reached in 10,000 tested seeds)."""

    def __post_init__(self) -> None:
        if not 0.0 <= self.difficulty <= 1.0:
            raise ValueError(f"difficulty must be in [0, 1], got {self.difficulty!r}")
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, tuple) and not v[0] <= v[1]:
                raise ValueError(f"{f.name}: range ({v[0]}, {v[1]}) has low > high")
        lo, hi = dimensions.LANE_WIDTH_RANGE_M
        if not lo <= self.lane_width_m <= hi:
            raise ValueError(f"lane_width_m must be in [{lo}, {hi}] m (the rules' ≈ 0.40 m), "
                             f"got {self.lane_width_m!r}")
        for name in ("dent_probability_max", "clockwise_probability",
                     "figure_eight_probability"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} is a probability in [0, 1], got {getattr(self, name)!r}")
        for name in ("gap_rate_max_per_m", "obstacle_rate_max_per_m", "min_straight_m",
                     "start_clear_m"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) >= 0.0):
                raise ValueError(f"{name} must be finite and ≥ 0, got {getattr(self, name)!r}")
        if self.gap_length_m[0] <= 0.0 or self.gap_length_m[1] > dimensions.MAX_MARKING_GAP_M:
            raise ValueError(f"gap_length_m must lie in (0, {dimensions.MAX_MARKING_GAP_M}] m (the "
                             f"rules' longest gap), got {self.gap_length_m}")
        if self.max_attempts < 1:
            raise ValueError(f"max_attempts must be ≥ 1, got {self.max_attempts}")
        if self.radius_m[0] < rules.min_centre_radius_m(self.lane_width_m) - 1e-9:
            raise ValueError(
                f"radius_m starts at {self.radius_m[0]} m, below the rules' minimum "
                f"{rules.min_centre_radius_m(self.lane_width_m):.3f} m for this lane width")


@dataclass(frozen=True)
class _Polygon:
    points: np.ndarray  # (k, 2) control points, in driving order
    max_tangent: np.ndarray  # (k,) longest tangent allowed at each corner [m]
    crossing: np.ndarray | None  # point where two straight edges cross (figure-eight)
    crossing_edges: tuple[int, ...]  # edges (from point i to i+1) through the crossing


def _draw_radius(rng: np.random.Generator, p: GeneratorParams) -> float:
    lo, hi = p.radius_m
    # Skew toward the tightest radius as difficulty grows.
    return lo + (hi - lo) * rng.random() ** (1.0 + 3.0 * p.difficulty)


def _loop_polygon(rng: np.random.Generator, p: GeneratorParams) -> _Polygon:
    k = int(rng.integers(p.loop_corners[0], p.loop_corners[1] + 1))
    angles = (np.arange(k) + rng.uniform(-0.3, 0.3, k)) * (2 * math.pi / k)
    radii = rng.uniform(*p.extent_m, k)
    dented = rng.random(k) < p.dent_probability_max * p.difficulty
    radii = np.where(dented, radii * rng.uniform(*p.dent_factor, k), radii)
    pts = np.column_stack([radii * np.cos(angles), radii * np.sin(angles)])
    return _Polygon(pts, np.full(k, np.inf), None, ())


def _lobe(rng: np.random.Generator, p: GeneratorParams, n_mid: int) -> np.ndarray:
    """Control points of a lobe above the crossing (at the origin): from the 45° ray over
    the top to the 135° ray. The points in between are sorted by angle around a centre
    above the crossing, so the lobe is star-shaped and cannot cross itself."""
    a, b = rng.uniform(*p.lobe_leg_m, 2)
    first = a * np.array([math.cos(math.pi / 4), math.sin(math.pi / 4)])
    last = b * np.array([math.cos(3 * math.pi / 4), math.sin(3 * math.pi / 4)])
    centre = np.array([0.0, rng.uniform(*p.extent_m) * 0.8])
    lo = max(math.atan2(first[1] - centre[1], first[0] - centre[0]), -0.4)
    hi = min(math.atan2(last[1] - centre[1], last[0] - centre[0]) % (2 * math.pi), math.pi + 0.4)
    step = (hi - lo) / (n_mid + 1)
    angles = lo + step * (np.arange(1, n_mid + 1) + rng.uniform(-0.2, 0.2, n_mid))
    rho = rng.uniform(0.8, 1.1, n_mid) * centre[1] + 0.5
    mid = centre + np.column_stack([rho * np.cos(angles), rho * np.sin(angles)])
    return np.vstack([first, mid, last])


def _figure_eight_polygon(rng: np.random.Generator, p: GeneratorParams) -> _Polygon:
    upper = _lobe(rng, p, int(rng.integers(p.lobe_corners[0], p.lobe_corners[1] + 1)))
    lower = _lobe(rng, p, int(rng.integers(p.lobe_corners[0], p.lobe_corners[1] + 1)))
    # Mirrored in y, a lobe runs from the -45° ray to the -135° ray: the path leaves
    # the crossing heading -45°, turns right around the lower lobe and returns at +45°.
    lower = lower * np.array([1.0, -1.0])
    pts = np.vstack([upper, lower])
    k = len(pts)
    last_up = len(upper) - 1
    # Edges last_up→last_up+1 and k-1→0 pass through the crossing at the origin.
    tmax = np.full(k, np.inf)
    for i in (last_up, last_up + 1, k - 1, 0):
        tmax[i] = float(np.hypot(*pts[i])) - dimensions.INTERSECTION_APPROACH_M
    return _Polygon(pts, tmax, np.zeros(2), (last_up, k - 1))


def _next(a: np.ndarray) -> np.ndarray:
    """``a`` moved one entry back along axis 0 (entry i holds a[i + 1], cyclically):
    ``np.roll(a, -1, axis=0)``'s values without its general path (µs per call)."""
    return np.concatenate((a[1:], a[:1]))


def _previous(a: np.ndarray) -> np.ndarray:
    """Entry i holds a[i − 1], cyclically (``np.roll(a, 1, axis=0)``)."""
    return np.concatenate((a[-1:], a[:-1]))


def _fillet(poly: _Polygon, rng: np.random.Generator, p: GeneratorParams, r_min: float
            ) -> tuple[list[Straight | Arc], list[int], np.ndarray] | None:
    """Round every corner. Returns the segments (edge 0's straight first), the index of
    each edge's straight among them and each corner's tangent length [m], or None if the
    polygon cannot carry legal curves."""
    pts = poly.points
    k = len(pts)
    edge = _next(pts) - pts
    edge_len = np.hypot(edge[:, 0], edge[:, 1])
    if np.any(edge_len < 1e-6):
        return None
    heading = np.arctan2(edge[:, 1], edge[:, 0])
    turn = (heading - _previous(heading) + math.pi) % (2 * math.pi) - math.pi  # at point i
    if np.any(np.abs(turn) > MAX_TURN_RAD):
        return None
    tan_half = np.tan(np.abs(turn) / 2)
    radius = np.array([_draw_radius(rng, p) for _ in range(k)])
    tangent = np.minimum(radius * tan_half, poly.max_tangent)
    # Shrink the curves of edges too short for both tangents, each corner in proportion
    # to what it can spare above the tightest legal radius.
    t_min = np.minimum(r_min * tan_half, tangent)
    for _ in range(k + 1):
        excess = tangent + _next(tangent) + p.min_straight_m - edge_len  # edge i
        if np.all(excess <= 1e-12):
            break
        for i in np.flatnonzero(excess > 1e-12):
            j = (i + 1) % k
            spare_i, spare_j = tangent[i] - t_min[i], tangent[j] - t_min[j]
            if spare_i + spare_j < excess[i]:
                return None
            cut = excess[i] / (spare_i + spare_j)
            tangent[i] -= spare_i * cut
            tangent[j] -= spare_j * cut
    with np.errstate(divide="ignore", invalid="ignore"):
        radius = np.where(tan_half > 1e-12, tangent / tan_half, np.inf)
    curved = np.abs(turn) > 1e-9
    straights = edge_len - tangent - _next(tangent)
    if np.any(radius[curved] < r_min - 1e-9) or np.any(straights < p.min_straight_m - 1e-9):
        return None
    segments: list[Straight | Arc] = []
    straight_of_edge: list[int] = []
    for i in range(k):
        straight_of_edge.append(len(segments))
        segments.append(Straight(float(straights[i])))
        j = (i + 1) % k
        if curved[j]:
            segments.append(Arc(float(radius[j]), float(turn[j])))
    return segments, straight_of_edge, tangent


def _assemble(poly: _Polygon, fil: tuple[list[Straight | Arc], list[int], np.ndarray],
              p: GeneratorParams, seed: int) -> Track:
    segments, straight_of_edge, tangent = fil
    pts = poly.points
    k = len(pts)
    n = len(segments)
    # Start at the middle of the longest straight that is no intersection's approach.
    best = max((i for i in range(k) if i not in poly.crossing_edges),
               key=lambda i: segments[straight_of_edge[i]].length_m)
    idx = straight_of_edge[best]
    half = segments[idx].length_m / 2
    direction = pts[(best + 1) % k] - pts[best]
    direction = direction / np.hypot(*direction)
    start_xy = pts[best] + direction * (tangent[best] + half)
    chain = [Straight(half), *segments[idx + 1:], *segments[:idx], Straight(half)]
    track = Track(tuple(chain), closed=True,
                  start=Pose(float(start_xy[0]), float(start_xy[1]),
                             math.atan2(direction[1], direction[0])),
                  lane_width_m=p.lane_width_m, start_line_s_m=0.0, name=seed_name(seed),
                  seed=seed)
    if poly.crossing is None:
        return track
    table = track.table
    passes = []
    for e in poly.crossing_edges:
        j = (straight_of_edge[e] - idx) % n  # the edge's straight in the rotated chain
        u = ((poly.crossing[0] - table.x0[j]) * math.cos(table.h0[j])
             + (poly.crossing[1] - table.y0[j]) * math.sin(table.h0[j]))
        passes.append(float(table.s0[j] + u))
    return track.with_elements(intersections=(Intersection(min(passes), max(passes)),))


def _free_interval(rng: np.random.Generator, track: Track, length: float,
                   blocked: list[tuple[float, float]]) -> float | None:
    """A start s [m] for an element of ``length`` that overlaps none of ``blocked``."""
    total = track.length_m
    for _ in range(20):
        s = float(rng.uniform(0.0, total))
        ok = True
        for lo, hi in blocked:
            for shift in (-total, 0.0, total):
                if s < hi + shift and s + length > lo + shift:
                    ok = False
        if ok:
            return s
    return None


def _add_elements(track: Track, rng: np.random.Generator, p: GeneratorParams) -> Track:
    total = track.length_m
    base_blocked = [(-p.start_clear_m, p.start_clear_m)]
    for x in track.intersections:
        for a in (x.s1_m, x.s2_m):
            reach = dimensions.INTERSECTION_APPROACH_M
            base_blocked.append((a - reach, a + reach))
    lines = (Line.LEFT, Line.CENTRE, Line.RIGHT)
    gaps: list[Gap] = []
    for _ in range(int(rng.poisson(p.gap_rate_max_per_m * p.difficulty * total))):
        line = lines[int(rng.integers(3))]
        length = float(rng.uniform(*p.gap_length_m))
        # Gaps of the same line keep apart; two other lines may be missing at once, a
        # third never (rules: at most two lines missing).
        blocked = list(base_blocked)
        by_line: dict[Line, list[tuple[float, float]]] = {}
        for g in gaps:
            by_line.setdefault(g.line, []).append((g.s_m, g.s_m + g.length_m))
        blocked += [(lo - 0.2, hi + 0.2) for lo, hi in by_line.get(line, [])]
        others = [iv for ln, ivs in by_line.items() if ln != line for iv in ivs]
        for i, a in enumerate(others):
            for b in others[i + 1:]:
                lo, hi = max(a[0], b[0]), min(a[1], b[1])
                if lo < hi:
                    blocked.append((lo, hi))
        s = _free_interval(rng, track, length, blocked)
        if s is not None:
            gaps.append(Gap(line, s % total, length))
    obstacles: list[Obstacle] = []
    for _ in range(int(rng.poisson(p.obstacle_rate_max_per_m * p.difficulty * total))):
        length = float(rng.uniform(*p.obstacle_length_m))
        width = float(rng.uniform(*p.obstacle_width_m))
        height = float(rng.uniform(*p.obstacle_height_m))
        lane = Lane.RIGHT if rng.random() < 0.5 else Lane.LEFT
        # Keep the box inside its lane with a margin for the bow of a curve.
        room = max(0.0, 0.5 * (track.lane_width_m - dimensions.LINE_WIDTH_M - width) - 0.02)
        offset = float(rng.uniform(-room, room))
        spacing = dimensions.OBSTACLE_MIN_SPACING_M
        blocked = list(base_blocked) + [
            (o.s_m - 0.5 * o.length_m - spacing - 0.05,
             o.s_m + 0.5 * o.length_m + spacing + 0.05) for o in obstacles]
        s = _free_interval(rng, track, length, blocked)
        if s is not None:
            obstacles.append(Obstacle((s + 0.5 * length) % total, lane, length, width, height,
                                      offset))
    return track.with_elements(gaps=tuple(sorted(gaps, key=lambda g: g.s_m)),
                               obstacles=tuple(sorted(obstacles, key=lambda o: o.s_m)))


GENERATE_CACHE_SIZE: int = 16
"""Generated tracks kept (a track is immutable: asking for a seed again, as an env on a
fixed generated track does at every reset, returns the same object)."""


def generate(seed: int, params: GeneratorParams | None = None) -> Track:
    """A valid closed Carolo-Cup circuit for scenario ``seed`` (deterministic)."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    p = params or GeneratorParams()
    try:
        hash(p)
    except TypeError:  # parameters holding lists: nothing to key a cache on
        return _generate(int(seed), p)
    return _generate_cached(int(seed), p)


def _generate(seed: int, p: GeneratorParams) -> Track:
    rng = np.random.default_rng(seed)
    r_min = rules.min_centre_radius_m(p.lane_width_m)
    eight = rng.random() < p.figure_eight_probability
    mirror = rng.random() < p.clockwise_probability
    rotation = rng.uniform(-math.pi, math.pi)
    rot = np.array([[math.cos(rotation), -math.sin(rotation)],
                    [math.sin(rotation), math.cos(rotation)]])
    for _ in range(p.max_attempts):
        poly = _figure_eight_polygon(rng, p) if eight else _loop_polygon(rng, p)
        pts = poly.points @ rot.T
        if mirror:
            pts = pts * np.array([1.0, -1.0])
        poly = replace(poly, points=pts)
        fil = _fillet(poly, rng, p, r_min)
        if fil is None:
            continue
        track = _assemble(poly, fil, p, int(seed))
        if rules.validate(track):
            continue
        track = _add_elements(track, rng, p)
        # Same road as just validated: only the new elements need checking.
        if not rules.validate_elements(track):
            return track
    raise RuntimeError(f"no valid track for seed {seed} after {p.max_attempts} attempts; "
                       "widen GeneratorParams.extent_m or radius_m")


_generate_cached = functools.lru_cache(maxsize=GENERATE_CACHE_SIZE)(_generate)
