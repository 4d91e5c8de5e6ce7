"""TfaldaTrack-v0 with another camera: check_env in every mode, same-seed rollouts,
pickling, other image sizes and lens models, and bad cameras refused."""

from __future__ import annotations

import math
import pickle
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from tfalda_sim.agents.pid import LanePid
from tfalda_sim.camera import Bonnet, CameraMount, PinholeCamera, load_camera, save_camera
from tfalda_sim.envs import TfaldaTrackEnv
from tfalda_sim.perception.geometry import CameraGeometryError
from tfalda_sim.perception.params import INITIAL_ROIS

MODES = ("lanes", "image", "dict")
SMALL_PINHOLE = PinholeCamera(
    np.array([[190.0, 0.0, 319.5], [0.0, 190.0, 199.5], [0.0, 0.0, 1.0]]),
    np.array([-0.05, 0.0, 0.0, 0.0, 0.0]), width=640, height=400,
    mount=CameraMount(height_m=0.18, pitch_rad=math.radians(14.0)),
    bonnet=Bonnet(top_row=385.0, edge_drop_px=8.0), frame_rate_hz=30.0)


@pytest.mark.parametrize("mode", MODES)
def test_check_env_with_the_reference_car_camera(mode: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gym.make("TfaldaTrack-v0", observation=mode, camera="reference-car",
                       render_mode="rgb_array")
        check_env(env.unwrapped)
        env.close()


def test_geometry_and_spaces_follow_the_camera() -> None:
    env = TfaldaTrackEnv(track="oval", observation="dict", camera=SMALL_PINHOLE)
    assert env.observation_space["image"].shape == (400, 640, 1)
    assert env.detector_config.layout.table_px != INITIAL_ROIS
    assert env.metadata["render_fps"] == 30.0
    obs, _ = env.reset(seed=0)
    assert obs["image"].shape == (400, 640, 1)
    pid = LanePid(camera=env.camera)
    for _ in range(60):
        obs, _, terminated, _, info = env.step(pid.act(obs["lanes"]))
        assert not terminated
    assert info["detector_hit_rate"] > 0.5
    # the thesis camera keeps the thesis' literal numbers
    assert TfaldaTrackEnv(track="oval").detector_config.layout.table_px == INITIAL_ROIS


def test_same_seed_rollouts_are_identical_and_the_env_pickles() -> None:
    def rollout(env: TfaldaTrackEnv) -> list[np.ndarray]:
        obs, _ = env.reset(seed=3)
        env.action_space.seed(3)
        out = [obs]
        for _ in range(40):
            obs, *_ = env.step(env.action_space.sample())
            out.append(obs)
        return out

    a = rollout(TfaldaTrackEnv(camera="reference-car", domain_randomization=True))
    b = rollout(TfaldaTrackEnv(camera="reference-car", domain_randomization=True))
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    env = TfaldaTrackEnv(camera="reference-car", track="oval")
    env.reset(seed=1)
    copy = pickle.loads(pickle.dumps(env))
    act = np.array([0.1], np.float32)
    assert np.array_equal(env.step(act)[0], copy.step(act)[0])


def test_a_camera_file(tmp_path: Path) -> None:
    path = save_camera(SMALL_PINHOLE, tmp_path / "car.yaml")
    env = TfaldaTrackEnv(track="oval", camera=str(path))
    assert env.camera.width == 640 and env.camera.lens.value == "pinhole"


def test_bad_cameras_are_refused() -> None:
    with pytest.raises(ValueError, match="unknown camera 'sony'"):
        TfaldaTrackEnv(camera="sony")
    with pytest.raises(TypeError, match="camera must be a profile name"):
        TfaldaTrackEnv(camera=3)  # type: ignore[arg-type]
    blind = load_camera("thesis").with_mount(pitch_rad=math.radians(-40.0))
    with pytest.raises(CameraGeometryError, match="does not see the road"):
        TfaldaTrackEnv(camera=blind)
