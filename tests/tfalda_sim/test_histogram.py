"""Binned durations: quantiles within a bin of numpy's, memory by bins, not samples."""

from __future__ import annotations

import math
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tfalda_sim.histogram import BIN_S, REL_BIN, TimeHistogram


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


def test_a_duration_beyond_ten_seconds_is_measured_not_capped() -> None:
    """A cold first frame (the kernels compiling) took longer than the bins' old cap of
    10 s and was reported as 10000.01 ms: it is now measured to 0.01 %."""
    for seconds in (10.0, 12.5, 61.0, 3600.0):
        ms = TimeHistogram([seconds]).median_ms()
        assert ms == pytest.approx(1e3 * seconds, rel=REL_BIN), seconds
    hist = TimeHistogram([0.001] * 3 + [25.0] * 2)
    assert hist.quantile(1.0) == pytest.approx(25.0, rel=REL_BIN)
    assert hist.median_ms() == pytest.approx(1.0, abs=0.01)
    # Memory: the bins beyond 10 s grow with the logarithm of the range, not the samples.
    wide = TimeHistogram(np.geomspace(10.0, 10.0 * 86400, 100_000))
    assert len(wide.counts) <= math.log(86400) / math.log1p(REL_BIN) + 1


@settings(max_examples=200, deadline=None, derandomize=True, database=None)
@given(st.lists(st.floats(-6.0, 5.0).map(lambda e: 10.0 ** e), min_size=1, max_size=100),
       st.sampled_from([0.0, 0.25, 0.5, 0.95, 1.0]))
def test_quantiles_over_eleven_decades_are_numpys_to_within_a_bin(times: list[float],
                                                                  q: float) -> None:
    tolerance = max(BIN_S, REL_BIN * max(times)) * 1.01
    assert TimeHistogram(times).quantile(q) == pytest.approx(float(np.quantile(times, q)),
                                                             abs=tolerance)


def test_replay_prints_a_slow_first_frame_as_measured(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
        ) -> None:
    """`replay r.png` on a cold cache printed `detector 10000.01 ms/frame`."""
    import cv2

    from tfalda_sim.cli import main
    from tfalda_sim.replay import loop

    png = tmp_path / "r.png"
    cv2.imwrite(str(png), np.full((480, 752), 40, np.uint8))
    clock = iter(np.arange(0.0, 1e6, 12.5))  # every reading 12.5 s after the last
    monkeypatch.setattr(loop, "time", SimpleNamespace(perf_counter=lambda: float(next(clock))))
    assert main(["replay", str(png), "--detector", "hough"]) == 0
    out = capsys.readouterr().out
    shown = re.search(r"detector ([\d.]+) ms/frame", out)
    assert shown and float(shown.group(1)) == pytest.approx(12500.0, rel=REL_BIN), out
