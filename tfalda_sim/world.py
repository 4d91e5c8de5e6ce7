"""The closed-loop world: the car on a track, simulated in pymunk.

The car is a kinematic pymunk body driven by the bicycle model of ``tfalda_sim.vehicle``
or, with ``dynamics``, by the dynamic single-track model of ``tfalda_sim.dynamics`` (its
velocity and yaw rate are set every physics step, pymunk integrates them); the
track's obstacle cartons are static bodies. One ``step`` is one camera frame (50 per
second) made of a fixed number of physics steps; after each physics step the car's body
is tested against the cartons, so a collision is caught even at top speed (4 cm per
physics step at 8.3 m/s, thinner than any carton).

Where the car is on the track (arc length, lateral offset, heading error) comes from
the track model's reverse query, with the last arc length as the hint.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
import pymunk

from tfalda_sim.tracks import Track
from tfalda_sim.tracks.rules import obstacle_corners

from .camera import FRAME_RATE_HZ
from .dynamics import DynamicsParams, advance, cruise_accel, kinematic_state
from .vehicle import (
    CarParams,
    ServoParams,
    motor_step,
    servo_step,
    servo_target_step,
    yaw_rate,
)

PHYSICS_STEPS_PER_FRAME: int = 4
"""Physics steps per camera frame (5 ms each at 50 frames/s)."""

_CAR = 1  # pymunk collision types
_OBSTACLE = 2


@dataclass(frozen=True)
class TrackPosition:
    """Where the car is relative to the track's lanes."""

    s_m: float
    """Arc length of the nearest centre-line point [m] (wraps on closed tracks)."""
    lateral_m: float
    """Offset of the rear axle centre from the centre line, left positive [m]."""
    cross_track_m: float
    """Offset from the right lane's centre (the ego lane), left positive [m]."""
    heading_error_rad: float
    """Car yaw minus the road's heading at ``s_m``, wrapped to (−π, π] [rad]."""
    off_road: bool
    """The centre of the car's body is beyond the outer edge of a side line (half the car
    has left the road)."""


class World:
    """A car on ``track``: ``reset`` places it, ``step`` advances one camera frame.

    Without a throttle the car holds the speed given to ``reset`` (cruise control); with
    one (``step(steer, throttle=...)``) it accelerates and brakes within the car's limits.

    ``dynamics``: None (the kinematic bicycle: it turns as sharply as its wheels point at
    any speed) or a ``DynamicsParams`` (the dynamic single-track car: it slides once
    v² / R exceeds its tyres' grip; ``mu_scale`` scales its friction, a wet patch).
    ``servo``: the steering servo's lag and dead band (default: none).
    ``actuator_latency_s``: a command given to ``step`` acts this long after [s] (resolved
    at physics steps; before it, the previous command still acts).
    """

    def __init__(self, track: Track, car: CarParams | None = None, *,
                 frame_rate_hz: float = FRAME_RATE_HZ,
                 physics_steps: int = PHYSICS_STEPS_PER_FRAME,
                 dynamics: DynamicsParams | None = None,
                 servo: ServoParams | None = None,
                 actuator_latency_s: float = 0.0) -> None:
        if not (math.isfinite(frame_rate_hz) and frame_rate_hz > 0):
            raise ValueError(f"frame_rate_hz must be finite and > 0, got {frame_rate_hz}")
        if physics_steps < 1:
            raise ValueError(f"physics_steps must be ≥ 1, got {physics_steps}")
        if not (math.isfinite(actuator_latency_s) and actuator_latency_s >= 0):
            raise ValueError(f"actuator_latency_s must be finite and ≥ 0, got "
                             f"{actuator_latency_s}")
        self.actuator_latency_s = float(actuator_latency_s)
        # Commands given and not yet superseded: (time given [s], steer, throttle).
        self._commands: deque[tuple[float, float, float | None]] = deque()
        self.car = car or CarParams()
        self.frame_dt_s = 1.0 / frame_rate_hz
        self.physics_steps = int(physics_steps)
        self.space = pymunk.Space()
        self.body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        self.shape = pymunk.Poly(self.body, self.car.body_outline())
        self.shape.collision_type = _CAR
        self.space.add(self.body, self.shape)
        self.obstacle_shapes: list[pymunk.Poly] = []
        self.speed_m_s = 0.0
        self.steer_rad = 0.0
        self.dynamics = dynamics
        self.servo = servo or ServoParams()
        self._servo_target = 0.0
        self._params = None if dynamics is None else dynamics.vector(self.car.wheelbase_m)
        self._state = np.zeros(7)  # the dynamic model's state (tfalda_sim.dynamics)
        self._set_speed_m_s = 0.0  # what cruise control holds (dynamic car)
        self.mu_scale = 1.0
        self.set_track(track)

    def set_track(self, track: Track) -> None:
        """Put the car on another track: its cartons replace the old ones; the clock, the
        collision flag and the arc-length hint start again (place the car with ``reset``
        next). The space, the car's body and shape stay: building them costs ~0.2 ms of a
        reset onto a new track (pymunk's allocations, in a process whose caches the
        renderer has just filled), and a kinematic car moves and collides the same in a
        space that held other cartons before.

        Safe to call again after an interruption (a Ctrl-C) anywhere inside: the new
        cartons are listed before they are added, and only shapes in the space are taken
        out of it."""
        shapes = []
        for k in range(len(track.obstacles)):  # may raise: nothing changed yet
            shape = pymunk.Poly(self.space.static_body,
                                [tuple(map(float, c)) for c in obstacle_corners(track, k)])
            shape.collision_type = _OBSTACLE
            shapes.append(shape)
        for shape in self.obstacle_shapes:
            if shape.space is not None:
                self.space.remove(shape)
            # The static body keeps its shapes (pymunk): without this, every carton of
            # every earlier track would live as long as the world.
            shape.body = None
        self.obstacle_shapes = shapes  # listed first: a retry takes out what was added
        if shapes:
            self.space.add(*shapes)
        self.track = track
        self.collided = False
        self.time_s = 0.0
        self._s_hint: float | None = None

    # ------------------------------------------------------------------ state
    @property
    def pose(self) -> tuple[float, float, float]:
        """Rear axle centre (x [m], y [m]) and yaw [rad] in the track frame."""
        p = self.body.position
        return float(p.x), float(p.y), float(self.body.angle)

    def reset(self, pose: tuple[float, float, float], speed_m_s: float = 0.0,
              steer_rad: float = 0.0) -> None:
        """Place the car at ``pose`` moving at ``speed_m_s`` with the wheels at
        ``steer_rad``; clears the collision flag and the clock."""
        x, y, yaw = (float(v) for v in pose)
        for name, v in (("pose", x), ("pose", y), ("pose", yaw), ("speed_m_s", speed_m_s),
                        ("steer_rad", steer_rad)):
            if not math.isfinite(v):
                raise ValueError(f"{name} must be finite, got {pose if name == 'pose' else v}")
        if not 0.0 <= speed_m_s <= self.car.max_speed_m_s:
            raise ValueError(f"speed_m_s must be in [0, {self.car.max_speed_m_s}] m/s, got "
                             f"{speed_m_s}")
        self.speed_m_s = float(speed_m_s)
        self.steer_rad = min(max(float(steer_rad), -self.car.max_steer_rad),
                             self.car.max_steer_rad)
        self.time_s = 0.0
        self._s_hint = None
        self._servo_target = self.steer_rad
        self._set_speed_m_s = self.speed_m_s
        self._commands = deque([(-math.inf, self.steer_rad, None)])
        self.mu_scale = 1.0
        if self._params is not None:
            self._state = kinematic_state(x, y, yaw, self.speed_m_s, self.steer_rad,
                                          self._params)
        self.place((x, y, yaw))
        self.collided = bool(self.obstacle_shapes) and self._touching()

    def place(self, pose: tuple[float, float, float]) -> None:
        """Move the car to ``pose`` at once (a reset, or a kick of a fault schedule); speed
        and steering stay."""
        x, y, yaw = (float(v) for v in pose)
        self.body.position = (x, y)
        self.body.angle = yaw
        self.space.reindex_shapes_for_body(self.body)

    def step(self, steer_command_rad: float, *, throttle: float | None = None) -> bool:
        """Advance one camera frame with the servo commanded to ``steer_command_rad``
        [rad] and, if given, the motor at ``throttle`` ∈ [−1, 1]. Returns whether the car
        touched an obstacle during the frame (also kept in ``collided``)."""
        if not math.isfinite(steer_command_rad):
            raise ValueError(f"steer_command_rad must be finite, got {steer_command_rad}")
        if throttle is not None and not (math.isfinite(throttle) and -1 <= throttle <= 1):
            raise ValueError(f"throttle must be in [-1, 1], got {throttle}")
        dt = self.frame_dt_s / self.physics_steps
        car = self.car
        servo = self.servo
        hit = False
        latency = self.actuator_latency_s
        if latency > 0.0:
            self._commands.append((self.time_s, float(steer_command_rad), throttle))
        for k in range(self.physics_steps):
            if latency > 0.0:
                steer_command_rad, throttle = self._acting(self.time_s + k * dt - latency)
            if servo.lag_s > 0.0 or servo.dead_band_rad > 0.0:
                self._servo_target = servo_target_step(self._servo_target,
                                                       steer_command_rad, dt, servo.lag_s)
                self.steer_rad = servo_step(self.steer_rad, self._servo_target, dt, car,
                                            servo.dead_band_rad)
            else:
                self.steer_rad = servo_step(self.steer_rad, steer_command_rad, dt, car)
            if self._params is not None:
                self._move_dynamic(throttle, dt)
            else:
                if throttle is not None:
                    self.speed_m_s = motor_step(self.speed_m_s, throttle, dt, car)
                omega = yaw_rate(self.speed_m_s, self.steer_rad, car)
                # Velocity along the mid-step heading: second-order accurate on an arc.
                heading = self.body.angle + 0.5 * omega * dt
                self.body.velocity = (self.speed_m_s * math.cos(heading),
                                      self.speed_m_s * math.sin(heading))
                self.body.angular_velocity = omega
            self.space.step(dt)
            if self.obstacle_shapes and self._touching():
                hit = True
        self.time_s += self.frame_dt_s
        self.collided = self.collided or hit
        return hit

    def _acting(self, given_by_s: float) -> tuple[float, float | None]:
        """The newest command given by ``given_by_s`` (the older ones are dropped)."""
        commands = self._commands
        while len(commands) > 1 and commands[1][0] <= given_by_s + 1e-9:
            commands.popleft()
        return commands[0][1], commands[0][2]

    def _move_dynamic(self, throttle: float | None, dt: float) -> None:
        """The dynamic car over ``dt``: its state integrated (``dynamics.advance``) from
        the body's pose, the body given the velocity that takes it to the new pose."""
        car, state = self.car, self._state
        p = self.body.position
        x0, y0, yaw0 = float(p.x), float(p.y), float(self.body.angle)
        state[0], state[1], state[2] = x0, y0, yaw0  # a kick (place) moved the body
        if throttle is None:
            a_cmd = cruise_accel(float(state[3]), self._set_speed_m_s, car.max_accel_m_s2,
                                 car.max_brake_m_s2)
        else:
            a_cmd = throttle * (car.max_accel_m_s2 if throttle >= 0 else car.max_brake_m_s2)
        advance(state, self.steer_rad, a_cmd, dt, self._params, self.mu_scale,
                car.max_speed_m_s)
        self.body.velocity = ((state[0] - x0) / dt, (state[1] - y0) / dt)
        self.body.angular_velocity = (state[2] - yaw0) / dt
        self.speed_m_s = float(state[3])

    @property
    def lateral_speed_m_s(self) -> float:
        """The CoG's sideways speed in the car frame [m/s] (0 for the kinematic car)."""
        return float(self._state[4]) if self._params is not None else 0.0

    def _touching(self) -> bool:
        """The car's body overlaps an obstacle."""
        return any(q.shape is not None and q.shape.collision_type == _OBSTACLE
                   for q in self.space.shape_query(self.shape))

    # ------------------------------------------------------------------ track
    def position(self) -> TrackPosition:
        """Where the car is on the track (the last answer is the next query's hint)."""
        x, y, yaw = self.pose
        track = self.track
        loc = track.locate(x, y, s_hint_m=self._s_hint)
        self._s_hint = loc.s_m
        road_heading = track.heading_at(loc.s_m)
        err = (yaw - road_heading + math.pi) % (2.0 * math.pi) - math.pi
        # The body's centre, ahead of the rear axle (the road is straight on that scale).
        ahead = 0.5 * self.car.length_m - self.car.rear_overhang_m
        centre_lateral = loc.lateral_m + ahead * math.sin(err)
        return TrackPosition(s_m=loc.s_m, lateral_m=loc.lateral_m,
                             cross_track_m=loc.lateral_m + 0.5 * track.lane_width_m,
                             heading_error_rad=err,
                             off_road=abs(centre_lateral) > track.half_road_m)
