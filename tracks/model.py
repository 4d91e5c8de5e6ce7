"""The track model: a chain of straight and arc segments plus the road's elements.

Coordinates: world frame in metres, x right / y up (a top view of the mat); headings in
radians, counter-clockwise from +x. The arc length ``s`` [m] runs along the road's
centre line (the dashed line) from the start pose; the lateral offset ``d`` [m] is
positive to the left of the driving direction. Cars drive on the right lane,
``-lane_width < d < 0``.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field
from enum import Enum
from functools import cached_property

import numpy as np

from .dimensions import LANE_WIDTH_M, LINE_WIDTH_M
from .geometry import (
    CHAIN_NOT_FINITE,
    CHAIN_OK,
    CHAIN_WRAP,
    Pose,
    SegmentTable,
    chain_angles,
    chain_points,
    extreme_sample_indices,
    pose_at,
)
from .index import GridIndex, build_index, locate_point, locate_points

MAX_TRACK_LENGTH_M: float = 250.0
"""Longest centre line a track may have [m]. A Carolo-Cup mat is at most tens of metres
across (generated tracks, seeds 0–999: ≤ 53 m; the named ones: ≤ 42 m), so 250 m is a
margin of almost five. Everything laid out per metre of road (rule-check samples every
5 cm, the spatial index, map pixels) is proportional to it; with
``tfalda_sim.tracks.fileformat.MAX_SEGMENTS`` it bounds the rule check's time to a few seconds."""

MAX_LANE_WIDTH_M: float = 1.0
"""Widest lane [m]: 2.5 × the rules' ≈ 0.40 m (``validate`` accepts 0.35–0.45 m). The
spatial index registers every centre-line sample in a square of cells whose area grows
with the square of the road's width, so an absurd width would allocate without bound."""

INDEX_CACHE_SIZE: int = 8
"""Spatial indexes kept per road geometry (an index is a few hundred kB at most)."""

_INDEX_CACHE: dict[tuple, GridIndex] = {}


def printable(text: str) -> str:
    """``text`` as a command prints it: every character that is not printable (a control
    character, a line or paragraph separator) as its Python escape (``\x1b``, ``\r``),
    the rest as is. A name from a file or a track built in Python reaches the terminal:
    it must not act on it (clear it, fake an output line)."""
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


class Line(Enum):
    """The three longitudinal lines of a road, seen in the driving direction."""

    LEFT = "left"
    CENTRE = "centre"
    RIGHT = "right"


class Lane(Enum):
    """A lane of the road; ``OFF_ROAD`` for points outside both side lines."""

    RIGHT = "right"
    LEFT = "left"
    OFF_ROAD = "off_road"


@dataclass(frozen=True)
class Straight:
    """A straight segment of ``length_m`` [m]."""

    length_m: float

    @property
    def curvature(self) -> float:
        return 0.0


@dataclass(frozen=True)
class Arc:
    """A circular arc of centre-line radius ``radius_m`` [m] turning by ``angle_rad`` [rad]
    (positive = left / counter-clockwise)."""

    radius_m: float
    angle_rad: float

    @property
    def length_m(self) -> float:
        return self.radius_m * abs(self.angle_rad)

    @property
    def curvature(self) -> float:
        return math.copysign(1.0 / self.radius_m, self.angle_rad)


Segment = Straight | Arc


@dataclass(frozen=True)
class Gap:
    """A stretch where ``line`` is not painted: from ``s_m`` for ``length_m`` [m]."""

    line: Line
    s_m: float
    length_m: float

    def __post_init__(self) -> None:
        # A negative stretch has no meaning (and broke the rules' event sweep); zero is
        # left to the rules, which report it.
        if not self.length_m >= 0:
            raise ValueError(f"a gap's length_m must be ≥ 0, got {self.length_m}")


@dataclass(frozen=True)
class Obstacle:
    """A white carton standing in ``lane``; its centre is at arc length ``s_m`` [m] and
    ``offset_m`` [m] left of the lane's centre. Sizes [m]: ``length_m`` along the road,
    ``width_m`` across, ``height_m`` up. The box is aligned with the road at ``s_m``."""

    s_m: float
    lane: Lane
    length_m: float
    width_m: float
    height_m: float
    offset_m: float = 0.0


@dataclass(frozen=True)
class Intersection:
    """A right-angled crossing of the road with itself: the centre line passes the same
    point at arc lengths ``s1_m`` and ``s2_m`` [m]."""

    s1_m: float
    s2_m: float


@dataclass(frozen=True)
class Location:
    """Answer of the reverse query: arc length [m], lateral offset [m] (left > 0), lane,
    and distance [m] from the nearest centre-line point."""

    s_m: float
    lateral_m: float
    lane: Lane
    distance_m: float


def _finite_positive(value: float, what: str) -> None:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise ValueError(f"{what} must be a finite number > 0, got {value!r}")


ELEMENT_FIELDS: tuple[str, ...] = ("start_line_s_m", "gaps", "obstacles", "intersections",
                                   "name", "description", "seed")
"""The fields of a ``Track`` that leave its road (segments, start, closed, lane width) as
it is: what ``Track.with_elements`` changes."""


@dataclass(frozen=True)
class Track:
    """A Carolo-Cup road: a chain of segments from ``start`` plus its markings' elements.

    ``closed`` tracks are circuits (the chain must end where it starts); open tracks are
    test strips. Whether the track obeys the rules is checked by
    ``tfalda_sim.tracks.rules.validate``; the constructor only rejects values that have no geometric
    meaning (negative lengths, zero radius, NaN).
    """

    segments: tuple[Segment, ...]
    closed: bool = True
    start: Pose = field(default_factory=Pose)
    lane_width_m: float = LANE_WIDTH_M
    start_line_s_m: float | None = None
    gaps: tuple[Gap, ...] = ()
    obstacles: tuple[Obstacle, ...] = ()
    intersections: tuple[Intersection, ...] = ()
    name: str = ""
    description: str = ""
    seed: int | None = None

    def __post_init__(self) -> None:
        for name in ("segments", "gaps", "obstacles", "intersections"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        if not self.segments:
            raise ValueError("a track needs at least one segment")
        total_m = 0.0
        for i, seg in enumerate(self.segments):
            if isinstance(seg, Straight):
                _finite_positive(seg.length_m, f"segments[{i}].length_m")
            elif isinstance(seg, Arc):
                _finite_positive(seg.radius_m, f"segments[{i}].radius_m")
                if not math.isfinite(seg.angle_rad) or not 0 < abs(seg.angle_rad) <= 2 * math.pi:
                    raise ValueError(
                        f"segments[{i}].angle_rad must be non-zero and within ±2π, "
                        f"got {seg.angle_rad!r}"
                    )
            else:
                raise TypeError(f"segments[{i}] must be Straight or Arc, got {type(seg).__name__}")
            total_m += seg.length_m
        # Checked here, before anything is laid out per metre of road (samples, index, map).
        if total_m > MAX_TRACK_LENGTH_M:
            raise ValueError(
                f"track too large: its segments add up to {total_m:g} m, more than the largest "
                f"track length {MAX_TRACK_LENGTH_M:g} m "
                "(tfalda_sim.tracks.model.MAX_TRACK_LENGTH_M)")
        _finite_positive(self.lane_width_m, "lane_width_m")
        if self.lane_width_m > MAX_LANE_WIDTH_M:
            raise ValueError(
                f"lane_width_m {self.lane_width_m:g} m is wider than the widest lane "
                f"{MAX_LANE_WIDTH_M:g} m (tfalda_sim.tracks.model.MAX_LANE_WIDTH_M)")
        for v, what in ((self.start.x_m, "start.x_m"), (self.start.y_m, "start.y_m"),
                        (self.start.heading_rad, "start.heading_rad")):
            if not math.isfinite(v):
                raise ValueError(f"{what} must be finite, got {v!r}")

    def with_elements(self, **changes: object) -> Track:
        """``dataclasses.replace`` for the fields that leave the road as it is (its
        elements and labels: ``ELEMENT_FIELDS``): the copy keeps what was computed from the
        road (segment table, heading table, centre-line extremes, spatial index) instead
        of computing it again, and skips the road's checks, passed already. A generated
        track is copied 2–3 times on its way to an env (intersections, elements, the
        cartons taken off)."""
        unknown = sorted(set(changes) - set(ELEMENT_FIELDS))
        if unknown:
            raise TypeError(f"with_elements changes only {', '.join(ELEMENT_FIELDS)}, not "
                            f"{', '.join(unknown)}; use dataclasses.replace")
        copy = object.__new__(type(self))
        copy.__dict__.update(self.__dict__)  # the fields, and the road's cached properties
        if "obstacles" in changes:  # the one cached property of an element (not the road)
            copy.__dict__.pop("obstacle_corners_m", None)
        for name, value in changes.items():
            if name in ("gaps", "obstacles", "intersections"):
                value = tuple(value)  # type: ignore[arg-type]  # as __post_init__ does
            object.__setattr__(copy, name, value)
        return copy

    # ------------------------------------------------------------------ layout
    @cached_property
    def table(self) -> SegmentTable:
        """Start pose, curvature, length and start arc length of every segment."""
        n = len(self.segments)
        x0 = np.empty(n)
        y0 = np.empty(n)
        h0 = np.empty(n)
        kappa = np.array([seg.curvature for seg in self.segments], dtype=np.float64)
        length = np.array([seg.length_m for seg in self.segments], dtype=np.float64)
        s0 = np.concatenate(([0.0], np.cumsum(length)[:-1]))
        x, y, h = self.start.x_m, self.start.y_m, self.start.heading_rad
        for i in range(n):
            x0[i], y0[i], h0[i] = x, y, h
            x, y, h = pose_at(x, y, h, kappa[i], length[i])
        return SegmentTable(x0, y0, h0, kappa, length, s0, Pose(x, y, h))

    @cached_property
    def length_m(self) -> float:
        """Length of the centre line [m] (kept: a step asks ≈ 8 times)."""
        t = self.table
        return float(t.s0[-1] + t.length[-1])

    @property
    def end_pose(self) -> Pose:
        """Pose at the end of the chain (equals ``start`` for a well-closed loop)."""
        return self.table.end

    @property
    def half_road_m(self) -> float:
        """Distance from the centre line to the outer edge of a side line [m]."""
        return self.lane_width_m + 0.5 * LINE_WIDTH_M

    def check_place(self, s_m: float, lateral_m: float, heading_rad: float, *,
                    names: tuple[str, str, str] = ("s_m", "lateral_m", "heading_rad")) -> None:
        """A car's place on this track — arc length, offset from the centre line, heading
        relative to the road — or a ``ValueError`` naming the first value out of bounds
        (by its name in ``names``) and the bounds. The bounds: ``s`` on an open track
        within ``[0, length]``; on a closed one (which wraps) within a lap of the start
        line, ``[-length, length]``; ``|lateral|`` at most ``half_road_m`` (on the road);
        ``|heading|`` at most π. Beyond them nothing of the road is seen or reached
        (a lateral of 1e300 m), or a wrapped arc length has lost its every digit."""
        name_s, name_lat, name_h = names
        length = self.length_m
        if not self.closed and not 0.0 <= s_m <= length:
            raise ValueError(f"{name_s} {s_m:g} m is off the open track: use 0 ≤ s ≤ "
                             f"{length:.3f} m")
        if self.closed and not -length <= s_m <= length:
            raise ValueError(f"{name_s} {s_m:g} m is more than a lap from the start line: use "
                             f"{-length:.3f} ≤ s ≤ {length:.3f} m (the closed track wraps)")
        if not abs(lateral_m) <= self.half_road_m:
            raise ValueError(f"{name_lat} {lateral_m:g} m is off the road: use |lateral| ≤ "
                             f"{self.half_road_m:.3f} m (centre line to a side line's edge)")
        if not abs(heading_rad) <= math.pi:
            raise ValueError(f"{name_h} {heading_rad:g} rad is more than a half turn from "
                             f"the road's direction: use |heading| ≤ π ({math.pi:.4f}) rad")

    def closure_error(self) -> tuple[float, float]:
        """Gap between the chain's end and its start: distance [m], heading [rad]."""
        end = self.end_pose
        dist = math.hypot(end.x_m - self.start.x_m, end.y_m - self.start.y_m)
        dh = (end.heading_rad - self.start.heading_rad + math.pi) % (2 * math.pi) - math.pi
        return dist, abs(dh)

    @property
    def min_centre_radius_m(self) -> float:
        """Smallest centre-line radius of any arc [m] (inf for a track of straights)."""
        radii = [seg.radius_m for seg in self.segments if isinstance(seg, Arc)]
        return min(radii) if radii else math.inf

    # ----------------------------------------------------------- forward query
    def pose(self, s: np.ndarray | float, lateral_m: np.ndarray | float = 0.0
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World ``x [m], y [m], heading [rad]`` at arc length ``s`` and lateral offset
        (broadcast against each other; numpy scalars for scalar arguments).

        Vectorised over ``s``; O(log n) per query (binary search over segment starts).
        Two small kernels around numpy's sine and cosine (``chain_angles``,
        ``chain_points``): the same numbers as the numpy expressions they replace, at a
        fifth of the calls (a pose query was ≈ 150 µs of numpy call overhead, several
        times per reset onto a new track).
        """
        s = np.asarray(s, dtype=np.float64)
        lat = np.asarray(lateral_m, dtype=np.float64)
        shape = s.shape
        if lat.shape != shape and lat.size != 1:
            # Offsets of another shape: x and y broadcast, the heading keeps s's shape.
            x, y, _ = self.pose(np.broadcast_to(s, np.broadcast_shapes(shape, lat.shape)),
                                np.broadcast_to(lat, np.broadcast_shapes(shape, lat.shape)))
            return x, y, self.pose(s)[2]
        idx, u, heading, slot, angles = self._chain(s.reshape(-1))
        _, _, kappa, _, _, sin_h0, cos_h0, x0, y0 = self._pose_args
        x, y = chain_points(idx, u, slot, sin_h0, cos_h0, np.sin(angles), np.cos(angles),
                            x0, y0, kappa, np.ascontiguousarray(lat.reshape(-1)))
        if lat.ndim > len(shape):  # one offset, as an array of more dimensions than s
            out = np.broadcast_shapes(shape, lat.shape)
            return x.reshape(out), y.reshape(out), heading.reshape(shape)[()]
        if not shape:
            return x[0], y[0], heading[0]
        return x.reshape(shape), y.reshape(shape), heading.reshape(shape)

    def _chain(self, flat: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``chain_angles`` of the 1-D arc lengths ``flat`` [m] on this track (its segment,
        local coordinate, heading and listed angles per query): a closed track's wrapped
        as ``np.mod`` wraps them, an open track's checked to lie on it, non-finite ones
        refused."""
        s0, h0, kappa, total, closed = self._pose_args[:5]
        answer, idx, u, heading, slot, angles = chain_angles(flat, s0, h0, kappa, total,
                                                             closed)
        if answer == CHAIN_WRAP:
            # np.mod may round up to the length itself (s = −1e−20): the search clamps it
            # to the last segment, so no second wrap check (closed=False).
            flat = np.mod(flat, total)
            answer, idx, u, heading, slot, angles = chain_angles(flat, s0, h0, kappa, total,
                                                                 False)
        if answer == CHAIN_NOT_FINITE:
            raise ValueError("arc length s must be finite")
        if answer != CHAIN_OK:  # the kernels after it would read unwritten indices
            raise RuntimeError(f"chain_angles answered {answer}")
        if not closed:
            self._check_open_range(flat)
        return idx, u, heading, slot, angles

    @cached_property
    def _pose_args(self) -> tuple:
        """``pose``'s kernel arguments, gathered once per road: its segment table, length,
        whether it is closed, and numpy's sine and cosine of each start heading."""
        t = self.table
        return (t.s0, t.h0, t.kappa, self.length_m, self.closed, np.sin(t.h0), np.cos(t.h0),
                t.x0, t.y0)

    def _check_open_range(self, s: np.ndarray) -> None:
        """An open track's arc lengths [m] must lie on it (±1 nm)."""
        total = self.length_m
        outside = (s < -1e-9) | (s > total + 1e-9)
        if np.any(outside):
            raise ValueError(
                f"s = {s[outside].ravel()[0]:.6g} m is outside the open track "
                f"[0, {total:.6g}] m; only closed tracks wrap around")

    def position(self, s: np.ndarray | float, lateral_m: np.ndarray | float = 0.0) -> np.ndarray:
        """World position ``(..., 2)`` [m] at arc length ``s`` [m] and lateral offset [m]."""
        x, y, _ = self.pose(s, lateral_m)
        return np.stack([x, y], axis=-1)

    def heading(self, s: np.ndarray | float) -> np.ndarray:
        """Centre-line heading [rad] at arc length ``s`` [m]."""
        return self.pose(s)[2]

    def heading_at(self, s_m: float) -> float:
        """``heading`` for one arc length [m] (a float; no arrays: for per-step use)."""
        if not math.isfinite(s_m):
            raise ValueError("arc length s must be finite")
        total = self.length_m
        if self.closed:
            s_m = s_m % total
        elif not -1e-9 <= s_m <= total + 1e-9:
            raise ValueError(f"s = {s_m:.6g} m is outside the open track [0, {total:.6g}] m; "
                             "only closed tracks wrap around")
        starts, h0, kappa = self._heading_table
        k = min(max(bisect.bisect_right(starts, s_m) - 1, 0), len(starts) - 1)
        return h0[k] + kappa[k] * (s_m - starts[k])

    @cached_property
    def _heading_table(self) -> tuple[list[float], list[float], list[float]]:
        t = self.table
        return t.s0.tolist(), t.h0.tolist(), t.kappa.tolist()

    def curvature(self, s: np.ndarray | float) -> np.ndarray:
        """Signed centre-line curvature [1/m] at arc length ``s`` [m] (left > 0)."""
        s = np.asarray(s, dtype=np.float64)
        idx = self._chain(s.reshape(-1))[0]
        return self.table.kappa[idx.reshape(s.shape)[()]]

    def sample(self, step_m: float) -> tuple[np.ndarray, np.ndarray]:
        """Arc lengths [m] every ``step_m`` (and the end for open tracks) and their
        centre-line points ``(N, 2)`` [m]."""
        total = self.length_m
        n = max(2, math.ceil(total / step_m))
        s = np.linspace(0.0, total, n + 1)
        if self.closed:
            s = s[:-1]
        return s, self.position(s)

    def bounds(self, margin_m: float = 0.0) -> tuple[float, float, float, float]:
        """Bounding box ``(xmin, ymin, xmax, ymax)`` [m] of the road plus ``margin_m``:
        the extremes of the centre-line points every 2 cm (``sample(0.02)``), ± the half
        road, the margin and 1 cm. Only the samples that can hold an extreme are computed
        (``_extreme_samples``, once per track): the same numbers, a tenth of the work."""
        lo, hi = self._centre_extremes
        pad = self.half_road_m + margin_m + 0.01
        return (float(lo[0] - pad), float(lo[1] - pad), float(hi[0] + pad),
                float(hi[1] + pad))

    @cached_property
    def _centre_extremes(self) -> tuple[np.ndarray, np.ndarray]:
        """``(min, max)`` over x and y of the centre-line points every 2 cm [m]."""
        pts = self.position(self._extreme_samples(0.02))
        return pts.min(axis=0), pts.max(axis=0)

    def _extreme_samples(self, step_m: float) -> np.ndarray:
        """The arc lengths of ``sample(step_m)`` near a segment's ends and near the points
        of an arc heading along an axis (±3 samples): the extremes of the sampled x and y
        lie among them. (Along a segment the computed x and y are monotone between those
        points: rounding is monotone, and next to an extreme adjacent samples differ by
        far more than rounding.)"""
        total = self.length_m
        n = max(2, math.ceil(total / step_m))
        t = self.table
        step = total / n
        idx = extreme_sample_indices(t.s0, t.length, t.h0, t.kappa, step,
                                     n if self.closed else n + 1)
        # np.linspace(0, total, n + 1)[idx] without the other ~10³ samples: its i-th is
        # i · (total / n) + 0.0, its last the end itself.
        s = idx * step
        if not self.closed:
            s[idx == n] = total
        return s

    @cached_property
    def obstacle_corners_m(self) -> np.ndarray:
        """``(n, 4, 2)`` world corners [m] of each obstacle's footprint, aligned with the
        road (read-only): the box ``length_m`` × ``width_m`` centred in its lane, moved by
        ``offset_m``. Computed once per track (the rules, the world and the renderer all
        ask, each reset onto a new track), the poses in one call: numpy's vectorised
        sine and cosine give each element the same bits whatever the array's length."""
        obs = self.obstacles
        out = np.zeros((len(obs), 4, 2))
        if obs:
            sign = [-1.0 if ob.lane.value == "right" else 1.0 for ob in obs]
            xs, ys, hs = self.pose(
                np.array([ob.s_m for ob in obs], np.float64),
                np.array([sg * 0.5 * self.lane_width_m + ob.offset_m
                          for sg, ob in zip(sign, obs, strict=True)], np.float64))
            for k, ob in enumerate(obs):
                x, y, h = float(xs[k]), float(ys[k]), float(hs[k])
                t = np.array([math.cos(h), math.sin(h)])
                n = np.array([-math.sin(h), math.cos(h)])
                c = np.array([x, y])
                hl, hw = 0.5 * ob.length_m, 0.5 * ob.width_m
                out[k] = (c + hl * t + hw * n, c - hl * t + hw * n, c - hl * t - hw * n,
                          c + hl * t - hw * n)
        out.flags.writeable = False
        return out

    # ----------------------------------------------------------- reverse query
    @cached_property
    def index(self) -> GridIndex:
        """Spatial hash of the segments for O(1) reverse queries (built on first use, and
        shared by tracks with the same road: a copy with other cartons or gaps)."""
        key = (self.segments, self.start, self.lane_width_m)
        index = _INDEX_CACHE.get(key)
        if index is None:
            index = build_index(self.table, self.half_road_m)
            if len(_INDEX_CACHE) >= INDEX_CACHE_SIZE:
                _INDEX_CACHE.pop(next(iter(_INDEX_CACHE)))
            _INDEX_CACHE[key] = index
        return index

    def locate(self, x_m: float, y_m: float, s_hint_m: float | None = None) -> Location:
        """Reverse query: world point → arc length, lateral offset, lane.

        Looks only at the segments registered in the point's grid cell (O(1) on average).
        Where the road crosses itself, the candidate nearest to ``s_hint_m`` (e.g. the
        car's arc length one step ago) wins among those the point lies on.
        """
        if not (math.isfinite(x_m) and math.isfinite(y_m)):
            raise ValueError(f"locate needs a finite point, got ({x_m!r}, {y_m!r})")
        hint = math.nan if s_hint_m is None else float(s_hint_m)
        if s_hint_m is not None and not math.isfinite(hint):
            raise ValueError(f"s_hint_m must be finite or None, got {s_hint_m!r}")
        if self.closed:
            hint = hint % self.length_m  # a hint from the next lap means the same place
        t = self.table
        g = self.index
        s, d, dist = locate_point(
            float(x_m), float(y_m), hint, t.x0, t.y0, t.h0, t.kappa, t.length, t.s0,
            self.length_m, self.closed, self.half_road_m,
            g.x0, g.y0, g.cell_m, g.nx, g.ny, g.cell_start, g.items,
        )
        return Location(s, d, self.lane_at(d), dist)

    def lane_at(self, lateral_m: float) -> Lane:
        """Lane for a lateral offset [m] (a point on the centre line counts as left)."""
        if abs(lateral_m) > self.half_road_m:
            return Lane.OFF_ROAD
        return Lane.LEFT if lateral_m >= 0.0 else Lane.RIGHT

    def locate_many(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Vectorised ``locate`` (no hint) for ``(N, 2)`` points [m]: arc lengths,
        lateral offsets and distances [m]."""
        pts = np.ascontiguousarray(points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 2:
            raise ValueError(f"locate_many expects an (N, 2) array of points, got {pts.shape}")
        if not np.all(np.isfinite(pts)):
            raise ValueError("locate_many needs finite points")
        t = self.table
        g = self.index
        out = locate_points(
            pts, t.x0, t.y0, t.h0, t.kappa, t.length, t.s0, self.length_m, self.closed,
            self.half_road_m, g.x0, g.y0, g.cell_m, g.nx, g.ny, g.cell_start, g.items,
        )
        return out[0], out[1], out[2]
