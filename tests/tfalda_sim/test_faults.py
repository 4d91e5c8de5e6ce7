"""Fault schedules in seconds and metres: frames at the camera's rate, the glare through
the lens, image faults equal on crops and full frames, gaps, the injector's stages, bad
values refused."""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest

from tfalda_sim.camera import load_camera
from tfalda_sim.faults import (
    Blackout,
    CameraShake,
    FaultInjector,
    FrameDropBurst,
    Glare,
    GlareBlob,
    LatencySpike,
    LateralKick,
    MarkingGap,
    Overexposure,
    ServoOffset,
    WetPatch,
    active,
    apply_image_faults,
    check_schedule,
    frames,
    glare_blob,
    with_gaps,
)
from tfalda_sim.rendering import Effects, Renderer, build_scene
from tfalda_sim.tracks import Line, load_named

WINDOWS = [(195, 260, 150, 75), (365, 260, 150, 75), (80, 340, 180, 85), (429, 340, 180, 85)]

THESIS = load_camera("thesis")
AT_30_HZ = THESIS.replace(frame_rate_hz=30.0)


@pytest.mark.parametrize("fault", [Blackout(0.02, 0.02), Overexposure(0.02, 0.02, gain=3.0),
                                   GlareBlob(300.0, 300.0, 50.0, 200.0)])
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
    apply_image_faults([black], [(0, 0, 752, 480)], [Blackout(0.0, 0.02)])
    assert black.max() == 0
    bright = frame.copy()
    apply_image_faults([bright], [(0, 0, 752, 480)], [Overexposure(0.0, 0.02, gain=2.0)])
    assert np.all(bright == 200)
    glare = frame.copy()
    apply_image_faults([glare], [(0, 0, 752, 480)], [GlareBlob(100, 200, 20, 80)])
    assert glare[200, 100] == 180 and glare[200, 200] == 100 and glare[0, 0] == 100


def test_seconds_are_frames_at_the_cameras_rate() -> None:
    """A 1 s blackout is 50 frames on the thesis camera and 30 at 30 frames/s; a start
    rounds to the nearest frame, a fault lasts at least one."""
    blackout = Blackout(start_s=2.0, duration_s=1.0)
    assert frames(blackout, THESIS.frame_rate_hz) == range(100, 150)
    assert frames(blackout, AT_30_HZ.frame_rate_hz) == range(60, 90)
    assert len(frames(Blackout(0.1, 0.5), 50.0)) == 25
    assert len(frames(Blackout(0.1, 0.5), 30.0)) == 15
    assert frames(Blackout(0.1, 0.001), 30.0) == range(3, 4)  # 0.1 s · 30/s = 3.0000000000000004
    assert frames(LateralKick(0.5), 30.0) == range(15, 16)
    assert frames(ServoOffset(0.05, 0.02, 0.1), 50.0) == range(3, 4)  # 2.5 rounds up


@pytest.mark.parametrize("camera, count", [(THESIS, 50), (AT_30_HZ, 30)],
                         ids=["thesis 50 Hz", "30 Hz"])
def test_the_injector_counts_a_fault_in_its_cameras_frames(camera, count: int) -> None:
    schedule = (Blackout(1.0, 1.0), FrameDropBurst(1.0, 1.0), LatencySpike(1.0, 1.0, 0.1),
                ServoOffset(1.0, 1.0, 0.05))
    injector = FaultInjector(schedule, np.random.default_rng(0), camera)
    black, dropped, late, offset = [], [], [], []
    for step in range(4 * count):
        crop = [np.full((2, 2), 100, np.uint8)]
        injector.image(step, crop, [(0, 0, 2, 2)])
        black.append(crop[0].max() == 0)
        lost, extra = injector.delivery(step)
        dropped.append(lost)
        late.append(extra == 0.1)
        offset.append(injector.steer_offset(step) == 0.05)
    for acted in (black, dropped, late, offset):
        assert sum(acted) == count
        assert acted.index(True) == count  # from 1 s on


def test_active_faults_by_step() -> None:
    schedule = check_schedule([Blackout(0.1, 0.06), LateralKick(0.12), Glare(0.04, 0.02)])
    assert [active(schedule, k, Blackout, 50.0) != [] for k in range(3, 10)] == [
        False, False, True, True, True, False, False]
    assert active(schedule, 6, LateralKick, 50.0) == [LateralKick(0.12)]
    assert active(schedule, 2, Glare, 50.0) == [Glare(0.04, 0.02)]
    assert active(schedule, 3, Glare, 50.0) == []
    assert active([WetPatch(2.0)], 10**6, WetPatch, 50.0) == [WetPatch(2.0)]


def test_the_glare_is_a_point_on_the_floor_seen_through_each_lens() -> None:
    """The defaults and the battery's glare are where the thesis camera's pixels were;
    on another camera the blob's centre still sees the same floor point."""
    default = glare_blob(Glare(0.0, 1.0), THESIS)
    assert (default.u_px, default.v_px, default.radius_px) == pytest.approx((376, 330, 60),
                                                                            abs=1.0)
    battery = glare_blob(Glare(0.0, 1.0, ahead_m=0.26, left_m=-0.18, radius_m=0.115), THESIS)
    assert (battery.u_px, battery.v_px, battery.radius_px) == pytest.approx((520, 380, 70),
                                                                            abs=1.0)
    other = load_camera("reference-car")
    glare = Glare(0.0, 1.0, ahead_m=0.6, left_m=0.1, radius_m=0.1)
    for camera in (THESIS, other):
        blob = glare_blob(glare, camera)
        ground = camera.pixels_to_ground(np.array([[blob.u_px, blob.v_px]]))[0]
        foot = np.array([camera.mount.forward_m, camera.mount.lateral_m])
        assert ground - foot == pytest.approx([0.6, 0.1], abs=1e-6)
    # farther away on the floor: smaller in the image
    far = glare_blob(Glare(0.0, 1.0, ahead_m=1.5, radius_m=0.1), THESIS)
    near = glare_blob(Glare(0.0, 1.0, ahead_m=0.5, radius_m=0.1), THESIS)
    assert far.radius_px < near.radius_px and far.v_px < near.v_px
    # behind the camera: not seen, nothing drawn
    assert glare_blob(Glare(0.0, 1.0, ahead_m=-2.0), THESIS) is None


def test_a_shaken_camera_sees_the_glare_move_the_other_way() -> None:
    glare = Glare(0.0, 1.0)
    still = glare_blob(glare, THESIS)
    left = glare_blob(glare, THESIS, shake_rad=0.05)  # the camera turned left
    assert left.u_px > still.u_px + 5  # the point moves right in the image


def test_the_injectors_glare_follows_the_shake_of_its_frame() -> None:
    schedule = (Glare(0.0, 1.0, radius_m=0.02), CameraShake(0.2, 0.02, amplitude_rad=0.05))
    injector = FaultInjector(schedule, np.random.default_rng(3), THESIS)
    shaken = injector.world(10, _Car())[2]
    for step in (9, 10, 10):  # a frame rendered again later sees the same blob
        full = np.zeros((480, 752), np.uint8)
        injector.image(step, [full], [(0, 0, 752, 480)])
        v, u = np.unravel_index(int(np.argmax(full)), full.shape)
        blob = glare_blob(schedule[0], THESIS, shaken if step == 10 else 0.0)
        assert (u, v) == pytest.approx((blob.u_px, blob.v_px), abs=1.0)


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


@pytest.mark.parametrize("make, error, match", [
    (lambda: Blackout(-0.1, 1.0), ValueError, "Blackout.start_s must be finite and in [0,"),
    (lambda: Blackout(1.0, 0.0), ValueError, "Blackout.duration_s must be > 0"),
    (lambda: Glare(1.0, -1.0), ValueError, "Glare.duration_s must be > 0"),
    (lambda: Blackout(math.inf, 1.0), ValueError, "Blackout.start_s"),
    (lambda: Blackout("1", 1.0), TypeError, "Blackout.start_s must be a real number"),
    (lambda: Blackout(True, 1.0), TypeError, "Blackout.start_s must be a real number"),
    (lambda: LateralKick(0.3, offset_m=math.nan), ValueError, "LateralKick.offset_m"),
    (lambda: MarkingGap(1.0, length_m=-1.0), ValueError, "MarkingGap.length_m"),
    (lambda: MarkingGap(1.0, lines=("left",)), ValueError, "Line"),
    (lambda: CameraShake(0.2, 1.0, amplitude_rad=-0.1), ValueError, "amplitude"),
    (lambda: Glare(1.0, 1.0, radius_m=0.0), ValueError, "Glare.radius_m must be > 0"),
    (lambda: Glare(1.0, 1.0, ahead_m=50.0), ValueError, "Glare.ahead_m"),
    (lambda: Glare(1.0, 1.0, peak_dn=300.0), ValueError, "Glare.peak_dn"),
    (lambda: LatencySpike(1.0, 0.5, 0.0), ValueError, "LatencySpike.extra_s must be > 0"),
    (lambda: LatencySpike(1.0, 0.5, 2.0), ValueError, "LatencySpike.extra_s must be finite"),
    (lambda: LatencySpike(1.0, 0.0, 0.1), ValueError, "LatencySpike.duration_s"),
    (lambda: FrameDropBurst(-1.0, 0.5), ValueError, "FrameDropBurst.start_s"),
    (lambda: FrameDropBurst(1.0, math.nan), ValueError, "FrameDropBurst.duration_s"),
    (lambda: WetPatch(1.0, mu_scale=1.5), ValueError, "WetPatch.mu_scale must be finite and in "
                                                      "[0, 1]"),
    (lambda: WetPatch(1.0, length_m=0.0), ValueError, "WetPatch.length_m must be > 0"),
    (lambda: WetPatch(1e6), ValueError, "WetPatch.s_m"),
    (lambda: ServoOffset(1.0, 1.0, 0.8), ValueError, "ServoOffset.offset_rad must be finite "
                                                     "and in [-0.5, 0.5] rad"),
    (lambda: ServoOffset(1.0, 1.0, None), TypeError, "ServoOffset.offset_rad"),
])
def test_bad_faults_are_refused_in_one_line(make, error: type, match: str) -> None:
    with pytest.raises(error) as err:
        make()
    assert match in str(err.value) and "\n" not in str(err.value)


def test_numpy_numbers_are_taken_as_floats() -> None:
    fault = LatencySpike(np.float32(1.5), np.int64(1), np.float64(0.1))
    assert fault == LatencySpike(1.5, 1.0, 0.1)
    assert all(type(v) is float for v in (fault.start_s, fault.duration_s, fault.extra_s))


def test_unknown_faults_in_a_schedule_are_refused() -> None:
    with pytest.raises(TypeError, match="unknown fault"):
        check_schedule([Blackout(1.0, 1.0), "glare"])
    with pytest.raises(TypeError, match="sequence"):
        check_schedule("blackout")
    with pytest.raises(TypeError, match=r"camera must be a tfalda_sim\.camera\.Camera"):
        FaultInjector((), np.random.default_rng(0), "thesis")  # type: ignore[arg-type]


class _Car:
    """The injector's view of the world: pose, place, track, position and mu_scale."""

    def __init__(self, track=None, s_m: float = 0.0) -> None:
        self.pose = (1.0, 2.0, 0.0)
        self.track = track
        self.s_m = s_m
        self.mu_scale = 1.0

    def place(self, pose: tuple[float, float, float]) -> None:
        self.pose = pose

    def position(self) -> object:
        return type("Position", (), {"s_m": self.s_m})()


def test_the_injector_acts_at_the_world_and_the_image() -> None:
    schedule = (LateralKick(0.06, 0.1), CameraShake(0.06, 0.04, amplitude_rad=0.05),
                Blackout(0.08, 0.02))
    injector = FaultInjector(schedule, np.random.default_rng(0), THESIS)
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
    again = FaultInjector(schedule, np.random.default_rng(0), THESIS)
    assert again.world(3, _Car())[2] == yaw


def test_the_delivery_and_the_servo_stages() -> None:
    schedule = (LatencySpike(0.1, 0.1, 0.04), LatencySpike(0.14, 0.1, 0.02),
                FrameDropBurst(0.3, 0.04), ServoOffset(0.5, 0.04, -0.03))
    injector = FaultInjector(schedule, np.random.default_rng(0), THESIS)
    assert injector.delivers
    assert [injector.delivery(k) for k in (4, 5, 7, 9, 10, 14, 15, 16, 17)] == [
        (False, 0.0), (False, 0.04), (False, 0.06), (False, 0.06), (False, 0.02),
        (False, 0.0), (True, 0.0), (True, 0.0), (False, 0.0)]
    assert [injector.steer_offset(k) for k in (24, 25, 26, 27)] == [0.0, -0.03, -0.03, 0.0]
    assert not FaultInjector((Blackout(1.0, 1.0),), np.random.default_rng(0), THESIS).delivers


def test_a_wet_patch_sets_mu_scale_only_on_its_metres() -> None:
    oval = load_named("oval")
    patches = (WetPatch(oval.length_m - 0.5, 1.0, mu_scale=0.3), WetPatch(5.0, 2.0, 0.6),
               WetPatch(5.5, 0.5, 0.2))
    injector = FaultInjector(patches, np.random.default_rng(0), THESIS)
    for s_m, mu in ((oval.length_m - 0.6, 1.0), (oval.length_m - 0.5, 0.3), (0.2, 0.3),
                    (0.6, 1.0), (4.99, 1.0), (5.2, 0.6), (5.7, 0.2), (6.0, 0.6), (7.0, 1.0)):
        car = _Car(oval, s_m)
        car.mu_scale = 0.123  # whatever the last step left
        injector.world(1, car)
        assert car.mu_scale == mu, s_m
    # an open track does not wrap
    straight = load_named("straight")
    injector = FaultInjector((WetPatch(-0.5, 1.0),), np.random.default_rng(0), THESIS)
    for s_m, mu in ((straight.length_m - 0.2, 1.0), (0.2, 0.3), (0.6, 1.0)):
        car = _Car(straight, s_m)
        injector.world(1, car)
        assert car.mu_scale == mu


def test_an_empty_schedule_leaves_pose_and_pixels_alone() -> None:
    injector = FaultInjector((), np.random.default_rng(0), THESIS)
    car = _Car()
    rng_state = injector.rng.bit_generator.state
    assert injector.world(5, car) == (1.0, 2.0, 0.0) and car.pose == (1.0, 2.0, 0.0)
    assert car.mu_scale == 1.0 and injector.steer_offset(5) == 0.0
    assert injector.delivery(5) == (False, 0.0) and not injector.delivers
    crops = [np.full((4, 4), 200, np.uint8)]
    injector.image(5, crops, [(0, 0, 4, 4)])
    assert crops[0].min() == 200 and crops[0].max() == 200
    assert injector.rng.bit_generator.state == rng_state  # nothing drawn


def test_a_pickled_injector_acts_the_same() -> None:
    schedule = (LateralKick(0.06, 0.1), Blackout(0.08, 0.02), Glare(0.0, 1.0),
                CameraShake(0.0, 1.0))
    injector = FaultInjector(schedule, np.random.default_rng(0), AT_30_HZ)
    copy = pickle.loads(pickle.dumps(injector))
    for restored in (injector, copy):
        car = _Car()
        restored.world(2, car)
        assert car.pose == pytest.approx((1.0, 2.1, 0.0))
    full = [np.zeros((480, 752), np.uint8) for _ in range(2)]
    injector.image(1, [full[0]], [(0, 0, 752, 480)])
    copy.image(1, [full[1]], [(0, 0, 752, 480)])
    assert np.array_equal(*full) and full[0].max() > 100
