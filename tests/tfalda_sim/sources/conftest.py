"""Camera frames for the frame-source tests: five rendered once per test run (the env's
camera, (480, 752) uint8 grey) and the same at a quarter of the size, which most tests
write (small recordings, quick tests)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tfalda_sim.envs import TfaldaTrackEnv

FRAMES = 5
EPOCH_NS = 1_712_345_678_000_000_000
"""The first frame's stamp in the tests [ns since the epoch]."""
PERIOD_NS = 33_333_333
"""30 Hz [ns]."""


@pytest.fixture(scope="session")
def rendered() -> list[np.ndarray]:
    """Five consecutive camera frames of a drive, (480, 752) uint8."""
    env = TfaldaTrackEnv(observation="image")
    try:
        env.reset(seed=0)
        frames = []
        for _ in range(FRAMES):
            env.step(np.zeros(1, np.float32))
            frames.append(env.camera_frame())
    finally:
        env.close()
    return frames


@pytest.fixture(scope="session")
def small(rendered: list[np.ndarray]) -> list[np.ndarray]:
    """The rendered frames at 188×120 px."""
    return [cv2.resize(f, (188, 120), interpolation=cv2.INTER_AREA) for f in rendered]


@pytest.fixture(scope="session")
def stamps() -> list[int]:
    """Header stamps of the five frames [ns]: 30 Hz with a little jitter."""
    return [EPOCH_NS + k * PERIOD_NS + (k % 2) * 1_000_000 for k in range(FRAMES)]
