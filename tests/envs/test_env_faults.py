"""Faults in the env: each acts where and when it should, in seconds at the camera's
frame rate and in metres on the track."""

from __future__ import annotations

import numpy as np
import pytest

from tfalda_sim.camera import load_camera
from tfalda_sim.envs import TfaldaTrackEnv
from tfalda_sim.faults import (
    Blackout,
    FrameDropBurst,
    Glare,
    LatencySpike,
    ServoOffset,
    WetPatch,
    glare_blob,
)
from tfalda_sim.timing import Timing

STRAIGHT = np.zeros(1, np.float32)


def _delivered(env: TfaldaTrackEnv, steps: int, action: np.ndarray = STRAIGHT) -> list[int]:
    """The step of the frame each step's observation comes from."""
    out = []
    for _ in range(steps):
        env.step(action)
        out.append(env._last.step)
    return out


@pytest.mark.parametrize("rate", [50.0, 30.0], ids=["thesis 50 Hz", "30 Hz"])
def test_a_latency_spike_delivers_the_frames_of_its_window_late(rate: float) -> None:
    """Ideal timing: every frame is the step's own, except that the frames taken from 1 s
    for 0.2 s arrive 0.1 s late — and the frames after them wait in the pipeline."""
    camera = load_camera("thesis").replace(frame_rate_hz=rate)
    env = TfaldaTrackEnv(track="oval", camera=camera, faults=[LatencySpike(1.0, 0.2, 0.1)])
    env.reset(seed=0, options={"start": (0.0, -0.2, 0.0)})
    seen = _delivered(env, int(2 * rate))
    first, count, late = int(rate), round(0.2 * rate), round(0.1 * rate)
    # frame k arrives at step k, those of the window `late` steps after, and none before
    # the one taken before it (one pipeline)
    arrival = [0]
    for k in range(1, len(seen) + 1):
        arrival.append(max(arrival[-1], k + (late if first <= k < first + count else 0)))
    expected = [max(k for k, a in enumerate(arrival) if a <= step)
                for step in range(1, len(seen) + 1)]
    assert seen == expected
    assert seen[first + late - 1] == first  # the window's first frame, `late` steps late
    assert seen[first - 1:first + late - 1] == [first - 1] * late


def test_a_latency_spike_adds_to_the_timings_latency() -> None:
    """Real-car timing without jitter: frames two periods old; those of the spike's
    window 0.1 s (5 frames) older still."""
    timing = Timing(camera_latency_s=0.04)
    env = TfaldaTrackEnv(track="oval", timing=timing, faults=[LatencySpike(1.0, 0.2, 0.1)])
    env.reset(seed=0, options={"start": (0.0, -0.2, 0.0)})
    seen = _delivered(env, 80)
    assert seen[:49] == [max(0, k - 2) for k in range(1, 50)]
    # frame 50 (taken at 1 s) arrives at step 57 = 50 + 2 + 5
    assert seen[56] == 50 and seen[55] == 49
    assert seen[79] == 78


@pytest.mark.parametrize("timing", ["ideal", "real-car"])
def test_a_burst_drops_exactly_its_frames(timing: str,
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """No frame of the burst reaches the detector; the observation stays the last one."""
    env = TfaldaTrackEnv(track="oval", timing=timing, faults=[FrameDropBurst(0.5, 0.3)])
    env.reset(seed=0, options={"start": (0.0, -0.2, 0.0)})
    observed = []
    observe = env._observe

    def spy(pose):
        observed.append(env._step_count)
        return observe(pose)

    monkeypatch.setattr(env, "_observe", spy)
    seen = _delivered(env, 60)
    dropped = set(range(25, 40))
    assert sorted(set(range(1, 61)) - set(observed)) == sorted(dropped)
    if timing == "ideal":
        assert [seen[k - 1] for k in range(24, 41)] == [24] * 16 + [40]


def test_a_wet_patch_changes_mu_scale_only_on_its_metres() -> None:
    env = TfaldaTrackEnv(track="straight", vehicle="dynamic",
                         faults=[WetPatch(2.0, 1.0, 0.3)])
    env.reset(seed=0, options={"start": (0.5, -0.2, 0.0)})
    on = []
    for _ in range(100):
        _, _, terminated, _, info = env.step(STRAIGHT)
        assert not terminated
        assert env._world.mu_scale == (0.3 if 2.0 <= info["s_m"] < 3.0 else 1.0)
        on.append(env._world.mu_scale == 0.3)
    assert 25 <= sum(on) <= 45  # 1 m at 1.5 m/s: 33 frames


def test_a_wet_patch_does_nothing_to_the_kinematic_car() -> None:
    runs = []
    for faults in ([], [WetPatch(2.0, 1.0, 0.0)]):
        env = TfaldaTrackEnv(track="oval", faults=faults)
        obs, _ = env.reset(seed=0, options={"start": (0.5, -0.2, 0.0)})
        steps = [obs]
        for _ in range(60):
            obs, reward, *_ = env.step(np.full(1, 0.1, np.float32))
            steps += [obs, reward]
        runs.append(steps)
    assert all(np.array_equal(a, b) for a, b in zip(*runs, strict=True))


def test_the_servo_offset_shifts_the_wheel_angle() -> None:
    env = TfaldaTrackEnv(track="oval", faults=[ServoOffset(0.1, 0.2, 0.05)])
    env.reset(seed=0, options={"start": (0.0, -0.2, 0.0)})
    steer = [env.step(STRAIGHT)[4]["steer_rad"] for _ in range(20)]
    # the servo (8.7 rad/s) turns 0.17 rad in a frame: the offset is reached at once
    assert steer[:4] == [0.0] * 4
    assert steer[4:14] == pytest.approx([0.05] * 10)
    assert steer[14:] == [0.0] * 6
    # at the end of the steering range the wheels stop there
    env.reset(seed=0, options={"start": (0.0, -0.2, 0.0), "faults": [ServoOffset(0.0, 1.0, 0.1)]})
    for _ in range(5):
        info = env.step(np.ones(1, np.float32))[4]
    assert info["steer_rad"] == env.car.max_steer_rad


@pytest.mark.parametrize("rate, count", [(50.0, 50), (30.0, 30)], ids=["thesis 50 Hz", "30 Hz"])
def test_a_one_second_blackout_is_a_second_of_frames_on_any_camera(rate: float,
                                                                   count: int) -> None:
    camera = load_camera("thesis").replace(frame_rate_hz=rate)
    env = TfaldaTrackEnv(track="oval", camera=camera, faults=[Blackout(0.5, 1.0)])
    env.reset(seed=0, options={"start": (0.0, -0.2, 0.0)})
    black = []
    for _ in range(int(2 * rate)):
        env.step(STRAIGHT)
        black.append(int(env.camera_frame().max()) == 0)
    assert sum(black) == count and black.index(True) + 1 == round(0.5 * rate)


def test_the_glare_lands_on_its_floor_point_in_the_frame() -> None:
    glare = Glare(0.1, 0.06, ahead_m=0.6, left_m=0.15, radius_m=0.05, peak_dn=255.0)
    env = TfaldaTrackEnv(track="oval", faults=[glare])
    env.reset(seed=0, options={"start": (0.0, -0.2, 0.0)})
    frames = []
    for _ in range(8):
        env.step(STRAIGHT)
        frames.append(env.camera_frame().astype(int))
    blob = glare_blob(glare, env.camera)
    u, v = round(blob.u_px), round(blob.v_px)
    assert frames[4][v, u] == 255 and frames[6][v, u] == 255  # steps 5 and 7: the car moved
    assert frames[3][v, u] < 200 and frames[7][v, u] < 200  # before and after
