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


CHAIN_OK, CHAIN_NOT_FINITE, CHAIN_WRAP = 0, 1, 2
"""``chain_angles``' answers: done, a non-finite arc length, an arc length of a closed
track outside ``[0, total)`` (the caller wraps it with ``np.mod`` and asks again)."""


@njit(cache=True)
def chain_angles(s: np.ndarray, s0: np.ndarray, h0: np.ndarray, kappa: np.ndarray,
                 total: float, closed: bool
                 ) -> tuple[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """First half of a vectorised pose query along the chain: for each arc length ``s``
    [m], its segment ``idx`` (``searchsorted(s0, s, "right") − 1``, clamped), the local
    coordinate ``u`` [m] and the heading ``h0[idx] + kappa[idx]·u`` [rad]. The pose needs
    the sine and cosine of both headings, numpy's (its vectorised ones differ from libm's
    by ulps): a segment's start heading has them once per track, and so has the heading
    of a straight (the same number); the others are listed in ``angles``, query ``i`` at
    ``slot[i]`` (−1 for none). Returns ``(CHAIN_OK, idx, u, heading, slot, angles)``, or
    ``CHAIN_NOT_FINITE`` / ``CHAIN_WRAP`` and empty arrays. (Allocated here: each numpy
    call costs µs in a process whose caches the renderer keeps busy.)"""
    n = len(s)
    for i in range(n):
        v = s[i]
        if not math.isfinite(v) or (closed and not (0.0 <= v < total
                                                    and math.copysign(1.0, v) > 0.0)):
            # np.mod is the identity inside [0, total), −0.0 aside (+0.0): only others
            # need wrapping
            code = CHAIN_NOT_FINITE if not math.isfinite(v) else CHAIN_WRAP
            none = np.empty(0)
            return code, np.empty(0, np.int64), none, none, np.empty(0, np.int64), none
    idx = np.empty(n, np.int64)
    u = np.empty(n)
    heading = np.empty(n)
    slot = np.empty(n, np.int64)
    angles = np.empty(n)
    last = len(s0) - 1
    m = 0
    for i in range(n):
        v = s[i]
        lo = 0
        hi = len(s0)
        while lo < hi:  # the number of s0 ≤ v
            mid = (lo + hi) >> 1
            if s0[mid] <= v:
                lo = mid + 1
            else:
                hi = mid
        j = min(max(lo - 1, 0), last)
        idx[i] = j
        uu = v - s0[j]
        u[i] = uu
        h = h0[j] + kappa[j] * uu
        heading[i] = h
        # h0 + 0·u is h0, but for a start heading of −0.0 (+0.0 then): sign included.
        if h == h0[j] and math.copysign(1.0, h) == math.copysign(1.0, h0[j]):
            slot[i] = -1
        else:
            slot[i] = m
            angles[m] = h
            m += 1
    return CHAIN_OK, idx, u, heading, slot, angles[:m]


@njit(cache=True)
def chain_points(idx: np.ndarray, u: np.ndarray, slot: np.ndarray, sin_h0: np.ndarray,
                 cos_h0: np.ndarray, sines: np.ndarray, cosines: np.ndarray,
                 x0: np.ndarray, y0: np.ndarray, kappa: np.ndarray, lateral: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Second half of the pose query (after ``chain_angles`` and numpy's sine and cosine
    of its listed angles; ``sin_h0``, ``cos_h0``: numpy's of each segment's start
    heading): the points ``(x, y)`` [m] at ``lateral`` [m] (one per query, or one for
    all), the same expressions in the same order as ``pose_at``'s."""
    n = len(idx)
    one = len(lateral) == 1
    if not one and len(lateral) != n:
        raise ValueError("chain_points: lateral needs one offset, or one per query")
    x = np.empty(n)
    y = np.empty(n)
    for i in range(n):
        j = idx[i]
        k = kappa[j]
        q = slot[i]
        sin_h = sin_h0[j] if q < 0 else sines[q]
        cos_h = cos_h0[j] if q < 0 else cosines[q]
        if k == 0.0:
            xc = x0[j] + u[i] * cos_h0[j]
            yc = y0[j] + u[i] * sin_h0[j]
        else:
            xc = x0[j] + (sin_h - sin_h0[j]) / k
            yc = y0[j] - (cos_h - cos_h0[j]) / k
        lat = lateral[0] if one else lateral[i]
        x[i] = xc - lat * sin_h
        y[i] = yc + lat * cos_h
    return x, y


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
    # np.unique's result by hand, a sort and a deduplicating loop: numba's np.unique took
    # ≈ 2 s to compile on a cold start, ≈ 0.6 s more than the sort alone.
    idx.sort()
    n = 0
    for q in range(len(idx)):
        if n == 0 or idx[q] != idx[n - 1]:
            idx[n] = idx[q]
            n += 1
    return idx[:n]
