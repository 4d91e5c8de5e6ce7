"""Named track files: present, valid, equal to their documented construction."""

from __future__ import annotations

import math

import pytest

from tfalda_sim.tracks import NAMED_TRACKS, Arc, load_named
from tfalda_sim.tracks.fileformat import track_to_dict
from tfalda_sim.tracks.named import named_path
from tfalda_sim.tracks.rules import min_centre_radius_m
from tools.make_named_tracks import THESIS_FPS, THESIS_SPEED_M_S, build


@pytest.mark.parametrize("name", NAMED_TRACKS)
def test_file_equals_its_construction(name: str) -> None:
    assert track_to_dict(load_named(name)) == track_to_dict(build()[name])


def test_straight_strip_is_at_least_8_m() -> None:
    assert load_named("straight").length_m >= 8.0


def test_left_curve_is_at_the_tightest_legal_radius() -> None:
    arcs = [s for s in load_named("left-curve").segments if isinstance(s, Arc)]
    assert len(arcs) == 1 and arcs[0].angle_rad > 0
    assert arcs[0].radius_m == pytest.approx(min_centre_radius_m())


def test_thesis_track_matches_the_183_frame_run() -> None:
    track = load_named("thesis")
    step = THESIS_SPEED_M_S / THESIS_FPS
    arc = track.segments[1]
    lane_arc = (arc.radius_m + 0.5 * track.lane_width_m) * arc.angle_rad  # the right lane
    assert lane_arc / step == pytest.approx(80)  # frames 81-160 show the curve
    assert isinstance(track.segments[1], Arc) and track.segments[1].angle_rad > 0
    assert track.length_m > 0.5 + 183 * step + 2.0  # room for all frames plus look-ahead


def test_figure_eight_has_a_right_angled_intersection() -> None:
    track = load_named("figure-eight")
    (x,) = track.intersections
    dh = float(track.heading(x.s1_m) - track.heading(x.s2_m))
    assert abs(math.cos(dh)) < 1e-9


def test_unknown_name_lists_the_known_ones() -> None:
    with pytest.raises(ValueError, match="known: straight, left-curve"):
        named_path("monza")
