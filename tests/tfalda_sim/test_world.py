"""The pymunk world: bicycle kinematics, collisions with cartons, position on the track."""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest

from tests.conftest import generated
from tfalda_sim.tracks import load_named
from tfalda_sim.world import PHYSICS_STEPS_PER_FRAME, World


def lane_start(track, s: float, lateral: float | None = None) -> tuple[float, float, float]:
    x, y, h = track.pose(s, -0.5 * track.lane_width_m if lateral is None else lateral)
    return float(x), float(y), float(h)


def test_constant_steering_drives_a_circle_of_the_bicycle_radius() -> None:
    world = World(load_named("oval"))
    steer = 0.3
    world.reset((0.0, 0.0, 0.0), speed_m_s=2.0, steer_rad=steer)
    points = []
    for _ in range(200):
        world.step(steer)
        points.append(world.pose[:2])
    p = np.array(points)
    radius = world.car.wheelbase_m / math.tan(steer)
    centre = np.array([0.0, radius])  # to the left of the start
    assert np.allclose(np.hypot(*(p - centre).T), radius, atol=2e-4)
    # Arc length driven = speed × time.
    heading = world.pose[2]
    assert heading == pytest.approx(2.0 * 200 / 50 / radius, rel=1e-6)


def test_straight_drive_covers_speed_times_time() -> None:
    world = World(load_named("straight"))
    world.reset((0.0, 0.0, 0.3), speed_m_s=1.5)
    for _ in range(50):
        world.step(0.0)
    x, y, yaw = world.pose
    assert (x, y) == pytest.approx((1.5 * math.cos(0.3), 1.5 * math.sin(0.3)), abs=1e-9)
    assert yaw == 0.3 and world.time_s == pytest.approx(1.0)


def test_throttle_accelerates_within_the_limit() -> None:
    world = World(load_named("straight"))
    world.reset((0.0, 0.0, 0.0), speed_m_s=1.0)
    world.step(0.0, throttle=1.0)
    assert world.speed_m_s == pytest.approx(1.0 + world.car.max_accel_m_s2 / 50)


def test_driving_into_a_carton_is_a_collision_and_the_free_lane_is_not() -> None:
    track = generated(3)
    ob = track.obstacles[0]
    sign = -1.0 if ob.lane.value == "right" else 1.0
    world = World(track)
    # Follow the lane exactly by placing the car on it: the carton's lane collides...
    hits = []
    for lateral in (sign * 0.5 * track.lane_width_m, -sign * 0.5 * track.lane_width_m):
        world.reset(lane_start(track, ob.s_m - 1.0, lateral), speed_m_s=0.0)
        hit = False
        for s in np.arange(ob.s_m - 1.0, ob.s_m + 1.0, 0.02):
            world.place(lane_start(track, s, lateral))
            world.step(0.0)
            hit = hit or world.collided
        hits.append(hit)
    assert hits == [True, False]


@pytest.mark.parametrize("dynamic", [False, True])
def test_a_fast_car_does_not_tunnel_through_a_carton(dynamic: bool) -> None:
    """Also the dynamic car: a collision with a carton stays an episode end."""
    from tfalda_sim.dynamics import DynamicsParams

    track = generated(3)
    ob = track.obstacles[0]
    lateral = (-1.0 if ob.lane.value == "right" else 1.0) * 0.5 * track.lane_width_m
    x, y, _h = lane_start(track, ob.s_m - 0.5, lateral)
    tx, ty, _ = lane_start(track, ob.s_m, lateral)
    world = World(track, dynamics=DynamicsParams() if dynamic else None)
    world.reset((x, y, math.atan2(ty - y, tx - x)), speed_m_s=world.car.max_speed_m_s)
    assert any(world.step(0.0) for _ in range(10))
    # The car's body is tested after every physics step, each shorter than a carton.
    assert world.car.max_speed_m_s / (50 * PHYSICS_STEPS_PER_FRAME) < min(ob.width_m,
                                                                           ob.length_m)


def test_position_on_the_track() -> None:
    track = load_named("oval")
    world = World(track)
    world.reset(lane_start(track, 3.0, -0.25), speed_m_s=1.0)
    x, y, yaw = world.pose
    world.place((x, y, yaw + 0.1))
    pos = world.position()
    assert pos.s_m == pytest.approx(3.0, abs=1e-6)
    assert pos.cross_track_m == pytest.approx(-0.05, abs=1e-6)
    assert pos.heading_error_rad == pytest.approx(0.1, abs=1e-9)
    assert not pos.off_road
    world.place(lane_start(track, 3.0, -track.half_road_m - 0.01))
    assert world.position().off_road


def test_bad_inputs_are_refused() -> None:
    world = World(load_named("oval"))
    with pytest.raises(ValueError, match="pose"):
        world.reset((math.nan, 0.0, 0.0))
    with pytest.raises(ValueError, match="speed_m_s"):
        world.reset((0.0, 0.0, 0.0), speed_m_s=100.0)
    world.reset((0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="throttle"):
        world.step(0.0, throttle=1.5)
    with pytest.raises(ValueError, match="steer"):
        world.step(math.inf)


def test_the_world_pickles_and_continues_identically() -> None:
    track = generated(3)
    world = World(track)
    world.reset(lane_start(track, 1.0), speed_m_s=2.0)
    for _ in range(5):
        world.step(0.1)
    copy = pickle.loads(pickle.dumps(world))
    for _ in range(20):
        world.step(-0.2)
        copy.step(-0.2)
    assert world.pose == copy.pose and world.speed_m_s == copy.speed_m_s


def _drive(world: World, track, steps: int = 60) -> list[tuple]:
    """A reset at a lane start, then a weave with throttle: poses, positions, hits."""
    world.reset(lane_start(track, 2.0), speed_m_s=1.5, steer_rad=0.05)
    out = []
    for k in range(steps):
        hit = world.step(0.3 * math.sin(0.2 * k), throttle=0.4 * math.cos(0.1 * k))
        out.append((world.pose, world.speed_m_s, world.steer_rad, hit, world.collided,
                    world.position(), world.time_s))
    return out


def test_a_world_moved_to_another_track_drives_as_a_new_one() -> None:
    """``set_track`` (the env's reset onto a new track) gives, bit for bit, what a new
    world on that track gives: the old track's cartons are gone (no collision with them),
    the new ones collide, and the hint of the old track does not leak."""
    with_cartons = generated(3)
    ob = with_cartons.obstacles[0]
    lateral = (-1.0 if ob.lane.value == "right" else 1.0) * 0.5 * with_cartons.lane_width_m
    oval = load_named("oval")
    moved = World(with_cartons)
    _drive(moved, with_cartons)
    for track in (oval, with_cartons, generated(5), with_cartons):
        moved.set_track(track)
        assert moved.track is track and not moved.collided and moved.time_s == 0.0
        assert _drive(moved, track) == _drive(World(track), track)
    # On another track, with cartons elsewhere, a car where the carton of track 3 stood
    # touches nothing (as on the oval, without cartons).
    where = lane_start(with_cartons, ob.s_m, lateral)
    for track in (generated(5), oval):
        moved.set_track(track)
        moved.reset(where)
        fresh = World(track)
        fresh.reset(where)
        assert not fresh.collided and not moved.collided and not moved.step(0.0)
    moved.set_track(with_cartons)
    moved.reset(lane_start(with_cartons, ob.s_m, lateral))
    assert moved.collided


def test_set_track_keeps_only_the_current_cartons_alive() -> None:
    """pymunk's static body keeps every shape made on it: the cartons of earlier tracks
    must be let go, or a long run on new tracks grows without bound."""
    three, nine = generated(3), generated(9)
    world = World(three)
    for k in range(30):
        track = nine if k % 2 else three
        world.set_track(track)
        assert len(world.space.static_body.shapes) == len(track.obstacles)
        assert len(world.space.shapes) == 1 + len(track.obstacles)  # the car's body too


def test_set_track_interrupted_then_called_again_is_right(monkeypatch) -> None:
    """A Ctrl-C inside ``set_track`` (at each carton it makes, or as it adds them) leaves a
    world that the next ``set_track`` puts right: the same cartons and collisions as a new
    world's."""
    import tfalda_sim.world as world_module

    three, nine = generated(3), generated(9)
    ob = nine.obstacles[0]
    where = lane_start(nine, ob.s_m, (-1.0 if ob.lane.value == "right" else 1.0)
                       * 0.5 * nine.lane_width_m)
    real_corners, real_add = world_module.obstacle_corners, world_module.pymunk.Space.add
    for point in ("corners", "add"):
        world = World(three)
        calls = []

        def interrupted(*args, real=real_corners if point == "corners" else real_add,
                        calls=calls):
            calls.append(1)
            if len(calls) == 2:
                raise KeyboardInterrupt
            return real(*args)

        if point == "corners":
            monkeypatch.setattr(world_module, "obstacle_corners", interrupted)
        else:
            monkeypatch.setattr(world_module.pymunk.Space, "add", interrupted)
            calls.append(1)  # the first add of the next call is the cartons'
        with pytest.raises(KeyboardInterrupt):
            world.set_track(nine)
        monkeypatch.undo()
        world.set_track(nine)
        assert len(world.space.shapes) == 1 + len(nine.obstacles)
        world.reset(where)
        assert world.collided


def _circle(world: World, speed: float, steer: float, frames: int = 250) -> tuple[float, float]:
    """Radius [m] and speed [m/s] of the path the car settles on at a held wheel angle
    (fitted through its last positions)."""
    world.reset((0.0, 0.0, 0.0), speed_m_s=speed, steer_rad=steer)
    points = []
    for _ in range(frames):
        world.step(steer)
        points.append(world.pose[:2])
    p = np.array(points[-60:])
    # Least-squares circle: x² + y² + D x + E y + F = 0.
    a = np.column_stack([p[:, 0], p[:, 1], np.ones(len(p))])
    d, e, f = np.linalg.lstsq(a, -(p ** 2).sum(axis=1), rcond=None)[0]
    return float(math.sqrt(d * d / 4 + e * e / 4 - f)), world.speed_m_s


def test_the_dynamic_car_turns_as_the_kinematic_one_slowly_and_slides_when_fast() -> None:
    from tfalda_sim.dynamics import GRAVITY_M_S2, DynamicsParams

    track = load_named("oval")
    params = DynamicsParams()
    steer = 0.25
    kinematic_radius = World(track).car.wheelbase_m / math.tan(steer)
    slow, speed = _circle(World(track, dynamics=params), 0.8, steer)
    assert slow == pytest.approx(kinematic_radius, rel=0.02)
    assert speed == pytest.approx(0.8, rel=0.01)  # cruise control holds it
    fast_kinematic, _ = _circle(World(track), 5.0, steer)
    assert fast_kinematic == pytest.approx(kinematic_radius, rel=1e-3)
    fast, speed = _circle(World(track, dynamics=params), 5.0, steer)
    assert fast >= speed ** 2 / (params.mu * GRAVITY_M_S2) > 1.5 * kinematic_radius
    wet = World(track, dynamics=params)
    wet_radius, _ = _circle(wet, 2.0, steer)
    wet.mu_scale = 0.2
    for _ in range(100):
        wet.step(steer)
    assert wet.lateral_speed_m_s != 0.0
    assert wet_radius < 2.0 ** 2 / (0.2 * params.mu * GRAVITY_M_S2)


def test_the_default_world_is_the_kinematic_car_with_an_ideal_servo() -> None:
    """Neither the servo nor the dynamics change a default world's drive (bit for bit)."""
    from tfalda_sim.vehicle import ServoParams

    track = load_named("oval")
    runs = []
    for world in (World(track), World(track, servo=ServoParams(), dynamics=None)):
        world.reset(lane_start(track, 1.0), speed_m_s=1.5)
        poses = []
        for k in range(100):
            world.step(0.3 * math.sin(0.1 * k))
            poses.append(world.pose)
        runs.append(poses)
    assert runs[0] == runs[1]


def test_a_lagging_servo_turns_later() -> None:
    from tfalda_sim.vehicle import REAL_SERVO

    track = load_named("oval")
    ideal, real = World(track), World(track, servo=REAL_SERVO)
    for world in (ideal, real):
        world.reset((0.0, 0.0, 0.0), speed_m_s=1.0)
        world.step(0.3)
        world.step(0.3)
    # The ideal servo is there (its rate limit: 0.3 rad in 34 ms); the real one's target
    # still lags the command.
    assert ideal.steer_rad == pytest.approx(0.3)
    assert 0.0 < real.steer_rad < 0.29


def test_a_pickled_dynamic_world_drives_on_the_same() -> None:
    from tfalda_sim.dynamics import DynamicsParams

    track = load_named("oval")
    world = World(track, dynamics=DynamicsParams())
    world.reset(lane_start(track, 1.0), speed_m_s=1.5)
    world.step(0.0)
    clone = pickle.loads(pickle.dumps(world))
    world.step(0.1)
    clone.step(0.1)
    assert clone.pose == world.pose


@pytest.mark.parametrize("frames", [1, 2, 3])
def test_actuator_latency_delays_the_commands_by_exactly_the_set_time(frames: int) -> None:
    """With a latency of k frames the wheel angle (and so the pose) after frame t is the
    latency-free world's after frame t − k, for any command sequence."""
    track = load_named("oval")
    ideal = World(track)
    late = World(track, actuator_latency_s=frames / 50.0)
    commands = [0.3 * math.sin(0.3 * t) + 0.1 * (t % 3) for t in range(40)]
    for world in (ideal, late):
        world.reset((0.0, 0.0, 0.0), speed_m_s=1.0, steer_rad=0.0)
    ideal_steer, late_steer = [], []
    for command in commands:
        ideal.step(command)
        late.step(command)
        ideal_steer.append(ideal.steer_rad)
        late_steer.append(late.steer_rad)
    assert late_steer[:frames] == [0.0] * frames
    assert late_steer[frames:] == pytest.approx(ideal_steer[:-frames], abs=1e-12)


def test_half_a_frame_of_actuator_latency_acts_mid_frame() -> None:
    world = World(load_named("oval"), actuator_latency_s=0.01)  # 2 of 4 physics steps
    world.reset((0.0, 0.0, 0.0), speed_m_s=1.0)
    world.step(0.3)
    # Two physics steps of 5 ms at the servo's rate, not four.
    assert world.steer_rad == pytest.approx(2 * 0.005 * world.car.max_steer_rate_rad_s)
    with pytest.raises(ValueError, match="actuator_latency_s"):
        World(load_named("oval"), actuator_latency_s=-0.01)
