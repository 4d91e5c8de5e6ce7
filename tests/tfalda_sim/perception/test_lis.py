"""Each LIS stage on hand-built lanes (thesis section 2, listing A.4)."""

from __future__ import annotations

from dataclasses import replace

import pytest

from tfalda_sim.perception import LaneInferenceSystem, LaneSegment, LisConfig, WidthCheck
from tfalda_sim.perception.lis import measured_widths, vertical_target, width_limits

UPPER = (260.0, 334.0)
LOWER = (340.0, 424.0)


def lane(x_top: float, x_bottom: float, rows: tuple[float, float],
         i: float = 5000.0) -> LaneSegment:
    return LaneSegment(x_top, x_bottom - x_top, i, rows[0], rows[1])


def straight() -> list[tuple[LaneSegment, LaneSegment]]:
    """A plausible straight: upper widths 92/234, lower 245/410 [px], lower lanes on the
    upper lanes' lines."""
    return [(lane(327, 251, UPPER), lane(419, 485, UPPER)),
            (lane(246, 163, LOWER), lane(491, 573, LOWER))]


def shifted(rows: list[tuple[LaneSegment, LaneSegment]], r: int, side: int, dx_top: float,
            dx_bottom: float) -> list[tuple[LaneSegment, LaneSegment]]:
    out = [list(pair) for pair in rows]
    ln = out[r][side]
    out[r][side] = lane(ln.x_top + dx_top, ln.x_bottom + dx_bottom, (ln.y_top, ln.y_bottom))
    return [(a, b) for a, b in out]


def lis(**changes: object) -> LaneInferenceSystem:
    system = LaneInferenceSystem(replace(LisConfig(vertical=False), **changes), rows=2)
    system.start(straight())
    return system


def test_a_plausible_frame_is_accepted_unchanged() -> None:
    system = lis()
    rows = shifted(straight(), 0, 1, 3.0, 3.0)
    result = system.infer(rows, straight())
    assert result.rows == rows
    assert result.replaced == [False, False]
    assert result.fault_count == 0 and not result.roi_reset_due


def test_width_outside_table_2_3_takes_the_old_lanes_of_that_row() -> None:
    system = lis()
    previous = straight()
    rows = shifted(straight(), 1, 1, 0.0, 200.0)  # lower bottom width 610 > 520
    result = system.infer(rows, previous)
    assert result.replaced == [False, True]
    assert result.rows[1] == previous[1] and result.rows[0] == rows[0]
    # the upper row was accepted after the lower one's fault: +1 then −1 (listing A.4)
    assert result.fault_count == 0


def test_width_limits_are_table_2_3_at_its_rows() -> None:
    cfg = LisConfig()
    assert width_limits(cfg, 260) == (45, 220)
    assert width_limits(cfg, 334) == (200, 272)
    assert width_limits(cfg, 424) == (320, 520)
    lo, hi = width_limits(cfg, 382)  # between the lower row's edges: interpolated
    assert 200 < lo < 320 and 272 < hi < 520


def test_sudden_width_change_is_rejected_and_filter_still_runs() -> None:
    system = lis(min_max=False)
    before = system.widths.copy()
    # top width of the upper row jumps by 100 px: filtered change 100·α ≈ 14 > 11
    rows = shifted(straight(), 0, 1, 100.0, 0.0)
    result = system.infer(rows, straight())
    assert result.replaced == [True, False]  # rows are listed top first
    alpha = LisConfig().alpha
    assert result.widths[0, 0] == pytest.approx(before[0, 0] + alpha * 100.0)
    assert system.widths[0, 0] == pytest.approx(before[0, 0] + alpha * 100.0)


def test_measured_width_check_is_stricter_than_the_filtered_one() -> None:
    rows = shifted(straight(), 0, 1, 40.0, 0.0)  # 40 px: 40·α ≈ 5.7 filtered
    assert lis(min_max=False).infer(rows, straight()).replaced == [False, False]
    measured = lis(min_max=False, width_check=WidthCheck.MEASURED)
    assert measured.infer(rows, straight()).replaced == [True, False]


def test_lowpass_follows_eq_2_1() -> None:
    system = lis(min_max=False, width_change=False)
    x = 150.0
    rows = shifted(straight(), 0, 1, x - 92.0, 0.0)  # measured top width 150
    y = 92.0
    for _ in range(5):
        system.infer(rows, straight())
        y = LisConfig().alpha * x + (1 - LisConfig().alpha) * y
        assert system.widths[0, 0] == pytest.approx(y)
    assert LisConfig().alpha == pytest.approx(0.1429, abs=1e-4)


def test_reset_is_due_after_the_11th_consecutive_fault() -> None:
    """Both rows rejected: two faults per frame; the 11th fault (frame 6) passes the limit
    of 10 (section 2.4), the 10th (frame 5) does not."""
    system = lis()
    bad = shifted(shifted(straight(), 0, 1, 0.0, 200.0), 1, 1, 0.0, 300.0)
    results = [system.infer(bad, straight()) for _ in range(6)]
    assert [r.fault_count for r in results] == [2, 4, 6, 8, 10, 12]
    assert [r.roi_reset_due for r in results] == [False] * 5 + [True]


def test_an_accepted_row_lowers_the_counter() -> None:
    system = lis()
    system.fault_count = 5
    one_bad = shifted(straight(), 0, 1, 0.0, 200.0)  # upper row bad, lower row fine
    result = system.infer(one_bad, straight())
    assert result.fault_count == 5  # lower row −1 (checked first), upper row +1
    assert system.infer(straight(), straight()).fault_count == 3


def test_reset_stage_off_never_asks_for_a_reset() -> None:
    system = lis(roi_reset=False)
    bad = shifted(shifted(straight(), 0, 1, 0.0, 200.0), 1, 1, 0.0, 300.0)
    assert not any(system.infer(bad, straight()).roi_reset_due for _ in range(20))


def test_vertical_target_is_eq_2_4() -> None:
    upper = lane(300.0, 260.0, UPPER)  # slope: −40 px over 74 rows
    lower = lane(250.0, 180.0, LOWER)
    y = 0.5 * (340.0 + 334.0)
    x1, y1, x2, y2 = 260.0, 334.0, 300.0, 260.0
    expected = x1 - (x2 - x1) / (y2 - y1) * (y1 - y)
    assert vertical_target(upper, lower) == pytest.approx(expected)
    assert expected == pytest.approx(260.0 - 40.0 / 74.0 * 3.0)


def test_vertical_check_moves_only_the_lower_lanes_upper_end() -> None:
    system = LaneInferenceSystem(replace(LisConfig(), min_max=False, width_change=False), 2)
    rows = straight()
    system.start(rows)
    off = shifted(rows, 1, 0, 20.0, 0.0)  # lower-left top end 20 px off the upper line
    result = system.infer(off, rows)
    moved = result.rows[1][0]
    target = vertical_target(rows[0][0], off[1][0])
    assert moved.x_top == pytest.approx(target)
    assert moved.x_bottom == pytest.approx(off[1][0].x_bottom)  # lower end kept
    assert result.corrected == [(False, False), (True, False)]
    # within the 5 px tolerance nothing moves
    near = shifted(rows, 1, 0, 4.0, 0.0)
    ok = system.infer(near, rows)
    assert ok.corrected[1] == (False, False)


def test_weighted_vertical_check_moves_part_of_the_way() -> None:
    cfg = replace(LisConfig(), min_max=False, width_change=False, vertical_weight=0.5)
    system = LaneInferenceSystem(cfg, 2)
    rows = straight()
    system.start(rows)
    off = shifted(rows, 1, 0, 20.0, 0.0)
    moved = system.infer(off, rows).rows[1][0]
    target = vertical_target(rows[0][0], off[1][0])
    assert moved.x_top == pytest.approx(off[1][0].x_top + 0.5 * (target - off[1][0].x_top))


def test_widths_are_measured_between_the_ends() -> None:
    left, right = straight()[0]
    assert measured_widths(left, right) == (92.0, 234.0)


def test_config_rejects_inconsistent_stages() -> None:
    with pytest.raises(ValueError, match="lowpass"):
        LisConfig(lowpass=False)
    with pytest.raises(ValueError, match="vertical_weight"):
        LisConfig(vertical_weight=0.0)
    with pytest.raises(ValueError, match="four"):
        LisConfig(width_limits_px=((1.0, 2.0),))


def test_gap_hold_ratio_is_checked() -> None:
    with pytest.raises(ValueError, match="gap_hold_ratio"):
        LisConfig(gap_hold_ratio=1.5)


def test_a_pickled_lis_keeps_its_state_and_checks_the_same() -> None:
    import pickle

    import numpy as np

    lis = LaneInferenceSystem(LisConfig(), 2)

    def row(x_left: float, x_right: float, y_top: float, y_bottom: float
            ) -> tuple[LaneSegment, LaneSegment]:
        return (LaneSegment(x_left, 0.0, 1.0, y_top, y_bottom),
                LaneSegment(x_right, 0.0, 1.0, y_top, y_bottom))

    rows = [row(300.0, 450.0, 260.0, 334.0), row(250.0, 500.0, 340.0, 424.0)]
    lis.start(rows)
    twin = pickle.loads(pickle.dumps(lis))
    assert "_limits" not in lis.__getstate__()
    wide = [row(100.0, 600.0, 260.0, 334.0), rows[1]]
    a, b = lis.infer(wide, rows), twin.infer(wide, rows)
    assert a.replaced == b.replaced and a.replaced[0]  # 500 px at row 260: over the limit
    np.testing.assert_array_equal(a.widths, b.widths)
