"""Fault schedules: image faults equal on crops and full frames, gaps, bad schedules."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tfalda_sim.faults import (
    Blackout,
    CameraShake,
    Glare,
    LateralKick,
    MarkingGap,
    Overexposure,
    active,
    apply_image_faults,
    check_schedule,
    with_gaps,
)
from tfalda_sim.rendering import Effects, Renderer, build_scene
from tfalda_sim.tracks import Line, load_named

WINDOWS = [(195, 260, 150, 75), (365, 260, 150, 75), (80, 340, 180, 85), (429, 340, 180, 85)]


@pytest.mark.parametrize("fault", [Blackout(1), Overexposure(1, gain=3.0),
                                   Glare(1, u_px=300.0, v_px=300.0, radius_px=50.0)])
def test_image_faults_on_crops_equal_the_faulted_full_frame(fault) -> None:
    rng = np.random.default_rng(0)
    frame = rng.integers(0, 256, (480, 752), dtype=np.uint8)
    crops = [frame[y:y + h, x:x + w].copy() for x, y, w, h in WINDOWS]
    full = frame.copy()
    apply_image_faults([full], [(0, 0, 752, 480)], [fault])
    apply_image_faults(crops, WINDOWS, [fault])
    for crop, (x, y, w, h) in zip(crops, WINDOWS, strict=True):
        assert np.array_equal(crop, full[y:y + h, x:x + w])
    assert not np.array_equal(full, frame)


def test_image_fault_values() -> None:
    frame = np.full((480, 752), 100, np.uint8)
    black = frame.copy()
    apply_image_faults([black], [(0, 0, 752, 480)], [Blackout(1)])
    assert black.max() == 0
    bright = frame.copy()
    apply_image_faults([bright], [(0, 0, 752, 480)], [Overexposure(1, gain=2.0)])
    assert np.all(bright == 200)
    glare = frame.copy()
    apply_image_faults([glare], [(0, 0, 752, 480)], [Glare(1, u_px=100, v_px=200,
                                                           radius_px=20, peak_dn=80)])
    assert glare[200, 100] == 180 and glare[200, 200] == 100 and glare[0, 0] == 100


def test_active_faults_by_step() -> None:
    schedule = check_schedule([Blackout(5, duration=3), LateralKick(6), Glare(2)])
    assert [active(schedule, k, Blackout) != [] for k in range(3, 10)] == [
        False, False, True, True, True, False, False]
    assert active(schedule, 6, LateralKick) == [LateralKick(6)]
    assert active(schedule, 2, Glare) == [Glare(2)] and active(schedule, 3, Glare) == []


def test_a_marking_gap_paints_the_lines_out() -> None:
    track = load_named("oval")
    gap = MarkingGap(s_m=1.6, length_m=2.0)  # under and ahead of the car
    renderer = Renderer()
    x, y, h = (float(v) for v in track.pose(1.6, -0.5 * track.lane_width_m))
    clean = renderer.render(build_scene(track, Effects.off()), (x, y, h))
    gapped = renderer.render(build_scene(with_gaps(track, [gap]), Effects.off()), (x, y, h))
    # The lines right ahead are gone: only the mat's grey is left in the lower ROIs.
    for x0, y0, w, hh in WINDOWS[2:]:
        assert clean[y0:y0 + hh, x0:x0 + w].max() > 150
        assert gapped[y0:y0 + hh, x0:x0 + w].max() <= Effects.off().mat_dn + 1
    wrapped = with_gaps(track, [MarkingGap(s_m=track.length_m + 1.0, lines=(Line.RIGHT,))])
    assert wrapped.gaps[-1].s_m == pytest.approx(1.0) and wrapped.gaps[-1].line is Line.RIGHT


@pytest.mark.parametrize("make, match", [
    (lambda: Blackout(0), "step"), (lambda: Glare(1, duration=0), "duration"),
    (lambda: LateralKick(3, offset_m=math.nan), "offset_m"),
    (lambda: MarkingGap(1.0, length_m=-1.0), "length_m"),
    (lambda: MarkingGap(1.0, lines=("left",)), "Line"),
    (lambda: CameraShake(2, amplitude_rad=-0.1), "amplitude"),
])
def test_bad_faults_are_refused(make, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        make()


def test_unknown_faults_in_a_schedule_are_refused() -> None:
    with pytest.raises(TypeError, match="unknown fault"):
        check_schedule([Blackout(1), "glare"])
    with pytest.raises(TypeError, match="sequence"):
        check_schedule("blackout")


class _Car:
    def __init__(self) -> None:
        self.pose = (1.0, 2.0, 0.0)

    def place(self, pose: tuple[float, float, float]) -> None:
        self.pose = pose


def test_the_injector_acts_at_the_world_and_the_image() -> None:
    from tfalda_sim.faults import FaultInjector

    schedule = (LateralKick(3, 0.1), CameraShake(3, 2, amplitude_rad=0.05), Blackout(4, 1))
    injector = FaultInjector(schedule, np.random.default_rng(0))
    car = _Car()
    assert injector.world(2, car) == (1.0, 2.0, 0.0) and car.pose == (1.0, 2.0, 0.0)
    x, y, yaw = injector.world(3, car)
    # the kick moved the car 0.1 m to its left; the shake turned only the camera
    assert car.pose == pytest.approx((1.0, 2.1, 0.0)) and (x, y) == pytest.approx((1.0, 2.1))
    assert 0 < abs(yaw) <= 0.05
    crops = [np.full((4, 4), 200, np.uint8)]
    injector.image(3, crops, [(0, 0, 4, 4)])
    assert crops[0].min() == 200
    injector.image(4, crops, [(0, 0, 4, 4)])
    assert crops[0].max() == 0
    # the same seed, the same shake
    again = FaultInjector(schedule, np.random.default_rng(0))
    assert again.world(3, _Car())[2] == yaw


def test_an_empty_schedule_leaves_pose_and_pixels_alone() -> None:
    from tfalda_sim.faults import FaultInjector

    injector = FaultInjector((), np.random.default_rng(0))
    car = _Car()
    rng_state = injector.rng.bit_generator.state
    assert injector.world(5, car) == (1.0, 2.0, 0.0) and car.pose == (1.0, 2.0, 0.0)
    crops = [np.full((4, 4), 200, np.uint8)]
    injector.image(5, crops, [(0, 0, 4, 4)])
    assert crops[0].min() == 200 and crops[0].max() == 200
    assert injector.rng.bit_generator.state == rng_state  # nothing drawn


def test_an_injector_pickled_before_the_stage_lists_still_acts() -> None:
    import pickle

    from tfalda_sim.faults import FaultInjector

    schedule = (LateralKick(3, 0.1), Blackout(4, 1))
    injector = FaultInjector(schedule, np.random.default_rng(0))
    old_state = {k: v for k, v in injector.__dict__.items()
                 if k not in ("_kicks", "_shakes", "_image_faults")}
    old = FaultInjector.__new__(FaultInjector)
    old.__setstate__(old_state)
    copy = pickle.loads(pickle.dumps(old))
    for restored in (old, copy):
        car = _Car()
        restored.world(3, car)
        assert car.pose == pytest.approx((1.0, 2.1, 0.0))
        crops = [np.full((4, 4), 200, np.uint8)]
        restored.image(4, crops, [(0, 0, 4, 4)])
        assert crops[0].max() == 0
