"""Geometry of the track model: forward queries, joins, reverse query."""

from __future__ import annotations

import math
from dataclasses import replace as _replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.conftest import generated
from tfalda_sim.tracks import Arc, Gap, Lane, Line, Pose, Straight, Track, generate, load_named
from tfalda_sim.tracks.geometry import extreme_sample_indices, project

segment = st.one_of(
    st.builds(Straight, st.floats(0.05, 6.0)),
    st.builds(Arc, st.floats(1.41, 12.0),
              st.floats(0.02, 3.0).flatmap(lambda a: st.sampled_from([a, -a]))),
)
chains = st.builds(
    lambda segs, x, y, h: Track(tuple(segs), closed=False, start=Pose(x, y, h)),
    st.lists(segment, min_size=1, max_size=8),
    st.floats(-20, 20), st.floats(-20, 20), st.floats(-math.pi, math.pi),
)


@settings(max_examples=150, deadline=None)
@given(chains)
def test_position_and_heading_are_continuous_at_joins(track: Track) -> None:
    for s_join in track.table.s0[1:]:
        before = track.pose(s_join - 1e-7)
        after = track.pose(s_join + 1e-7)
        assert math.hypot(before[0] - after[0], before[1] - after[1]) < 1e-6
        assert abs(math.remainder(float(before[2] - after[2]), 2 * math.pi)) < 1e-6


@settings(max_examples=150, deadline=None)
@given(chains, st.floats(0.0, 1.0))
def test_heading_is_the_derivative_of_position_and_curvature_of_heading(
        track: Track, frac: float) -> None:
    s = frac * track.length_m
    h = 1e-5
    lo, hi = max(0.0, s - h), min(track.length_m, s + h)
    p0, p1 = track.position(lo), track.position(hi)
    # Inside a segment the finite difference of position points along the heading.
    idx = np.searchsorted(track.table.s0, [lo, hi], side="right")
    if idx[0] == idx[1] and hi > lo:
        tangent = (p1 - p0) / (hi - lo)
        heading = float(track.heading(0.5 * (lo + hi)))
        assert np.allclose(tangent, [math.cos(heading), math.sin(heading)], atol=1e-4)
        dh = math.remainder(float(track.heading(hi) - track.heading(lo)), 2 * math.pi)
        assert dh / (hi - lo) == pytest.approx(float(track.curvature(s)), abs=1e-4)


@settings(max_examples=400, deadline=None)
@given(st.integers(0, 60), st.floats(0.0, 1.0, exclude_max=True), st.floats(-0.409, 0.409))
def test_reverse_query_inverts_forward_query(seed: int, frac: float, lateral: float) -> None:
    track = generated(seed)
    s = frac * track.length_m
    x, y, _ = track.pose(s, lateral)
    loc = track.locate(float(x), float(y), s_hint_m=s)
    ds = abs(loc.s_m - s)
    assert min(ds, track.length_m - ds) < 1e-4  # 0.1 mm
    assert loc.lateral_m == pytest.approx(lateral, abs=1e-4)
    if abs(lateral) > 1e-9:  # exactly on the centre line either lane is right
        assert loc.lane == (Lane.LEFT if lateral > 0 else Lane.RIGHT)


@pytest.mark.parametrize("seed", range(0, 40, 3))
def test_loops_close(seed: int) -> None:
    dist, dh = generated(seed).closure_error()
    assert dist < 1e-9 and dh < 1e-9


def test_reverse_query_matches_brute_force_over_all_segments() -> None:
    rng = np.random.default_rng(1)
    for seed in range(10):
        track = generated(seed)
        t = track.table
        s = rng.uniform(0, track.length_m, 300)
        pts = track.position(s, rng.uniform(-1.2, 1.2, 300))
        _, _, dist_fast = track.locate_many(pts)
        for i, (px, py) in enumerate(pts):
            brute = min(project(t.x0[j], t.y0[j], t.h0[j], t.kappa[j], 0.0, t.length[j], px, py)[2]
                        for j in range(len(t.length)))
            assert dist_fast[i] == pytest.approx(brute, abs=1e-12)


def test_far_point_falls_back_to_exact_answer() -> None:
    track = Track((Straight(10.0),), closed=False)
    loc = track.locate(4.0, 7.5)
    assert loc.s_m == pytest.approx(4.0)
    assert loc.lateral_m == pytest.approx(7.5)
    assert loc.lane is Lane.OFF_ROAD


def test_hint_picks_the_branch_at_a_crossing(eight: Track) -> None:
    x = eight.intersections[0]
    p = eight.position(x.s1_m + 0.05, -0.2)
    on_first = eight.locate(float(p[0]), float(p[1]), s_hint_m=x.s1_m)
    on_second = eight.locate(float(p[0]), float(p[1]), s_hint_m=x.s2_m)
    assert on_first.s_m == pytest.approx(x.s1_m + 0.05, abs=1e-9)
    assert on_first.lateral_m == pytest.approx(-0.2, abs=1e-9)
    # Seen from the other branch the same point lies 5 cm along and 20 cm across it.
    assert abs(on_second.s_m - x.s2_m) < 0.25
    assert abs(on_second.lateral_m) == pytest.approx(0.05, abs=1e-9)


def test_hint_from_another_lap_means_the_same_place(eight: Track) -> None:
    x = eight.intersections[0]
    p = eight.position(x.s1_m + 0.05, -0.2)
    for lap in (-2, -1, 1, 3):
        loc = eight.locate(float(p[0]), float(p[1]), s_hint_m=x.s2_m + lap * eight.length_m)
        assert abs(loc.s_m - x.s2_m) < 0.25  # the second branch, as with the plain hint
    with pytest.raises(ValueError, match="s_hint_m must be finite"):
        eight.locate(float(p[0]), float(p[1]), s_hint_m=float("inf"))


def test_open_track_refuses_arc_length_outside() -> None:
    track = Track((Straight(2.0),), closed=False)
    with pytest.raises(ValueError, match="outside the open track"):
        track.position(2.5)
    closed = generated(0)
    assert np.allclose(closed.position(closed.length_m + 1.0), closed.position(1.0))


@pytest.mark.parametrize(("segments", "match"), [
    ((), "at least one segment"),
    ((Straight(-1.0),), r"segments\[0\].length_m"),
    ((Arc(0.0, 1.0),), r"segments\[0\].radius_m"),
    ((Arc(2.0, 7.0),), r"segments\[0\].angle_rad"),
    ((Straight(float("nan")),), r"segments\[0\].length_m"),
])
def test_constructor_rejects_meaningless_geometry(segments: tuple, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        Track(segments)


def test_locate_rejects_nan_and_bad_shapes() -> None:
    track = generated(0)
    with pytest.raises(ValueError, match="finite"):
        track.locate(math.nan, 0.0)
    with pytest.raises(ValueError, match=r"\(N, 2\)"):
        track.locate_many(np.zeros((3, 3)))


def test_heading_at_equals_the_vectorised_heading(eight) -> None:
    for track in (eight, load_named("oval"), load_named("straight")):
        s = np.linspace(0.0, track.length_m, 501)
        assert np.array_equal([track.heading_at(float(v)) for v in s], track.heading(s))
    with pytest.raises(ValueError, match="outside"):
        load_named("straight").heading_at(-1.0)


def test_a_gap_of_negative_length_is_refused() -> None:
    """Found by the track-file fuzz: validate() crashed with a KeyError on one."""
    from tfalda_sim.tracks.model import Gap, Line

    with pytest.raises(ValueError, match="gap's length_m must be ≥ 0"):
        Gap(Line.RIGHT, 1.0, -0.1)
    assert Gap(Line.RIGHT, 1.0, 0.0).length_m == 0.0


def test_tracks_with_the_same_road_share_their_index() -> None:
    """A copy with other cartons or gaps (the env drops the cartons) reuses the spatial
    index; another road gets its own."""

    from tfalda_sim.tracks import generate

    track = generate(3)
    bare = _replace(track, obstacles=(), gaps=())
    assert bare.index is track.index
    assert generate(4).index is not track.index
    x, y = track.position(1.0, -0.2)
    assert bare.locate(float(x), float(y)) == track.locate(float(x), float(y))


@pytest.mark.parametrize("seed", [0, 5, 17, 123])
def test_index_cells_hold_exactly_the_segments_within_reach(seed: int) -> None:
    """Every cell lists, once and in increasing order, each segment with a centre sample
    within reach of the cell's square (a plain numpy reference over all pairs)."""
    from tfalda_sim.tracks.index import _SAMPLE_STEP_M, EXTRA_REACH_M, _centre_samples

    track = generated(seed)
    t, index = track.table, track.index
    reach = track.half_road_m + EXTRA_REACH_M + _SAMPLE_STEP_M
    xs, ys, segs = _centre_samples(t.x0, t.y0, t.h0, t.kappa, t.length, _SAMPLE_STEP_M)
    cells = np.arange(index.nx * index.ny)
    lo_x = index.x0 + (cells % index.nx) * index.cell_m
    lo_y = index.y0 + (cells // index.nx) * index.cell_m
    for c in cells:
        dx = np.maximum(0.0, np.maximum(lo_x[c] - xs, xs - lo_x[c] - index.cell_m))
        dy = np.maximum(0.0, np.maximum(lo_y[c] - ys, ys - lo_y[c] - index.cell_m))
        want = np.unique(segs[dx * dx + dy * dy <= reach * reach])
        got = index.items[index.cell_start[c]:index.cell_start[c + 1]]
        assert np.array_equal(got, want), c


@pytest.mark.parametrize("seed", [0, 3, 42, 999])
def test_bounds_are_the_extremes_of_the_2_cm_samples(seed: int) -> None:
    """``bounds`` computes only the samples that can hold an extreme: the same numbers as
    all of ``sample(0.02)``."""
    track = generated(seed)
    _, pts = track.sample(0.02)
    pad = track.half_road_m + 0.3 + 0.01
    want = (pts[:, 0].min() - pad, pts[:, 1].min() - pad,
            pts[:, 0].max() + pad, pts[:, 1].max() + pad)
    assert track.bounds(0.3) == tuple(float(v) for v in want)


@pytest.mark.parametrize("seed", [0, 42])
def test_extreme_sample_indices_are_sorted_unique_and_hold_every_segment_end(seed: int) -> None:
    """The candidates of ``bounds``: strictly increasing sample indices inside the
    samples, every segment end's sample and the three on either side among them."""
    track = generated(seed)
    t, step = track.table, 0.02
    n = int(track.length_m / step) + 1
    idx = extreme_sample_indices(t.s0, t.length, t.h0, t.kappa, step, n)
    assert idx.dtype == np.int64 and len(idx) > 0
    assert np.all(np.diff(idx) > 0) and idx[0] >= 0 and idx[-1] < n
    held = set(idx.tolist())
    for end in np.concatenate([t.s0, t.s0 + t.length]):
        c = int(np.rint(end / step))
        assert {min(max(c + o, 0), n - 1) for o in range(-3, 4)} <= held


def test_with_elements_is_replace_keeping_what_the_road_computed() -> None:
    """A copy with other elements equals ``dataclasses.replace``'s, shares the road's
    computed tables (not computed again), and refuses fields that change the road."""
    import dataclasses
    import pickle

    track = generate(4)
    track.bounds()
    track.locate(track.start.x_m, track.start.y_m)
    gap = Gap(Line.LEFT, 1.0, 0.2)
    copy = track.with_elements(obstacles=[], gaps=[gap], name="copy")
    want = dataclasses.replace(track, obstacles=(), gaps=(gap,), name="copy")
    assert copy == want and copy.obstacles == () and copy.gaps == (gap,)
    assert copy.table is track.table  # not computed again
    assert copy.bounds() == want.bounds()
    for name in ("x0", "y0", "h0", "kappa", "length", "s0"):
        np.testing.assert_array_equal(getattr(copy.table, name), getattr(want.table, name))
    assert track.obstacles and track.name != "copy"  # the original is left as it was
    assert pickle.loads(pickle.dumps(copy)) == copy
    # The obstacles' corners, once computed, belong to those obstacles: a copy with other
    # cartons has its own (as replace's), one with the same keeps them.
    assert len(track.obstacle_corners_m) == len(track.obstacles)
    assert copy.obstacle_corners_m.shape == (0, 4, 2)
    one = track.with_elements(obstacles=track.obstacles[-1:])
    np.testing.assert_array_equal(
        one.obstacle_corners_m, dataclasses.replace(track, obstacles=track.obstacles[-1:])
        .obstacle_corners_m)
    assert track.with_elements(name="x").obstacle_corners_m is track.obstacle_corners_m
    with pytest.raises(TypeError, match=r"lane_width_m; use dataclasses\.replace"):
        track.with_elements(lane_width_m=0.5)


def test_every_track_field_is_road_or_element() -> None:
    """``with_elements`` keeps the road's computed tables: a new field must be classified
    (road fields change the road; element fields may be changed by ``with_elements``)."""
    import dataclasses

    from tfalda_sim.tracks.model import ELEMENT_FIELDS

    road = {"segments", "closed", "start", "lane_width_m"}
    assert road | set(ELEMENT_FIELDS) == {f.name for f in dataclasses.fields(Track)}
    assert not road & set(ELEMENT_FIELDS)


@pytest.mark.parametrize("seed", range(0, 40, 3))
def test_obstacle_corners_are_each_obstacles_own_pose_read_only(seed: int) -> None:
    """``Track.obstacle_corners_m`` takes the poses of all obstacles in one call: each
    box equals the one made from that obstacle's own pose (the same bits), a box of
    ``length_m`` × ``width_m`` about its lane's centre moved by ``offset_m``; the cached
    array is read-only and ``rules.obstacle_corners`` hands out copies."""
    from tfalda_sim.tracks.rules import obstacle_corners

    track = generated(seed)
    corners = track.obstacle_corners_m
    assert corners.shape == (len(track.obstacles), 4, 2) and not corners.flags.writeable
    for k, ob in enumerate(track.obstacles):
        sign = -1.0 if ob.lane is Lane.RIGHT else 1.0
        x, y, h = (float(v) for v in track.pose(ob.s_m, sign * 0.5 * track.lane_width_m
                                                + ob.offset_m))
        t = np.array([math.cos(h), math.sin(h)])
        n = np.array([-math.sin(h), math.cos(h)])
        c, hl, hw = np.array([x, y]), 0.5 * ob.length_m, 0.5 * ob.width_m
        own = np.array([c + hl * t + hw * n, c - hl * t + hw * n, c - hl * t - hw * n,
                        c + hl * t - hw * n])
        assert np.array_equal(corners[k], own)
        assert math.dist(own[0], own[1]) == pytest.approx(ob.length_m)
        assert math.dist(own[1], own[2]) == pytest.approx(ob.width_m)
        mine = obstacle_corners(track, k)
        mine[:] = 0.0
        assert np.array_equal(track.obstacle_corners_m[k], own)
    assert sum(len(generated(s).obstacles) for s in range(0, 40, 3)) > 0


def _numpy_pose(track: Track, s: np.ndarray | float, lateral_m: np.ndarray | float = 0.0
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pose query as plain numpy expressions (``Track.pose`` before its kernels)."""
    t = track.table
    s = np.asarray(s, dtype=np.float64)
    if track.closed:
        s = np.mod(s, track.length_m)
    idx = np.minimum(np.maximum(np.searchsorted(t.s0, s, side="right") - 1, 0), len(t.s0) - 1)
    u = s - t.s0[idx]
    h0, k = t.h0[idx], t.kappa[idx]
    h = h0 + k * u
    straight = k == 0.0
    safe_k = np.where(straight, 1.0, k)
    sin_h0, cos_h0, sin_h, cos_h = np.sin(h0), np.cos(h0), np.sin(h), np.cos(h)
    x = np.where(straight, t.x0[idx] + u * cos_h0, t.x0[idx] + (sin_h - sin_h0) / safe_k)
    y = np.where(straight, t.y0[idx] + u * sin_h0, t.y0[idx] - (cos_h - cos_h0) / safe_k)
    lat = np.asarray(lateral_m, dtype=np.float64)
    return x - lat * sin_h, y + lat * cos_h, h


def _same_bits(a: object, b: object) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.tobytes() == b.tobytes()


@pytest.mark.parametrize("name", ["seed-3", "seed-11", "oval", "oval -0.0", "open"])
def test_pose_gives_the_bits_of_the_numpy_expressions(name: str) -> None:
    """``Track.pose`` (two kernels around numpy's sine and cosine) gives bit for bit what
    the numpy expressions give: every arc length, wrapped or not (−0.0 too), scalars,
    vectors and 2-d arrays, with a lateral offset per query, one for all or one of
    another shape (x and y broadcast, the heading keeps the shape of s), and a straight
    whose start heading is −0.0 (whose heading h0 + 0·u is +0.0)."""
    if name == "open":
        track = Track((Straight(1.0), Arc(2.0, 1.0), Straight(0.5)), closed=False,
                      start=Pose(0.3, -0.2, -0.0))
    elif name == "oval -0.0":
        track = _replace(load_named("oval"), start=Pose(1.0, 2.0, -0.0))
    elif name == "oval":
        track = load_named("oval")
    else:
        track = generate(int(name.split("-")[1]))
    total = track.length_m
    rng = np.random.default_rng(0)
    ends = np.concatenate((track.table.s0, track.table.s0 + track.table.length))
    if track.closed:
        queries: list[tuple[object, object]] = [
            (rng.uniform(-2 * total, 3 * total, 500), rng.uniform(-0.6, 0.6, 500)),
            (np.array([0.0, -0.0, total, -total, 2 * total, np.nextafter(total, 0.0),
                       -1e-20, -5e-324, 1e300, -1e300]), 0.1),
            (-1e-20, 0.0),  # np.mod gives the length itself
        ]
    else:
        queries = [(rng.uniform(0.0, total, 500), rng.uniform(-0.6, 0.6, 500))]
    queries += [
        (np.linspace(0.0, total, 531)[:-1], 0.0),
        (float(rng.uniform(0.0, total)), -0.2),
        (rng.uniform(0.0, total, (3, 4)), rng.uniform(-0.5, 0.5, (3, 4))),
        (np.clip(ends, 0.0, total), -0.1),
        (0.0, 0.0),
        (-0.0, 0.0),
        (1.0, np.array([0.1, 0.2])),
        (rng.uniform(0.0, total, 3), rng.uniform(-0.5, 0.5, (2, 1))),
        (rng.uniform(0.0, total, (3, 1)), rng.uniform(-0.5, 0.5, 3)),
        (rng.uniform(0.0, total, 3), np.array([[0.1]])),
        (0.5, np.array([0.2])),
    ]
    for s, lateral in queries:
        got, want = track.pose(s, lateral), _numpy_pose(track, s, lateral)
        for g, w in zip(got, want, strict=True):
            assert _same_bits(g, w)
            assert np.ndim(g) > 0 or isinstance(g, np.float64)


def test_pose_rejects_what_it_cannot_place() -> None:
    closed = generate(3)
    with pytest.raises(ValueError, match="must be finite"):
        closed.pose(np.array([1.0, np.nan]))
    with pytest.raises(ValueError, match="must be finite"):
        closed.pose(np.inf)
    open_track = Track((Straight(1.0), Arc(2.0, 1.0)), closed=False)
    with pytest.raises(ValueError, match="outside the open track"):
        open_track.pose(np.array([0.5, 3.5]))
    with pytest.raises(ValueError, match="outside the open track"):
        open_track.pose(-0.1)



@pytest.mark.parametrize("name", ["seed-3", "seed-40", "oval", "open"])
def test_extreme_samples_are_those_of_linspace(name: str) -> None:
    """The candidate samples of ``bounds`` are computed alone, as ``np.linspace`` computes
    them among all (bit for bit, the open track's end included)."""
    if name == "open":
        track = Track((Straight(1.013), Arc(2.0, 1.0), Straight(0.517)), closed=False)
    elif name == "oval":
        track = load_named("oval")
    else:
        track = generate(int(name.split("-")[1]))
    for step in (0.02, 0.05, 0.3):
        n = max(2, math.ceil(track.length_m / step))
        every = np.linspace(0.0, track.length_m, n + 1)
        got = track._extreme_samples(step)
        idx = np.rint(got / (track.length_m / n)).astype(np.int64)
        assert _same_bits(got, every[idx])
        if not track.closed:
            assert got[-1] == track.length_m
