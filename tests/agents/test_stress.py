"""The stress battery: a blackout makes the LIS reset only when its reset stage is on."""

from __future__ import annotations

from tfalda_sim.agents.stress import FAULTS, markdown_table, run_one, summarise


def test_blackout_triggers_the_reset_and_the_lanes_recover() -> None:
    with_reset = run_one(10003, "blackout", True)
    without = run_one(10003, "blackout", False)
    assert with_reset.roi_reset and with_reset.on_road
    assert with_reset.frames_to_recover is not None and with_reset.frames_to_recover < 50
    assert not without.roi_reset and without.roi_resets == 0


def test_summary_table_has_one_row_per_fault_and_stage() -> None:
    runs = [run_one(10003, "lateral_kick", stage) for stage in (True, False)]
    rows = summarise(runs)
    assert [(r["fault"], r["roi_reset_stage"]) for r in rows] == [
        ("lateral_kick", True), ("lateral_kick", False)]
    table = markdown_table(rows)
    assert table.count("\n") == 3 and "lateral_kick | on" in table
    assert set(FAULTS) >= {"blackout", "overexposed", "glare", "marking_gap", "lateral_kick",
                           "camera_shake", "obstacle", "fast_curve"}


def test_the_tally_gives_numpys_median_and_the_rates() -> None:
    import numpy as np

    from tfalda_sim.agents.stress import StressRun, StressTally

    rng = np.random.default_rng(1)
    for n in (1, 2, 5, 10, 37):
        frames = [int(v) if v >= 0 else None for v in rng.integers(-5, 150, n)]
        tally = StressTally()
        for k, f in enumerate(frames):
            tally.add(StressRun(seed=k, fault="glare", roi_reset_stage=True,
                                roi_reset=k % 2 == 0, frames_to_recover=f,
                                false_resets=k % 3, on_road=k % 4 != 0, roi_resets=1))
        (row,) = tally.rows()
        done = [f for f in frames if f is not None]
        assert row["median_frames_to_recover"] == (float(np.median(done)) if done else None)
        assert row["recovered_rate"] == len(done) / n and row["runs"] == n
        assert row["false_resets_per_run"] == np.mean([k % 3 for k in range(n)])


def test_battery_jobs_are_lazy_and_seed_by_seed() -> None:
    from itertools import islice

    from tfalda_sim.agents.stress import battery_jobs

    jobs = battery_jobs(range(10**8), ["none", "blackout"])
    assert list(islice(jobs, 5)) == [(0, "none", True, "thesis"), (0, "none", False, "thesis"),
                                     (0, "blackout", True, "thesis"),
                                     (0, "blackout", False, "thesis"), (1, "none", True, "thesis")]
