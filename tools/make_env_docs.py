"""Make docs/env-render.png: TfaldaTrack-v0's rgb_array render after a short drive."""

from __future__ import annotations

from pathlib import Path

import cv2

from tfalda_sim.agents.oracle import OracleAgent
from tfalda_sim.envs import TfaldaTrackEnv

OUT = Path(__file__).resolve().parent.parent / "docs" / "env-render.png"


def main() -> None:
    env = TfaldaTrackEnv(track=7, render_mode="rgb_array")
    env.reset(seed=0, options={"start": (0.0, -0.2, 0.0)})
    oracle = OracleAgent(env)  # the picture steers with ground truth; agents use the lanes
    for _ in range(120):
        env.step(oracle.act())
    cv2.imwrite(str(OUT), env.render()[..., ::-1])
    print(OUT)


if __name__ == "__main__":
    main()
