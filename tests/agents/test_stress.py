"""The stress battery: a blackout makes the LIS reset only when its reset stage is on."""

from __future__ import annotations

from agents.stress import FAULTS, markdown_table, run_one, summarise


def test_blackout_triggers_the_reset_and_the_lanes_recover() -> None:
    with_reset = run_one(10003, "blackout", True)
    without = run_one(10003, "blackout", False)
    assert with_reset.reset and with_reset.on_road
    assert with_reset.frames_to_recover is not None and with_reset.frames_to_recover < 50
    assert not without.reset and without.resets == 0


def test_summary_table_has_one_row_per_fault_and_stage() -> None:
    runs = [run_one(10003, "lateral_kick", stage) for stage in (True, False)]
    rows = summarise(runs)
    assert [(r["fault"], r["lis_reset_stage"]) for r in rows] == [
        ("lateral_kick", True), ("lateral_kick", False)]
    table = markdown_table(rows)
    assert table.count("\n") == 3 and "lateral_kick | on" in table
    assert set(FAULTS) >= {"blackout", "overexposed", "glare", "marking_gap", "lateral_kick",
                           "camera_shake", "obstacle", "fast_curve"}
