"""The car's body in a clip (``camera fit --bonnet auto`` on a recording): what does not
move while the road does.

Two kinds of body, found across the clip's frames and joined (per column the higher):

- **bright structures that stay put** — cables, a print, screws: the marking search's
  own bright narrow structures (``fit.marking_mask``), found at the same place (within a
  shake) in most frames while the road moves (its markings move past, or the frames
  change elsewhere: the hall, the mat's border). Only those wholly in the
  image's lower half count (a body over more hides the road), and not those that run on,
  unbroken, into the moving road in most frames (a lane line's near end stays put for a
  car that keeps its place in the lane).
- **a dark bonnet's edge** — the single-frame detector (``fit.detect_bonnet``) run on
  each frame, kept when it finds the same edge in most of them (an edge that moves with
  the car's weaving is the road's, not the car's).

The result is a polygon for ``Bonnet.polygon``: everything below it in a column is body.
"""

from __future__ import annotations

import itertools
import math

import cv2
import numpy as np

from .fit import MountFitError, detect_bonnet, marking_mask
from .limits import MIN_BONNET_TOP_SHARE

STATIC_MIN_FRAMES: int = 3
"""Fewest frames that can show what stays put [1]: with two, a solid line that did not
move between them looks like the body."""

STATIC_SHARE: float = 0.6
"""A pixel whose bright structure is there in at least this share of the frames stays
put [1]: a road marking passes a pixel in a few frames of a moving car, the body's
structures are in all of them (a share, not all: a frame with the body shaken or
changed is allowed)."""

STATIC_SHAKE_SHARE: float = 0.004
"""How far a body's structure may shake between frames [share of the image diagonal]:
3.6 px on a 752×480 frame, a cable on a driving car."""

MIN_MOVING_SHARE: float = 0.2
"""At least this share of the pixels where a bright structure was seen must see it move
[1]: else the road did not move in the clip (a parked car), and what stays put is road
as well as body."""

MOTION_DN: int = 30
"""A pixel changes between the clip's frames when its grey level spans more than this
[DN of 255]: ten times a camera's noise, a marking or an edge passing."""

MIN_MOTION_SHARE: float = 0.02
"""…and the clip moves when at least this share of its pixels change [1] (the hall's
edges, the mat's border, markings), even with no bright structure moving (an empty
road)."""

RUNS_ON_SHARE: float = 0.05
"""A structure that stays put runs on into the road in a frame when the frame's bright
structure through it reaches higher up than its own top by more than this share of the
image height [1] (toward the horizon, where a lane line goes)."""

EDGE_AGREEMENT_PX: float = 3.0
"""A dark body's edge found in two frames is the same edge when its rows agree within
this [px on a 480-row frame, scaled with the height]: the detector's blur."""

EDGE_SHARE: float = 0.6
"""…in at least this share of the frames [1]."""

POLYGON_BINS: int = 96
"""Column bins of the static body's outline [1]: its top per bin, a step polygon (two
vertices per bin)."""


def _static_structures(frames: list[np.ndarray], marking_width_px: int
                       ) -> tuple[np.ndarray | None, str]:
    """``(H, W)`` bool of the bright structures that stay put, or None and why."""
    h, w = frames[0].shape
    shake = max(1, int(round(STATIC_SHAKE_SHARE * math.hypot(w, h))))
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * shake + 1, 2 * shake + 1))
    seen = np.zeros((h, w), np.uint16)
    near = np.zeros((h, w), np.uint16)
    masks = []
    for frame in frames:
        m = marking_mask(frame, marking_width_px).astype(np.uint8)
        masks.append(m)
        seen += m
        near += cv2.dilate(m, kernel)
    n = len(frames)
    stays = near >= STATIC_SHARE * n
    ever = seen > 0
    if not ever.any():
        return None, "no bright structures in the clip"
    moving = float(np.mean(~stays[ever]))
    lo = np.minimum.reduce(frames)
    hi = np.maximum.reduce(frames)
    changing = float(np.mean((hi.astype(np.int16) - lo) > MOTION_DN))
    if moving < MIN_MOVING_SHARE and changing < MIN_MOTION_SHARE:
        return None, (f"only {moving:.0%} of the clip's bright structures and {changing:.1%} "
                      "of its pixels change: the road does not move in it (a parked car?), "
                      "so what stays put is not only the car")
    body = (stays & ever).astype(np.uint8)
    if not body.any():
        return None, "nothing bright stays put"
    # Join a structure's pieces (a cable's highlights) before judging where it reaches.
    joined = cv2.dilate(body, kernel)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(joined, connectivity=8)
    lowest_top = MIN_BONNET_TOP_SHARE * h
    keep = np.zeros(count, bool)
    keep[1:] = stats[1:, cv2.CC_STAT_TOP] >= lowest_top
    if not keep.any():
        return None, "what stays put reaches into the upper half (road lines, not the car)"
    # A lane line's near end stays put for a car that keeps its place in the lane, but
    # in the frames it runs on, unbroken, into the far road that moves: not the car's.
    continues = np.zeros(count, np.int32)
    runs_on_rows = RUNS_ON_SHARE * h
    for m in masks:
        _, lab_m, stats_m, _ = cv2.connectedComponentsWithStats(m, connectivity=8)
        hit = np.zeros(count, bool)
        on = (m > 0) & (joined > 0)
        pairs = np.unique(np.stack([labels[on], lab_m[on]]), axis=1)
        for c, k in pairs.T:
            # the frame's structure through it reaches higher up, toward the horizon
            if k and stats_m[k, cv2.CC_STAT_TOP] < stats[c, cv2.CC_STAT_TOP] - runs_on_rows:
                hit[c] = True
        continues += hit
    keep &= continues < STATIC_SHARE * n
    if not keep.any():
        return None, "what stays put runs on into the moving road (lane lines, not the car)"
    return keep[labels] & (joined > 0), ""


def _static_edge(frames: list[np.ndarray]) -> np.ndarray | None:
    """The dark body's polygon (``detect_bonnet``) when most frames find the same edge."""
    polys = []
    for frame in frames:
        try:
            polys.append(detect_bonnet(frame))
        except MountFitError:
            polys.append(None)
    found = [p for p in polys if p is not None]
    if len(found) < EDGE_SHARE * len(frames):
        return None
    rows = np.array([p[1:-1, 1] for p in found])
    median = np.median(rows, axis=0)
    h = frames[0].shape[0]
    tol = EDGE_AGREEMENT_PX * h / 480.0
    agree = np.max(np.abs(rows - median), axis=1) <= tol
    if agree.sum() < EDGE_SHARE * len(frames):
        return None  # an edge that moves with the car is the road's
    poly = found[int(np.flatnonzero(agree)[0])].copy()
    poly[1:-1, 1] = np.median(rows[agree], axis=0)
    return poly


def static_body(frames: list[np.ndarray], marking_width_px: int
                ) -> tuple[np.ndarray | None, list[str]]:
    """The car's body across the clip's grey ``frames`` (one size, uint8): a polygon
    ``(n, 2)`` [px] for ``Bonnet.polygon`` (None: no body found) and notes on what was
    found or why nothing was. ``marking_width_px`` [px] is the marking search's top-hat."""
    if len(frames) < STATIC_MIN_FRAMES:
        raise ValueError(f"a static body needs at least {STATIC_MIN_FRAMES} frames, got "
                         f"{len(frames)}")
    h, w = frames[0].shape
    notes = []
    structures, why = _static_structures(frames, marking_width_px)
    top = np.full(w, np.inf)
    if structures is not None:
        cols = structures.any(axis=0)
        top[cols] = np.argmax(structures[:, cols], axis=0)
        notes.append(f"bright structures that stay put in {int(cols.sum())} of {w} columns")
    else:
        notes.append(f"no bright structure of the car: {why}")
    edge = _static_edge(frames)
    if edge is not None:
        mask = np.zeros((h, w), np.uint8)
        cv2.fillPoly(mask, [np.rint(edge).astype(np.int32)], 1)
        has = mask.any(axis=0)
        top[has] = np.minimum(top[has], np.argmax(mask[:, has], axis=0))
        notes.append("a dark body's edge that stays put")
    else:
        notes.append("no dark body's edge that stays put")
    if not np.isfinite(top).any():
        return None, notes
    # A step polygon: per column bin its highest body row, the bottom row where none.
    edges = np.linspace(0, w, POLYGON_BINS + 1).round().astype(int)
    vertices = [[0.0, h - 1.0]]
    for a, b in itertools.pairwise(edges):
        if b <= a:
            continue
        row = float(np.min(top[a:b]))
        row = h - 1.0 if not math.isfinite(row) else max(row, math.ceil(MIN_BONNET_TOP_SHARE
                                                                         * h))
        vertices += [[float(a), row], [float(b - 1), row]]
    vertices.append([w - 1.0, h - 1.0])
    return np.array(vertices), notes
