"""Build the named track files in ``tracks/data/`` from their documented geometry.

Run ``python tools/make_named_tracks.py --force`` after changing a definition; the test
suite checks that the committed files equal what this script builds.
"""

from __future__ import annotations

import argparse
import math
import sys

from tfalda_sim.evaluation.scenarios import THESIS_SPEED_M_S, THESIS_START_S_M
from tfalda_sim.evaluation.trajectory import FRAME_RATE_HZ as THESIS_FPS
from tfalda_sim.tracks.dimensions import LANE_WIDTH_M
from tfalda_sim.tracks.fileformat import save_track
from tfalda_sim.tracks.model import Arc, Intersection, Pose, Straight, Track
from tfalda_sim.tracks.named import NAMED_TRACKS, named_path
from tfalda_sim.tracks.rules import min_centre_radius_m

THESIS_LOOKAHEAD_M = 1.0
"""Distance [m] from the car to the middle of the ROIs: a frame "shows the curve" once the
ROIs reach it (thesis: look-ahead 1.8–2 m, upper ROI row ≈ 1–1.2 m)."""


def thesis_track() -> Track:
    """Straight → left curve → straight, laid out so that at 15 km/h and 50 frames/s,
    starting at s = 0.5 m, frames 0–80 show the straight, 81–160 the curve and 161–182
    the final straight (thesis figure 4.6's 183-frame run)."""
    step = THESIS_SPEED_M_S / THESIS_FPS  # 0.0833 m per frame, along the car's lane
    first = THESIS_START_S_M + 81 * step + THESIS_LOOKAHEAD_M
    # the car drives the right lane, outside the left curve: 80 steps on a radius 0.2 m
    # larger than the centre line's
    radius = 80 * step / math.pi - 0.5 * LANE_WIDTH_M
    last = 22 * step + 2.5  # the remaining frames plus the camera's look-ahead
    return Track(
        (Straight(first), Arc(radius, math.pi), Straight(last)),
        closed=False, name="thesis",
        description=(
            "Thesis test drive (ch. 4, fig. 4.6): 183 frames at 15 km/h (scaled), 50 frames/s, "
            "car starting at s = 0.5 m: frames 0-80 straight, 81-160 a 180-degree left curve, "
            "161-182 straight."))


def figure_eight() -> Track:
    """Two lobes of two 135° curves each; the crossing straights meet at a right angle."""
    r, top = 2.0, 3.0
    leg = r + top / math.sqrt(2)  # from the crossing to the first curve
    turn = 0.75 * math.pi
    segments = (Straight(top / 2), Arc(r, turn), Straight(2 * leg), Arc(r, -turn), Straight(top),
                Arc(r, -turn), Straight(2 * leg), Arc(r, turn), Straight(top / 2))
    s1 = top / 2 + r * turn + leg
    s2 = s1 + leg + 2 * r * turn + top + leg
    return Track(segments, closed=True, start=Pose(0.0, 0.0, math.pi), start_line_s_m=0.0,
                 intersections=(Intersection(s1, s2),), name="figure-eight",
                 description="Figure-eight with one right-angled intersection; 2 m curves.")


def build() -> dict[str, Track]:
    r_min = min_centre_radius_m()
    return {
        "straight": Track((Straight(10.0),), closed=False, name="straight",
                          description="10 m straight test strip."),
        "left-curve": Track(
            (Straight(3.0), Arc(r_min, math.pi / 2), Straight(3.0)), closed=False,
            name="left-curve",
            description="3 m straight, 90-degree left curve at the tightest legal centre-line "
                        "radius, 3 m straight."),
        "thesis": thesis_track(),
        "oval": Track((Straight(2.5), Arc(2.0, math.pi), Straight(5.0), Arc(2.0, math.pi),
                       Straight(2.5)), closed=True, start_line_s_m=0.0, name="oval",
                      description="Oval: 5 m straights, 2 m curves, counter-clockwise."),
        "figure-eight": figure_eight(),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--force", action="store_true", help="overwrite existing files")
    args = parser.parse_args(argv)
    tracks = build()
    assert tuple(tracks) == NAMED_TRACKS
    for name, track in tracks.items():
        print(save_track(track, named_path(name), overwrite=args.force))
    return 0


if __name__ == "__main__":
    sys.exit(main())
