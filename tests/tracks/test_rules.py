"""The rule checker: each rule can fail, and every violation is reported."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from tests.conftest import generated
from tfalda_sim.tracks import (
    Arc,
    Gap,
    Intersection,
    Lane,
    Line,
    Obstacle,
    Straight,
    Track,
    load_named,
    validate,
)
from tfalda_sim.tracks.geometry import project
from tfalda_sim.tracks.rules import (
    OVERLAP_SAMPLE_STEP_M,
    _close_approaches,
    min_centre_radius_m,
    min_road_clearance_m,
)


def rules_of(track: Track) -> list[str]:
    return [v.rule for v in validate(track)]


def test_min_centre_radius_follows_from_the_inner_edge_rule() -> None:
    assert min_centre_radius_m() == pytest.approx(1.41)
    assert min_road_clearance_m() == pytest.approx(0.87)


@pytest.mark.parametrize("name", ["straight", "left-curve", "thesis", "oval", "figure-eight"])
def test_named_tracks_are_valid(name: str) -> None:
    assert validate(load_named(name)) == []


def test_tight_curve_is_reported_with_its_field() -> None:
    track = Track((Straight(2.0), Arc(1.2, math.pi / 2), Straight(2.0)), closed=False)
    (v,) = validate(track)
    assert (v.rule, v.field) == ("min_radius", "segments[1].radius_m")
    assert "1.200 m" in v.message and "1.410 m" in v.message


def test_curve_at_exactly_the_minimum_radius_is_legal() -> None:
    track = Track((Straight(1.0), Arc(1.41, math.pi / 2)), closed=False)
    assert validate(track) == []


def test_loop_that_does_not_close_is_reported() -> None:
    oval = load_named("oval")
    broken = replace(oval, segments=(*oval.segments[:-1], Straight(2.5 + 0.002)))
    assert rules_of(broken) == ["closure"]
    almost = replace(oval, segments=(*oval.segments[:-1], Straight(2.5 + 0.0005)))
    assert rules_of(almost) == []  # 0.5 mm is within the 1 mm tolerance


def test_crossing_without_declared_intersection_is_an_overlap() -> None:
    eight = load_named("figure-eight")
    violations = validate(replace(eight, intersections=()))
    assert {v.rule for v in violations} == {"overlap"}
    x = eight.intersections[0]
    assert any(abs(v.s_m - x.s1_m) < 1.0 for v in violations)


def test_parallel_roads_closer_than_the_rules_allow() -> None:
    r = 1.41
    # A spiral that comes back 0.5 m beside its own first straight.
    spiral = Track((Straight(5.0), Arc(r, math.pi / 2), Straight(0.5), Arc(r, math.pi / 2),
                    Straight(2.0), Arc(r, math.pi / 2), Arc(r, math.pi / 2), Straight(1.0)),
                   closed=False)
    violations = validate(spiral)
    assert [v.rule for v in violations] == ["overlap"]
    assert "0.500 m" in violations[0].message
    # The same spiral 1.0 m apart keeps the 50 mm gap between the roads' edges.
    wider = replace(spiral, segments=(*spiral.segments[:2], Straight(1.0), *spiral.segments[3:]))
    assert validate(wider) == []


def test_gap_longer_than_a_metre() -> None:
    strip = load_named("straight")
    assert rules_of(replace(strip, gaps=(Gap(Line.LEFT, 2.0, 1.0),))) == []
    assert rules_of(replace(strip, gaps=(Gap(Line.LEFT, 2.0, 1.2),))) == ["gap_length"]
    # Two touching gaps of one line make one long missing stretch.
    two = (Gap(Line.LEFT, 2.0, 0.8), Gap(Line.LEFT, 2.7, 0.8))
    assert rules_of(replace(strip, gaps=two)) == ["gap_length"]
    # Exactly end to end (the second starts where the first ends, to rounding) too.
    end_to_end = (Gap(Line.LEFT, 2.0, 0.8), Gap(Line.LEFT, 2.0 + 0.8, 0.8))
    assert rules_of(replace(strip, gaps=end_to_end)) == ["gap_length"]
    # Separated by 20 mm of paint: two gaps, both within the rules.
    apart = (Gap(Line.LEFT, 2.0, 0.8), Gap(Line.LEFT, 2.82, 0.8))
    assert rules_of(replace(strip, gaps=apart)) == []


def test_at_most_two_lines_missing_at_once() -> None:
    strip = load_named("straight")
    two = (Gap(Line.LEFT, 2.0, 0.8), Gap(Line.RIGHT, 2.2, 0.8))
    assert rules_of(replace(strip, gaps=two)) == []
    three = (*two, Gap(Line.CENTRE, 2.5, 0.5))
    assert rules_of(replace(strip, gaps=three)) == ["lines_missing"]
    # A third line's gap that begins exactly where another ends is not a third at once.
    handover = (*two, Gap(Line.CENTRE, 2.8, 0.5))
    assert rules_of(replace(strip, gaps=handover)) == []


def test_obstacle_rules() -> None:
    strip = load_named("straight")
    ok = Obstacle(3.0, Lane.RIGHT, 0.2, 0.3, 0.15)
    assert rules_of(replace(strip, obstacles=(ok,))) == []
    too_wide = replace(ok, width_m=0.5)
    assert "obstacle_size" in rules_of(replace(strip, obstacles=(too_wide,)))
    too_high = replace(ok, height_m=0.3)
    assert rules_of(replace(strip, obstacles=(too_high,))) == ["obstacle_size"]
    into_other_lane = replace(ok, offset_m=0.15)
    assert rules_of(replace(strip, obstacles=(into_other_lane,))) == ["obstacle_blocks"]
    close_pair = (ok, replace(ok, s_m=3.9, lane=Lane.LEFT))
    assert rules_of(replace(strip, obstacles=close_pair)) == ["obstacle_spacing"]


def test_intersection_must_be_a_real_right_angled_crossing() -> None:
    oval = load_named("oval")
    bogus = replace(oval, intersections=(Intersection(1.0, 6.0),))
    rules = rules_of(bogus)
    assert "intersection_position" in rules
    assert "intersection_approach" in rules  # s = 6 m lies in a curve


def test_every_violation_is_reported_not_just_the_first() -> None:
    oval = load_named("oval")
    bad = replace(
        oval,
        segments=(oval.segments[0], Arc(1.0, math.pi), *oval.segments[2:]),
        gaps=(Gap(Line.LEFT, 5.0, 1.5),),
        obstacles=(Obstacle(6.0, Lane.RIGHT, 0.2, 0.6, 0.15),),
        start_line_s_m=None,
    )
    rules = set(rules_of(bad))
    assert {"min_radius", "closure", "gap_length", "obstacle_size", "start_line"} <= rules


def test_generated_tracks_pass_every_rule() -> None:
    for seed in range(30):
        assert validate(generated(seed)) == []


def _close_approaches_unfiltered(track: Track) -> list[tuple[float, float, float]]:
    """``_close_approaches`` without its cheap distance bound: every segment's pieces
    outside the three windows are projected on (the plain definition)."""
    clearance = min_road_clearance_m(track.lane_width_m)
    exclude = 0.5 * math.pi * clearance
    t, total = track.table, track.length_m
    s, pts = track.sample(OVERLAP_SAMPLE_STEP_M)
    shifts = (-total, 0.0, total) if track.closed else (0.0,)
    hits = []
    for si, (px, py) in zip(s, pts, strict=True):
        for j in range(len(t.length)):
            pieces = [(t.s0[j], t.s0[j] + t.length[j])]
            for shift in shifts:
                lo, hi = si - exclude + shift, si + exclude + shift
                pieces = [q for a, b in pieces for q in (
                    [(a, b)] if hi <= a or lo >= b else
                    [*([(a, lo)] if a < lo else []), *([(hi, b)] if hi < b else [])])]
            best = (math.inf, 0.0)
            for a, b in pieces:
                u, _, dist = project(t.x0[j], t.y0[j], t.h0[j], t.kappa[j], a - t.s0[j],
                                     b - t.s0[j], px, py)
                best = min(best, (dist, t.s0[j] + u), key=lambda v: v[0])
            if best[0] < clearance:
                hits.append((float(si), float(best[1]), float(best[0])))
    return hits


@pytest.mark.parametrize("case", ["spiral", "figure-eight", "generated"])
def test_close_approaches_bound_drops_no_hit(case: str) -> None:
    """The kernel's squared distance bound only skips segments that cannot come closer
    than the clearance: its hits are the unfiltered definition's, exactly."""
    if case == "spiral":
        r = 1.41
        track = Track((Straight(5.0), Arc(r, math.pi / 2), Straight(0.5), Arc(r, math.pi / 2),
                       Straight(2.0), Arc(r, math.pi / 2), Arc(r, math.pi / 2),
                       Straight(1.0)), closed=False)
    elif case == "figure-eight":
        track = load_named("figure-eight")
    else:
        track = generated(3)
    clearance = min_road_clearance_m(track.lane_width_m)
    t = track.table
    s, pts = track.sample(OVERLAP_SAMPLE_STEP_M)
    got = _close_approaches(np.column_stack([s, pts]), t.x0, t.y0, t.h0, t.kappa, t.length,
                            t.s0, track.length_m, track.closed, 0.5 * math.pi * clearance,
                            clearance)
    want = _close_approaches_unfiltered(track)
    assert [tuple(map(float, h)) for h in got] == want
    if case != "generated":
        assert want  # the crossing and the spiral do come close
