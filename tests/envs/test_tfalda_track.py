"""TfaldaTrack-v0: API checks, determinism, bad input, faults, termination, rendering."""

from __future__ import annotations

import pickle
import warnings
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import tfalda_sim
from tfalda_sim.agents.oracle import OracleAgent
from tfalda_sim.envs import StartInCarton, TfaldaTrackEnv
from tfalda_sim.faults import Blackout, LateralKick, MarkingGap
from tfalda_sim.tracks import load_named

MODES = ("lanes", "image", "dict")


@pytest.fixture(scope="module")
def oval_env() -> TfaldaTrackEnv:
    return TfaldaTrackEnv(track="oval", render_mode="rgb_array")


@pytest.mark.parametrize("mode", MODES)
def test_gymnasium_check_env_passes_with_warnings_as_errors(mode: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gym.make("TfaldaTrack-v0", observation=mode, render_mode="rgb_array")
        check_env(env.unwrapped)
        env.close()


def test_registration_is_idempotent_and_has_a_module_path() -> None:
    tfalda_sim.register_envs()
    tfalda_sim.register_envs()
    spec = gym.spec("TfaldaTrack-v0")
    assert spec.max_episode_steps == tfalda_sim.MAX_EPISODE_STEPS
    assert isinstance(spec.entry_point, str)
    env = gym.make("tfalda_sim:TfaldaTrack-v0", track="oval")
    assert isinstance(env.unwrapped, TfaldaTrackEnv)


def rollout(env: gym.Env, seed: int, steps: int, options: dict | None = None) -> tuple:
    obs, info = env.reset(seed=seed, options=options)
    env.action_space.seed(seed)
    observations, rewards, infos = [obs], [], [info]
    for _ in range(steps):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample() * 0.3)
        observations.append(obs)
        rewards.append(reward)
        infos.append(info)
        if terminated or truncated:
            obs, info = env.reset()
            observations.append(obs)
            infos.append(info)
    return observations, rewards, infos


def equal_obs(x: np.ndarray | dict, y: np.ndarray | dict) -> bool:
    if isinstance(x, dict):
        return x.keys() == y.keys() and all(np.array_equal(x[k], y[k]) for k in x)
    return np.array_equal(x, y)


def same(a: tuple, b: tuple) -> bool:
    obs_a, rew_a, info_a = a
    obs_b, rew_b, info_b = b
    return (len(obs_a) == len(obs_b) and rew_a == rew_b and info_a == info_b
            and all(equal_obs(x, y) for x, y in zip(obs_a, obs_b, strict=True)))


@pytest.mark.parametrize("randomize", [False, True])
def test_same_seed_gives_bit_identical_1000_step_rollouts(randomize: bool) -> None:
    kwargs = {"track": 5, "domain_randomization": randomize}
    a = rollout(TfaldaTrackEnv(**kwargs), seed=11, steps=1000)
    b = rollout(TfaldaTrackEnv(**kwargs), seed=11, steps=1000)
    assert same(a, b)
    c = rollout(TfaldaTrackEnv(**kwargs), seed=12, steps=50)
    assert not same(a, c)


@pytest.mark.parametrize("mode", ["lanes", "image"])
def test_an_episode_does_not_depend_on_the_episodes_before_it(mode: str) -> None:
    """A new track per reset takes over the last scene's memory (``build_scene(reuse=…)``)
    and may share marking maps: an env that drove other tracks (and the same track with
    other effects) before gives, for a seed, the rollout of a fresh env."""
    used = TfaldaTrackEnv(observation=mode, domain_randomization=True)
    for seed in (1, 2, 3, 2):
        rollout(used, seed=seed, steps=25)
    for seed in (4, 3):
        assert same(rollout(used, seed=seed, steps=40),
                    rollout(TfaldaTrackEnv(observation=mode, domain_randomization=True),
                            seed=seed, steps=40))
    assert used._scene.tiles is not None and not used._scene.tiles.retired


def test_same_seed_image_rollouts_are_identical_and_generated_tracks_follow_the_seed() -> None:
    a = rollout(TfaldaTrackEnv(observation="image"), seed=3, steps=40)
    b = rollout(TfaldaTrackEnv(observation="image"), seed=3, steps=40)
    assert same(a, b)
    tracks = {TfaldaTrackEnv(track_seeds=(100, 110)).reset(seed=s)[1]["track"] for s in range(6)}
    assert tracks <= set(range(100, 110)) and len(tracks) > 1


@pytest.mark.parametrize("action, match", [
    (np.array([np.nan], np.float32), "finite"),
    (np.array([1.5], np.float32), r"\[-1, 1\]"),
    (np.array([0.1, 0.2], np.float32), "shape"),
    (np.zeros((1, 1), np.float32), "shape"),
    (np.array(["a"]), "real numbers"),
])
def test_bad_actions_raise_naming_the_problem(oval_env: TfaldaTrackEnv, action, match: str) -> None:
    oval_env.reset(seed=0)
    with pytest.raises(ValueError, match=match):
        oval_env.step(action)


def test_bad_options_and_arguments_are_refused(oval_env: TfaldaTrackEnv) -> None:
    with pytest.raises(ValueError, match=r"unknown reset option.*'spedd'"):
        oval_env.reset(options={"spedd": 2.0})
    with pytest.raises(ValueError, match="unknown track 'ovl'"):
        oval_env.reset(options={"track": "ovl"})
    with pytest.raises(ValueError, match="off the road"):
        oval_env.reset(options={"start": (1.0, 0.9, 0.0)})
    with pytest.raises(TypeError, match="unknown fault"):
        oval_env.reset(options={"faults": ["blackout"]})
    with pytest.raises(ValueError, match="unknown observation"):
        TfaldaTrackEnv(observation="pixels")
    with pytest.raises(ValueError, match="speed_m_s"):
        TfaldaTrackEnv(speed_m_s=20.0)
    with pytest.raises(ValueError, match="track_seeds"):
        TfaldaTrackEnv(track_seeds=(5, 5))


def test_reset_options_place_the_car(oval_env: TfaldaTrackEnv) -> None:
    _, info = oval_env.reset(seed=0, options={"start": (4.0, -0.15, 0.05), "speed_m_s": 2.5})
    assert info["s_m"] == pytest.approx(4.0, abs=1e-6)
    assert info["cross_track_m"] == pytest.approx(0.05, abs=1e-6)
    assert info["heading_error_rad"] == pytest.approx(0.05, abs=1e-9)
    assert info["speed_m_s"] == 2.5
    _, info = oval_env.reset(options={"track": load_named("thesis")})
    assert info["track"] == "thesis"  # a given track is labelled with its own name


def centre_steering(env: TfaldaTrackEnv) -> np.ndarray:
    """Ground-truth steering for the tests (the agents steer from the lanes)."""
    return OracleAgent(env).act()


def test_a_centred_drive_earns_about_one_per_step_and_counts_laps() -> None:
    env = TfaldaTrackEnv(track="oval", max_laps=1)
    env.reset(seed=0, options={"start": (0.0, -0.2, 0.0)})
    rewards = []
    for _ in range(3000):
        _, reward, terminated, truncated, info = env.step(centre_steering(env))
        rewards.append(reward)
        assert not terminated
        if truncated:
            break
    assert truncated and info["lap"] == 1
    assert info["distance_m"] == pytest.approx(env._world.track.length_m, abs=0.05)
    assert 0.9 < np.mean(rewards) <= 1.0
    assert info["detector_hit_rate"] > 0.8 and info["roi_resets"] == 0


def test_leaving_the_road_terminates_with_the_crash_penalty() -> None:
    env = TfaldaTrackEnv(track="oval")
    env.reset(seed=0, options={"start": (0.0, -0.2, 0.0)})
    for _ in range(500):
        _, reward, terminated, _, info = env.step(np.array([-1.0], np.float32))
        if terminated:
            break
    assert terminated and info["off_road"] and reward < -5


def test_hitting_a_carton_terminates() -> None:
    env = TfaldaTrackEnv(track=3, obstacles=True)
    env.reset(seed=0)
    ob = env._world.track.obstacles[0]
    lateral = -0.2 if ob.lane.value == "right" else 0.2
    env.reset(options={"start": (ob.s_m - 1.2, lateral, 0.0)})
    for _ in range(200):
        _, reward, terminated, _, info = env.step(centre_steering(env))
        if terminated:
            break
    assert terminated and info["collision"] and not info["off_road"] and reward < -5
    assert env.reset(seed=0)[1]["collision"] is False  # random starts avoid the cartons


def test_a_start_inside_a_carton_is_refused_and_the_env_stays_usable() -> None:
    """Its own error type, so that a caller (drive's recovery) can move on past it."""
    env = TfaldaTrackEnv(track=3, obstacles=True)
    env.reset(seed=0)
    ob = env._world.track.obstacles[0]
    lateral = -0.2 if ob.lane.value == "right" else 0.2
    with pytest.raises(StartInCarton, match="inside a carton; choose another"):
        env.reset(options={"start": (ob.s_m, lateral, 0.0)})
    _, info = env.reset(options={"start": (ob.s_m - 1.2, lateral, 0.0)})
    assert info["collision"] is False and abs(info["s_m"] - (ob.s_m - 1.2)) < 1e-6
    assert not env.step(centre_steering(env))[2]


def test_an_open_track_truncates_at_its_end() -> None:
    env = TfaldaTrackEnv(track="straight", speed_m_s=4.0)
    env.reset(seed=0)
    for _ in range(2000):
        _, _, terminated, truncated, _ = env.step(centre_steering(env))
        if terminated or truncated:
            break
    assert truncated and not terminated


def test_blackout_makes_the_lis_reset_and_recover() -> None:
    env = TfaldaTrackEnv(track="oval", faults=[Blackout(start_s=0.4, duration_s=0.8)])
    env.reset(seed=0, options={"start": (0.0, -0.2, 0.0)})
    resets, hits = [], []
    for _ in range(150):
        _, _, terminated, _, info = env.step(centre_steering(env))
        resets.append(info["roi_reset"])
        hits.append(info["detector_hit_rate"])
        assert not terminated
    first = resets.index(True)
    assert 20 <= first < 60  # during the blackout
    assert np.mean(hits[100:]) > 0.8  # lanes found again after it


def test_lateral_kick_moves_the_car_sideways() -> None:
    env = TfaldaTrackEnv(track="oval", faults=[LateralKick(start_s=0.1, offset_m=0.12)])
    env.reset(seed=0, options={"start": (0.0, -0.2, 0.0)})
    errors = [env.step(np.zeros(1, np.float32))[4]["cross_track_m"] for _ in range(6)]
    assert errors[4] - errors[3] == pytest.approx(0.12, abs=0.005)


def test_marking_gap_is_rendered_but_not_scored_away(oval_env: TfaldaTrackEnv) -> None:
    obs_clean, _ = oval_env.reset(seed=0, options={"start": (2.0, -0.2, 0.0)})
    obs_gap, info = oval_env.reset(seed=0, options={
        "start": (2.0, -0.2, 0.0), "faults": [MarkingGap(s_m=1.5, length_m=3.0)]})
    assert not np.array_equal(obs_clean, obs_gap)
    assert info["cross_track_m"] == pytest.approx(0.0, abs=1e-9)  # the real track


def test_camera_frame_is_what_the_detector_saw_in_every_mode() -> None:
    frames, lanes = {}, {}
    for mode in ("lanes", "dict"):
        env = TfaldaTrackEnv(track="oval", observation=mode)
        with pytest.raises(RuntimeError, match="reset"):
            env.camera_frame()
        obs, _ = env.reset(seed=3, options={"faults": [Blackout(start_s=0.1, duration_s=0.02)]})
        for _ in range(4):
            obs, *_ = env.step(np.full(1, 0.2, np.float32))
        frames[mode] = env.camera_frame()
        lanes[mode] = obs["lanes"] if mode == "dict" else obs
        assert frames[mode].shape == (480, 752) and frames[mode].dtype == np.uint8
        if mode == "dict":
            assert np.array_equal(frames[mode], obs["image"][..., 0])
            frames[mode][:] = 0  # a copy: the observation is not changed through it
            assert obs["image"].max() > 0
            frames[mode] = env.camera_frame()
        env.step(np.zeros(1, np.float32))  # the blackout frame: faults are in it
        assert env.camera_frame().max() < 10
    # "lanes" mode renders only the ROIs, the detector sees them: same lanes as from the
    # full frame, and the full frame rendered afterwards is the same pixels.
    assert np.array_equal(lanes["lanes"], lanes["dict"])
    assert np.array_equal(frames["lanes"], frames["dict"])


def test_render_shows_the_frame_with_rois_and_the_inset(oval_env: TfaldaTrackEnv) -> None:
    oval_env.reset(seed=0)
    oval_env.step(np.zeros(1, np.float32))
    img = oval_env.render()
    assert img.shape == (480, 752, 3) and img.dtype == np.uint8
    # ROI rectangles are drawn in colour; the grey camera frame has R = G = B.
    assert np.any(img[..., 0] != img[..., 2])
    quiet = TfaldaTrackEnv(track="oval")
    quiet.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode"):
        assert quiet.render() is None


@pytest.mark.parametrize("mode", MODES)
def test_the_env_pickles_and_continues_identically(mode: str) -> None:
    env = TfaldaTrackEnv(track=4, observation=mode, domain_randomization=True)
    env.reset(seed=2)
    for _ in range(10):
        env.step(np.array([0.05], np.float32))
    copy = pickle.loads(pickle.dumps(env))
    assert len(pickle.dumps(env)) < 5_000_000  # caches are not pickled
    for _ in range(10):
        a = env.step(np.array([-0.1], np.float32))
        b = copy.step(np.array([-0.1], np.float32))
        assert same(([a[0]], [a[1]], [a[4]]), ([b[0]], [b[1]], [b[4]]))


@pytest.mark.parametrize("vector", ["sync", "async"])
def test_vector_envs(vector: str) -> None:
    make = gym.vector.SyncVectorEnv if vector == "sync" else gym.vector.AsyncVectorEnv
    fns = [lambda: gym.make("TfaldaTrack-v0", track="oval")] * 2
    envs = make(fns)
    try:
        obs, info = envs.reset(seed=[1, 2])
        assert obs.shape == (2, 42) and obs.dtype == np.float32
        for _ in range(5):
            obs, reward, _terminated, _truncated, info = envs.step(
                np.zeros((2, 1), np.float32))
        assert reward.shape == (2,) and info["cross_track_m"].shape == (2,)
    finally:
        envs.close()


def test_record_video_wrapper_writes_an_mp4(tmp_path) -> None:
    pytest.importorskip("moviepy")
    env = gym.make("TfaldaTrack-v0", track="oval", render_mode="rgb_array",
                   max_episode_steps=20)
    env = gym.wrappers.RecordVideo(env, str(tmp_path / "videos"), episode_trigger=lambda e: True,
                                   disable_logger=True)
    env.reset(seed=0)
    done = False
    while not done:
        _, _, terminated, truncated, _ = env.step(np.zeros(1, np.float32))
        done = terminated or truncated
    env.close()
    videos = list((tmp_path / "videos").glob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 1000


def test_a_reset_refused_for_its_track_leaves_the_env_as_it_was() -> None:
    """A track the renderer refuses (too large) fails the reset before the last scene
    hands its memory over: the next reset and its rollout are a fresh env's."""
    from tfalda_sim.tracks import Straight, Track

    env = TfaldaTrackEnv()
    rollout(env, seed=0, steps=5)
    with pytest.raises(ValueError, match="too large"):
        env.reset(options={"track": Track((Straight(100.0),), closed=False)})
    assert same(rollout(env, seed=0, steps=20), rollout(TfaldaTrackEnv(), seed=0, steps=20))


@pytest.mark.parametrize("kwargs", [{}, {"domain_randomization": True},
                                    {"faults": (MarkingGap(s_m=1.0, length_m=1.0),)}],
                         ids=["default", "domain randomization", "faults"])
def test_prepare_reset_prepares_the_next_episode_and_changes_nothing(
        kwargs: dict[str, Any]) -> None:
    """``prepare_reset`` (a vector env's idle lane) generates the track the next reset
    draws and builds its scene (effects, scene seed and faults drawn as the reset draws
    them), which the reset then takes; episodes equal an env's that never prepared, and a
    seeded reset (another draw) generates and builds its own."""
    plain, eager = gym.make("TfaldaTrack-v0", **kwargs), gym.make("TfaldaTrack-v0", **kwargs)
    env = eager.unwrapped
    assert not env.prepare_reset()  # no np_random yet: nothing to draw from
    for e in (plain, eager):
        e.reset(seed=3)
    for episode in range(4):
        assert env.prepare_reset()
        assert not env.prepare_reset()  # prepared already
        spec, track = env._prepared
        scene = env._prepared_scene[1]
        before = env._scene
        if episode == 2:
            want, got = plain.reset(seed=9), eager.reset(seed=9)  # not the prepared draw
            assert env._track is not track and env._scene is not scene
        else:
            want, got = plain.reset(), eager.reset()
            assert env._track is track and env._track_label == spec
            assert env._scene is scene and env._spare_scene is before
        assert env._prepared_scene is None
        assert np.array_equal(want[0], got[0]) and want[1] == got[1]
        for _ in range(5):
            a = np.array([0.1], np.float32)
            pairs = zip(plain.step(a), eager.step(a), strict=True)
            assert all(np.array_equal(x, y) for x, y in pairs)
        assert np.array_equal(plain.unwrapped.camera_frame(), env.camera_frame())
    # The spare scene's memory went to the scene prepared next (it can render no more).
    spare = env._spare_scene
    assert env.prepare_reset() and env._spare_scene is None
    assert spare.tiles is not None and spare.tiles.retired
    fixed = gym.make("TfaldaTrack-v0", track="oval").unwrapped
    fixed.reset(seed=0)
    assert not fixed.prepare_reset()  # a fixed track: nothing to generate


@pytest.mark.parametrize("observation", ["lanes", "image"])
def test_prepare_reset_goes_in_stages_and_paints_the_first_frame_ahead(
        observation: str) -> None:
    """``prepare_reset(stop)`` asks ``stop`` after each stage and ends there when it says
    so; the next call goes on: track, scene, then the first frame's paint, after which the
    reset's first frame paints nothing more. The episode equals an unprepared env's."""
    plain = gym.make("TfaldaTrack-v0", observation=observation)
    prepared = gym.make("TfaldaTrack-v0", observation=observation)
    env = prepared.unwrapped
    for e in (plain, prepared):
        e.reset(seed=11)
    asked = []

    def stop() -> bool:
        asked.append(True)
        return True

    assert env.prepare_reset(stop) and len(asked) == 1
    assert env._prepared is not None and env._prepared_scene is None
    assert env.prepare_reset(stop) and len(asked) == 2
    scene = env._prepared_scene[1]
    assert scene.tiles.n_filled == 0
    assert env.prepare_reset(stop) and len(asked) == 2  # the last stage: nothing to ask
    painted = scene.tiles.n_filled
    assert painted > 0
    assert not env.prepare_reset(stop)
    want, got = plain.reset(), prepared.reset()
    assert env._scene is scene and scene.tiles.n_filled == painted  # all painted ahead
    assert np.array_equal(want[0], got[0]) and want[1] == got[1]
    for _ in range(10):
        a = np.array([0.3], np.float32)
        pairs = zip(plain.step(a), prepared.step(a), strict=True)
        assert all(np.array_equal(x, y) for x, y in pairs)


@pytest.mark.parametrize("point", ["corners", "add"])
def test_a_reset_interrupted_while_the_world_changes_track_leaves_the_env_right(
        monkeypatch, point: str) -> None:
    """A Ctrl-C while the env's world moves to a new track (``World.set_track``: as it
    makes the cartons, or as it adds them after taking the old ones out): the next
    reset, even onto the track before, puts the world on its track with exactly its
    cartons; episodes match a fresh env's."""
    import tfalda_sim.world as world_module
    from tfalda_sim.tracks.rules import obstacle_corners

    env = TfaldaTrackEnv(obstacles=True)
    env.reset(seed=0, options={"track": 3})
    owner = world_module if point == "corners" else world_module.pymunk.Space
    name = "obstacle_corners" if point == "corners" else "add"
    real = getattr(owner, name)
    calls: list[int] = []

    def interrupted(*args: Any) -> Any:
        calls.append(1)
        if len(calls) == 2 or point == "add":
            raise KeyboardInterrupt
        return real(*args)

    monkeypatch.setattr(owner, name, interrupted)
    with pytest.raises(KeyboardInterrupt):
        env.reset(seed=1, options={"track": 9})
    monkeypatch.undo()
    fresh = TfaldaTrackEnv(obstacles=True)
    for seed, spec in ((2, 3), (3, 9)):
        obs, _ = env.reset(seed=seed, options={"track": spec})
        want, _ = fresh.reset(seed=seed, options={"track": spec})
        world = env.unwrapped._world
        assert world.track == fresh.unwrapped._world.track
        cartons = [s for s in world.space.shapes if s is not world.shape]
        assert len(cartons) == len(world.track.obstacles) > 0
        for k, shape in enumerate(world.obstacle_shapes):
            assert shape in cartons
            got = sorted(tuple(v) for v in shape.get_vertices())  # pymunk's own order
            want_corners = sorted(map(tuple, obstacle_corners(world.track, k)))
            np.testing.assert_allclose(got, want_corners)
        np.testing.assert_array_equal(obs, want)
        for _ in range(40):
            a = env.step(np.array([0.4], np.float32))
            b = fresh.step(np.array([0.4], np.float32))
            np.testing.assert_array_equal(a[0], b[0])
            assert a[1:4] == b[1:4]
            if a[2] or a[3]:
                break


def test_a_reset_takes_the_envs_car_as_it_is_now() -> None:
    """The env keeps its world (and pymunk space) across resets, but not its car: a car
    changed between episodes drives the next one."""
    from dataclasses import replace

    env = TfaldaTrackEnv(track="oval")
    env.reset(seed=0)
    world = env._world
    env.reset(seed=1)
    assert env._world is world  # kept
    env.car = replace(env.car, max_steer_rad=0.5 * env.car.max_steer_rad)
    env.reset(seed=2)
    assert env._world is not world and env._world.car is env.car


def test_a_generated_track_given_as_a_track_is_labelled_by_its_seed() -> None:
    """drive passes the Track itself: its label (info, the video overlay) is seed-N, the
    one spelling every output uses."""
    from tfalda_sim.tracks import generate

    env = TfaldaTrackEnv(track=generate(7))
    _, info = env.reset(seed=0)
    assert info["track"] == "seed-7"


def test_the_last_frame_car_pose_and_top_view_are_what_the_step_saw() -> None:
    """What recordings read: the observed frame's lanes are what a detector makes of the
    camera frames in order, its step lags with a late pipeline, the pose is the car's,
    the map shows it."""
    from tfalda_sim.perception import TfaldaDetector

    env = TfaldaTrackEnv(track="oval")
    with pytest.raises(RuntimeError, match="reset"):
        _ = env.last_frame
    env.reset(seed=0)
    again = TfaldaDetector(env.detector_config)
    again.process(env.camera_frame())
    for _ in range(3):
        env.step(np.zeros(1, np.float32))
        obs = again.process(env.camera_frame())
    frame = env.last_frame
    assert frame.step == 3
    np.testing.assert_array_equal(frame.lanes.lanes, obs.lanes)
    x, y, yaw = env.car_pose
    assert (x, y, yaw) == env._world.pose and np.isfinite([x, y, yaw]).all()
    view = env.top_view()
    assert view.ndim == 3 and view.shape[2] == 3 and view.dtype == np.uint8
    env.step(np.zeros(1, np.float32))
    assert not np.array_equal(view, env.top_view())  # the car moved on the map
    late = TfaldaTrackEnv(track="oval", timing="real-car")
    late.reset(seed=0)
    for _ in range(6):
        late.step(np.zeros(1, np.float32))
    assert late.last_frame.step < 6  # the newest result arrived is an older frame's
