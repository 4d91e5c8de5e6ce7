"""The oracle: steers from the ground truth (the track geometry), not from the camera.

A reference for what the car and the control law can do when perception is perfect
(docs/agents.md uses it to show that the PID's failures are perception failures), and a
driver for tests and pictures. Not a lane keeper a real car could run.
"""

from __future__ import annotations

import math

import numpy as np

from tfalda_sim.envs import TfaldaTrackEnv

K_LATERAL: float = 3.0
"""Steering command per metre of offset from the right lane's centre [1/m]."""

K_HEADING: float = 1.2
"""Steering command per radian of heading error [1/rad]."""


class OracleAgent:
    """Steering from ``env``'s true lane offset, heading error and road curvature."""

    def __init__(self, env: TfaldaTrackEnv) -> None:
        self.env = env

    def reset(self) -> None:
        pass

    def act(self, obs: object = None) -> np.ndarray:
        world = self.env._world
        if world is None:
            raise RuntimeError("reset the env before asking the oracle")
        pos = world.position()
        kappa = float(world.track.curvature(pos.s_m))
        car = self.env.car
        a = (-K_LATERAL * pos.cross_track_m - K_HEADING * pos.heading_error_rad
             + math.atan(car.wheelbase_m * kappa) / car.max_steer_rad)
        return np.array([np.clip(a, -1.0, 1.0)], np.float32)
