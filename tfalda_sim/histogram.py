"""Durations in fixed bins: medians and percentiles of per-frame times with memory bounded
by the number of distinct bins, not by the number of frames.

A sweep over many tracks or an endless replay times every frame; keeping every time
would grow without end. ``TimeHistogram`` counts them in bins of ``BIN_S`` (0.01 ms) up
to ``LINEAR_LIMIT_S`` (10 s), and in bins ``REL_BIN`` (0.01 %) wide beyond — a first
frame that compiles the kernels for a minute is measured, not clipped to a cap. Its
quantiles come from the bin centres, so a reported median is within 0.01 ms of the exact
one (0.01 % beyond 10 s). The bins beyond 10 s grow with the logarithm of the longest
duration: memory stays bounded.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable

BIN_S: float = 1e-5
"""Bin width [s] (0.01 ms: finer than any figure reported, ms with two decimals)."""

LINEAR_LIMIT_S: float = 10.0
"""Durations below this [s] go to bins ``BIN_S`` wide; longer ones to bins ``REL_BIN``
of their duration wide."""

REL_BIN: float = 1e-4
"""Relative width of the bins beyond ``LINEAR_LIMIT_S`` (1 ms at 10 s)."""

MAX_BIN: int = 10**6
"""The first bin beyond ``LINEAR_LIMIT_S`` (the bins below it are 0 … MAX_BIN − 1)."""

_LOG_STEP = math.log1p(REL_BIN)


def bin_of(seconds: float) -> int:
    """The bin a duration [s] is counted in."""
    if seconds < LINEAR_LIMIT_S:
        return min(int(seconds / BIN_S), MAX_BIN - 1)
    return MAX_BIN + int(math.log(seconds / LINEAR_LIMIT_S) / _LOG_STEP)


def bin_centre(b: int) -> float:
    """The duration [s] a bin stands for: its centre."""
    if b < MAX_BIN:
        return (b + 0.5) * BIN_S
    return LINEAR_LIMIT_S * math.exp((b - MAX_BIN + 0.5) * _LOG_STEP)


class TimeHistogram:
    """Counts of durations [s] per ``BIN_S`` bin (sparse: only bins seen are stored)."""

    def __init__(self, seconds: Iterable[float] = ()) -> None:
        self.counts: Counter[int] = Counter()
        for s in seconds:
            self.add(s)

    def add(self, seconds: float) -> None:
        if not math.isfinite(seconds) or seconds < 0:
            raise ValueError(f"a duration must be finite and ≥ 0 s, got {seconds}")
        self.counts[bin_of(seconds)] += 1

    def __add__(self, other: TimeHistogram) -> TimeHistogram:
        out = TimeHistogram()
        out.counts = self.counts + other.counts
        return out

    def __len__(self) -> int:
        return sum(self.counts.values())

    def quantile(self, q: float) -> float | None:
        """The ``q`` quantile [s] of the bin centres, interpolated between the two nearest
        ranks as numpy's default does; None when empty."""
        n = len(self)
        if n == 0:
            return None
        pos = min(max(q, 0.0), 1.0) * (n - 1)
        lo_rank, hi_rank = math.floor(pos), math.ceil(pos)
        lo = hi = None
        seen = 0
        for b in sorted(self.counts):
            seen += self.counts[b]
            if lo is None and seen > lo_rank:
                lo = bin_centre(b)
            if seen > hi_rank:
                hi = bin_centre(b)
                break
        assert lo is not None and hi is not None
        return lo + (pos - lo_rank) * (hi - lo)

    def median_ms(self) -> float | None:
        m = self.quantile(0.5)
        return None if m is None else 1e3 * m

    def p95_ms(self) -> float | None:
        p = self.quantile(0.95)
        return None if p is None else 1e3 * p
