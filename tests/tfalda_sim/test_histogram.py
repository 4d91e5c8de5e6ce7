"""Binned durations: quantiles within a bin of numpy's, memory by bins, not samples."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tfalda_sim.histogram import BIN_S, TimeHistogram


@settings(max_examples=200, deadline=None, derandomize=True, database=None)
@given(st.lists(st.floats(0.0, 0.05), min_size=1, max_size=300),
       st.sampled_from([0.0, 0.25, 0.5, 0.95, 1.0]))
def test_quantiles_are_numpys_to_within_a_bin(times: list[float], q: float) -> None:
    hist = TimeHistogram(times)
    assert len(hist) == len(times)
    assert hist.quantile(q) == pytest.approx(float(np.quantile(times, q)), abs=BIN_S * 1.01)


def test_merging_and_memory() -> None:
    a, b = TimeHistogram([0.001] * 1000), TimeHistogram([0.002] * 1000)
    both = a + b
    assert len(both) == 2000 and len(both.counts) == 2  # two bins, whatever the count
    assert both.median_ms() == pytest.approx(1.5, abs=0.01)
    assert TimeHistogram().median_ms() is None
    with pytest.raises(ValueError, match="finite and ≥ 0"):
        a.add(float("nan"))
