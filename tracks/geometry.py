"""Closed-form geometry of one track segment (a straight or a circular arc).

A segment is described by its start pose ``(x0, y0, h0)`` [m, m, rad], its signed
curvature ``kappa`` [1/m] (0 for a straight, > 0 turning left) and its length [m].
The local coordinate ``u`` [m] runs along the segment's centre line from 0 to its
length; the lateral offset ``d`` [m] is measured along the left normal
``n = (-sin h, cos h)``, so ``d > 0`` is left of the centre line.

These kernels are compiled with numba because the reverse query (world point →
arc length) runs every env step and the rasteriser and rule checker call them
millions of times per track.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class Pose:
    """A pose on the mat: position [m] and heading [rad]."""

    x_m: float = 0.0
    y_m: float = 0.0
    heading_rad: float = 0.0


@dataclass(frozen=True)
class SegmentTable:
    """The chain laid out in the world: one entry per segment (arrays of equal length)."""

    x0: np.ndarray
    y0: np.ndarray
    h0: np.ndarray
    kappa: np.ndarray
    length: np.ndarray
    s0: np.ndarray
    end: Pose


@njit(cache=True)
def pose_at(x0: float, y0: float, h0: float, kappa: float, u: float) -> tuple[float, float, float]:
    """Centre-line pose ``(x [m], y [m], heading [rad])`` at ``u`` [m] along a segment."""
    if kappa == 0.0:
        return x0 + u * math.cos(h0), y0 + u * math.sin(h0), h0
    h = h0 + kappa * u
    return (
        x0 + (math.sin(h) - math.sin(h0)) / kappa,
        y0 - (math.cos(h) - math.cos(h0)) / kappa,
        h,
    )


@njit(cache=True)
def project(
    x0: float,
    y0: float,
    h0: float,
    kappa: float,
    u_lo: float,
    u_hi: float,
    px: float,
    py: float,
) -> tuple[float, float, float]:
    """Nearest point of the segment part ``u in [u_lo, u_hi]`` to the point ``(px, py)``.

    Returns ``(u [m], d [m], distance [m])``: the local coordinate of the foot point,
    the signed lateral offset of the point from the centre line (measured along the
    normal at the foot point) and the Euclidean distance to the foot point.
    """
    if kappa == 0.0:
        c = math.cos(h0)
        s = math.sin(h0)
        dx = px - x0
        dy = py - y0
        u = dx * c + dy * s
        d = -dx * s + dy * c
        if u_lo <= u <= u_hi:
            return u, d, abs(d)
        u = u_lo if u < u_lo else u_hi
        ex = dx - u * c
        ey = dy - u * s
        return u, -ex * s + ey * c, math.hypot(ex, ey)
    inv = 1.0 / kappa
    sign = 1.0 if kappa > 0.0 else -1.0
    radius = abs(inv)
    # Circle centre: one radius along the start normal (left for kappa > 0).
    cx = x0 - math.sin(h0) * inv
    cy = y0 + math.cos(h0) * inv
    vx = px - cx
    vy = py - cy
    r = math.hypot(vx, vy)
    phi0 = math.atan2(y0 - cy, x0 - cx)
    phi = math.atan2(vy, vx)
    delta = (sign * (phi - phi0)) % TWO_PI
    u = delta * radius
    if u_lo <= u <= u_hi:
        d = sign * (radius - r)
        return u, d, abs(d)
    # Outside the angular span the nearest arc point is one of the two ends.
    best_u = u_lo
    best_d = 0.0
    best_dist = math.inf
    for ue in (u_lo, u_hi):
        ex, ey, he = pose_at(x0, y0, h0, kappa, ue)
        dist = math.hypot(px - ex, py - ey)
        if dist < best_dist:
            best_dist = dist
            best_u = ue
            best_d = -(px - ex) * math.sin(he) + (py - ey) * math.cos(he)
    return best_u, best_d, best_dist


@njit(cache=True)
def local_coordinates(
    x0: float, y0: float, h0: float, kappa: float, px: float, py: float
) -> tuple[float, float]:
    """Unclamped ``(u [m], d [m])`` of a point w.r.t. the segment's straight line or circle.

    For an arc, ``u`` is in ``[0, 2π·R)``; callers decide whether it lies on the segment.
    """
    if kappa == 0.0:
        c = math.cos(h0)
        s = math.sin(h0)
        dx = px - x0
        dy = py - y0
        return dx * c + dy * s, -dx * s + dy * c
    inv = 1.0 / kappa
    sign = 1.0 if kappa > 0.0 else -1.0
    radius = abs(inv)
    cx = x0 - math.sin(h0) * inv
    cy = y0 + math.cos(h0) * inv
    vx = px - cx
    vy = py - cy
    r = math.hypot(vx, vy)
    phi0 = math.atan2(y0 - cy, x0 - cx)
    phi = math.atan2(vy, vx)
    delta = (sign * (phi - phi0)) % TWO_PI
    return delta * radius, sign * (radius - r)


@njit(cache=True)
def extreme_sample_indices(s0: np.ndarray, length: np.ndarray, h0: np.ndarray,
                           kappa: np.ndarray, delta_m: float, n_samples: int) -> np.ndarray:
    """Sorted indices of the samples ``i · delta_m`` (``0 ≤ i < n_samples``) within 3 of a
    segment's ends or of a point where an arc heads along an axis (heading a multiple of
    90°): where a chain's sampled x and y can take their extremes (``Track.bounds``).
    The arithmetic of the numpy expression it replaced, element by element (no
    transcendental function: the same bits); a loop instead of ~10 small array calls
    per arc."""
    quarter = 0.5 * math.pi
    n_seg = len(s0)
    n_marks = 2 * n_seg
    for j in range(n_seg):
        if kappa[j] != 0.0:
            a = h0[j]
            b = a + kappa[j] * length[j]
            n_marks += (math.ceil(max(a, b) / quarter) + 1) - math.floor(min(a, b) / quarter)
    marks = np.empty(n_marks)
    k = 0
    for j in range(n_seg):
        marks[k] = s0[j]
        k += 1
    for j in range(n_seg):
        marks[k] = s0[j] + length[j]
        k += 1
    for j in range(n_seg):
        if kappa[j] != 0.0:
            a = h0[j]
            b = a + kappa[j] * length[j]
            for m in range(math.floor(min(a, b) / quarter), math.ceil(max(a, b) / quarter) + 1):
                marks[k] = s0[j] + (float(m) * quarter - a) / kappa[j]
                k += 1
    idx = np.empty(7 * n_marks, np.int64)
    for q in range(n_marks):
        centre = np.int64(np.rint(marks[q] / delta_m))
        for o in range(7):
            idx[7 * q + o] = min(max(centre + o - 3, 0), n_samples - 1)
    return np.unique(idx)
