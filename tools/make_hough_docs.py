"""Make docs/hough/stage-view.png: the seed's 2×2 stage view (simulator preset) of a camera
frame in a curve of held-out track 10000."""

from __future__ import annotations

from pathlib import Path

import cv2

from tfalda_sim.agents.oracle import OracleAgent
from tfalda_sim.envs import TfaldaTrackEnv
from tfalda_sim.perception import HoughConfig, HoughDetector
from tfalda_sim.rendering.overlay import stage_view

OUT = Path(__file__).resolve().parent.parent / "docs" / "hough" / "stage-view.png"


def main() -> None:
    env = TfaldaTrackEnv(track=10000)
    env.reset(seed=0, options={"start": (0.0, -0.2, 0.0)})
    oracle = OracleAgent(env)  # ground-truth steering: the picture is about the detector
    for _ in range(60):
        env.step(oracle.act())
    result = HoughDetector(HoughConfig.simulator()).detect(env.camera_frame())
    OUT.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(OUT), stage_view(result))
    print(OUT)


if __name__ == "__main__":
    main()
