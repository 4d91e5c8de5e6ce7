"""Durations in fixed bins: medians and percentiles of per-frame times with memory bounded
by the number of distinct bins, not by the number of frames.

A sweep over many tracks or an endless replay times every frame; keeping every time
would grow without end. ``TimeHistogram`` counts them in bins of ``BIN_S`` (0.01 ms);
its quantiles come from the bin centres, so a reported median is within 0.01 ms of the
exact one.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable

BIN_S: float = 1e-5
"""Bin width [s] (0.01 ms: finer than any figure reported, ms with two decimals)."""

MAX_BIN: int = 10**6
"""Last bin (10 s): longer durations are counted there."""


class TimeHistogram:
    """Counts of durations [s] per ``BIN_S`` bin (sparse: only bins seen are stored)."""

    def __init__(self, seconds: Iterable[float] = ()) -> None:
        self.counts: Counter[int] = Counter()
        for s in seconds:
            self.add(s)

    def add(self, seconds: float) -> None:
        if not math.isfinite(seconds) or seconds < 0:
            raise ValueError(f"a duration must be finite and ≥ 0 s, got {seconds}")
        self.counts[min(int(seconds / BIN_S), MAX_BIN)] += 1

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
                lo = (b + 0.5) * BIN_S
            if seen > hi_rank:
                hi = (b + 0.5) * BIN_S
                break
        assert lo is not None and hi is not None
        return lo + (pos - lo_rank) * (hi - lo)

    def median_ms(self) -> float | None:
        m = self.quantile(0.5)
        return None if m is None else 1e3 * m

    def p95_ms(self) -> float | None:
        p = self.quantile(0.95)
        return None if p is None else 1e3 * p
