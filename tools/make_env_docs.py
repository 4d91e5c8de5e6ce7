"""Make docs/env-render.png: TfaldaTrack-v0's rgb_array render after a short drive."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np

from envs import TfaldaTrackEnv

OUT = Path(__file__).resolve().parent.parent / "docs" / "env-render.png"


def main() -> None:
    env = TfaldaTrackEnv(track=7, render_mode="rgb_array")
    env.reset(seed=0, options={"start": (0.0, -0.2, 0.0)})
    world = env._world  # the docs picture steers with ground truth; agents use the lanes
    for _ in range(120):
        pos = world.position()
        kappa = float(world.track.curvature(pos.s_m))
        a = (-3.0 * pos.cross_track_m - 1.2 * pos.heading_error_rad
             + math.atan(env.car.wheelbase_m * kappa) / env.car.max_steer_rad)
        env.step(np.array([np.clip(a, -1, 1)], np.float32))
    cv2.imwrite(str(OUT), env.render()[..., ::-1])
    print(OUT)


if __name__ == "__main__":
    main()
