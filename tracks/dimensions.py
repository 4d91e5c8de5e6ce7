"""The Carolo-Cup rulebook's track dimensions, each a named constant with unit and source.

Sources: Carolo-Cup rules 2013–2016 as indexed in ``shared/REFERENCE.md`` ("Carolo-Cup
track"). Values marked *ours* are tolerances the rules do not state; they are chosen
here and documented so that a user can see exactly what is checked
(``tracks.rules.validate``).
"""

from __future__ import annotations

import math

LINE_WIDTH_M: float = 0.020
"""Width of every longitudinal marking line [m]. Rules: ≈ 20 mm, white on black."""

LANE_WIDTH_M: float = 0.400
"""Default lane width, line centre to line centre [m]. Rules: 820 mm road between the
outer edges of the side lines ≈ 2 × 400 mm + 20 mm."""

LANE_WIDTH_RANGE_M: tuple[float, float] = (0.35, 0.45)
"""Lane widths accepted by ``validate`` [m]. *Ours*: the rules say "≈ 400 mm"; we allow
±50 mm for experiments with narrower or wider roads."""

CENTRE_DASH_M: float = 0.200
"""Length of one dash of the dashed centre line [m]. Rules: 200 mm."""

CENTRE_DASH_GAP_M: float = 0.200
"""Gap between two dashes of the centre line [m]. Rules: 200 mm."""

START_LINE_WIDTH_M: float = 0.040
"""Width (along the road) of the start line [m]. Rules: 40 mm, across the road."""

STOP_LINE_WIDTH_M: float = 0.040
"""Width (along the road) of an intersection's stop line [m]. Rules: 40 mm."""

MIN_INNER_EDGE_RADIUS_M: float = 1.000
"""Tightest curve: radius of the inner edge of the inner side line [m]. Rules: ≥ 1000 mm."""

MAX_MARKING_GAP_M: float = 1.000
"""Longest stretch over which any one line may be missing [m]. Rules: ≤ 1000 mm."""

MAX_LINES_MISSING: int = 2
"""Most lines that may be missing at the same place (except at intersections). Rules."""

OBSTACLE_MIN_LENGTH_M: float = 0.100
"""Shortest obstacle carton, along the road [m]. Rules: ≥ 100 mm."""

OBSTACLE_WIDTH_RANGE_M: tuple[float, float] = (0.100, 0.400)
"""Obstacle carton width, across the road [m]. Rules: 100–400 mm."""

OBSTACLE_HEIGHT_RANGE_M: tuple[float, float] = (0.100, 0.240)
"""Obstacle carton height [m]. Rules: 100–240 mm."""

OBSTACLE_MIN_SPACING_M: float = 1.000
"""Free road between two obstacles, measured along the track [m]. Rules: ≥ 1000 mm."""

PARALLEL_ROAD_MIN_GAP_M: float = 0.050
"""Gap between the outer line edges of two neighbouring roads [m]. Rules: ≥ 50 mm."""

MAT_EDGE_MARGIN_M: float = 0.300
"""Distance of the road from the edge of the mat [m]. Rules: ≥ 300 mm."""

CLOSURE_TOLERANCE_M: float = 0.001
"""A closed loop's end must meet its start within this distance [m] (the tracks'
specification: 1 mm)."""

CLOSURE_TOLERANCE_RAD: float = math.radians(0.1)
"""A closed loop's end heading must match its start within this angle [rad] (the
tracks' specification: 0.1°)."""

INTERSECTION_ANGLE_TOLERANCE_RAD: float = math.radians(1.0)
"""Allowed deviation of an intersection from a right angle [rad]. *Ours*; rules: right-angled."""

INTERSECTION_APPROACH_M: float = 1.000
"""Straight road required on each side of an intersection's crossing point [m]. *Ours*:
room for the crossing road (≈ 0.41 m), the 40 mm stop line and a straight approach."""
