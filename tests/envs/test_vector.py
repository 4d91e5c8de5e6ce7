"""``gymnasium.make_vec("TfaldaTrack-v0")``: the worker-process vector env equals
Gymnasium's SyncVectorEnv bit for bit, and fails cleanly."""

from __future__ import annotations

import os
import signal
import threading
import time
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import tfalda_sim  # noqa: F401
from tfalda_sim.envs.vector import TfaldaTrackVectorEnv

STEPS = 120


def rollout(venv: gym.vector.VectorEnv, seed: int, steps: int = STEPS) -> list[Any]:
    """Observations, rewards, flags and infos of a random-action rollout (copied)."""
    obs, info = venv.reset(seed=seed)
    rng = np.random.default_rng(seed)
    out: list[Any] = [obs, info]
    shape = venv.action_space.shape
    for _ in range(steps):
        # Hard steering: episodes end (off the road), so autoresets happen.
        action = rng.uniform(-0.2, 1.0, shape).astype(np.float32)
        out.append(venv.step(action))
    venv.close()
    return out


def assert_same(a: Any, b: Any) -> None:
    if isinstance(a, dict):
        assert a.keys() == b.keys()
        for key in a:
            assert_same(a[key], b[key])
    elif isinstance(a, np.ndarray) and a.dtype == object:  # final_obs
        assert isinstance(b, np.ndarray) and b.dtype == object and a.shape == b.shape
        for x, y in zip(a, b, strict=True):
            assert (x is None and y is None) or assert_same(x, y) is None
    elif isinstance(a, tuple | list):
        assert len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            assert_same(x, y)
    else:
        a, b = np.asarray(a), np.asarray(b)
        assert a.dtype == b.dtype and a.shape == b.shape
        assert np.array_equal(a, b)


def test_make_vec_defaults_to_the_worker_vector_env() -> None:
    venv = gym.make_vec("TfaldaTrack-v0", num_envs=2)
    try:
        assert isinstance(venv.unwrapped, TfaldaTrackVectorEnv)
        assert venv.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
        assert venv.observation_space.shape == (2, 42)
        assert venv.action_space.shape == (2, 1)
    finally:
        venv.close()


@pytest.mark.parametrize(("num_envs", "workers", "kwargs"), [
    (2, None, {}),                                  # this process + one worker (2 CPUs)
    (3, 2, {"track": "oval", "max_laps": 1}),       # uneven slices: 2 + 1 envs
    (5, 3, {"max_laps": 1}),                        # 2 + 1 + 2 envs, two workers
    (2, 1, {}),                                     # all in this process
    (2, 2, {"observation": "dict", "obstacles": True}),  # images through shared memory
    (2, None, {"autoreset_mode": AutoresetMode.SAME_STEP}),  # final_obs, final_info
    (3, 2, {"autoreset_mode": "SameStep", "max_laps": 1}),
])
def test_rollouts_equal_sync_vector_env(num_envs: int, workers: int | None,
                                        kwargs: dict[str, Any]) -> None:
    ours = rollout(TfaldaTrackVectorEnv(num_envs, workers=workers, **kwargs), seed=5)
    kwargs = dict(kwargs)
    mode = kwargs.pop("autoreset_mode", AutoresetMode.NEXT_STEP)
    sync = rollout(gym.make_vec("TfaldaTrack-v0", num_envs=num_envs,
                                vectorization_mode="sync",
                                vector_kwargs={"autoreset_mode": mode}, **kwargs), seed=5)
    assert_same(ours, sync)
    # The rollout did reset some env on its own (else autoreset went untested).
    assert any(np.any(step[2] | step[3]) for step in ours[2:])


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_step_per_env_gives_the_infos_step_merges(mode: AutoresetMode) -> None:
    """``step_per_env`` is ``step`` with each env's own info dict: the same observations,
    rewards and flags, and infos that ``step``'s merged columns hold, final ones of
    ended episodes (SAME_STEP) included, from this process's env and the worker's."""
    from tfalda_sim.envs.vector import _merge_infos

    merged = rollout(TfaldaTrackVectorEnv(2, autoreset_mode=mode), seed=3, steps=80)
    venv = TfaldaTrackVectorEnv(2, autoreset_mode=mode)
    obs, info = venv.reset(seed=3)
    per_env: list[Any] = [obs, info]
    rng = np.random.default_rng(3)
    for _ in range(80):
        action = rng.uniform(-0.2, 1.0, venv.action_space.shape).astype(np.float32)
        per_env.append(venv.step_per_env(action))
    venv.close()
    ended = 0
    for got, want in zip(per_env[2:], merged[2:], strict=True):
        assert_same(got[:4], want[:4])
        infos = got[4]
        assert isinstance(infos, list) and len(infos) == 2
        assert all(type(v) in (float, int, bool, str, dict, np.ndarray)
                   for info in infos for v in info.values())
        assert_same(_merge_infos(infos), want[4])
        ended += sum("final_info" in info for info in infos)
    assert (ended > 0) == (mode is AutoresetMode.SAME_STEP)

@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_step_merges_this_process_infos_while_the_worker_steps(
        mode: AutoresetMode, monkeypatch: pytest.MonkeyPatch) -> None:
    """``step`` merges the infos ahead (``_MergeAhead``: this process's env's while the
    worker steps) whenever every env's info has the same layout, and falls back to
    ``_merge_infos`` only for the steps where it does not (SAME_STEP: an ended episode's
    info carries ``final_obs`` and ``final_info``); the rollouts equal SyncVectorEnv's
    either way (``test_rollouts_equal_sync_vector_env``)."""
    import tfalda_sim.envs.vector as vector

    fallbacks: list[list[dict[str, Any]]] = []
    merge = vector._merge_infos

    def counted(infos: list[dict[str, Any]]) -> dict[str, Any]:
        fallbacks.append(infos)
        return merge(infos)

    monkeypatch.setattr(vector, "_merge_infos", counted)
    venv = TfaldaTrackVectorEnv(2, workers=2, autoreset_mode=mode)
    venv.reset(seed=3)
    rng = np.random.default_rng(3)
    fell_back, ended = [], []  # the steps merged after the fact; those an episode ended in
    for k in range(80):
        calls = len(fallbacks)
        action = rng.uniform(-0.2, 1.0, venv.action_space.shape).astype(np.float32)
        _, _, terminated, truncated, info = venv.step(action)
        assert set(info) >= {"cross_track_m", "_cross_track_m", "track", "_track"}
        if len(fallbacks) > calls:
            fell_back.append(k)
        if np.any(terminated | truncated):
            ended.append(k)
    venv.close()
    assert ended
    # NEXT_STEP: a reset's info has a step's layout; SAME_STEP: exactly the steps whose
    # ended episode put final_obs and final_info into its env's info.
    assert fell_back == ([] if mode is AutoresetMode.NEXT_STEP else ended)


def test_same_seed_same_rollout_and_another_seed_differs() -> None:
    a = rollout(gym.make_vec("TfaldaTrack-v0", num_envs=2), seed=11, steps=30)
    b = rollout(gym.make_vec("TfaldaTrack-v0", num_envs=2), seed=11, steps=30)
    c = rollout(gym.make_vec("TfaldaTrack-v0", num_envs=2), seed=12, steps=30)
    assert_same(a, b)
    assert not np.array_equal(a[0], c[0])


def test_returned_observations_are_copies() -> None:
    venv = gym.make_vec("TfaldaTrack-v0", num_envs=2, track="oval")
    try:
        first, _ = venv.reset(seed=0)
        kept = first.copy()
        venv.step(np.zeros((2, 1), np.float32))
        assert np.array_equal(first, kept)
    finally:
        venv.close()


def test_a_bad_action_raises_the_envs_error_and_the_env_goes_on() -> None:
    venv = gym.make_vec("TfaldaTrack-v0", num_envs=2, track="oval")
    try:
        venv.reset(seed=0)
        with pytest.raises(ValueError, match="finite"):
            venv.step(np.array([[0.0], [np.nan]], np.float32))  # env 1: in the worker
        with pytest.raises(ValueError, match="finite"):
            venv.step(np.array([[np.nan], [0.0]], np.float32))  # env 0: in this process
        with pytest.raises(ValueError, match="one action per env"):
            venv.step(np.zeros((3, 1), np.float32))
        obs, *_ = venv.step(np.zeros((2, 1), np.float32))  # the pipes stayed in step
        assert obs.shape == (2, 42)
    finally:
        venv.close()


def test_bad_arguments_fail_before_any_worker_starts() -> None:
    with pytest.raises(ValueError, match="unknown track"):
        gym.make_vec("TfaldaTrack-v0", num_envs=2, track="nowhere")
    with pytest.raises(ValueError, match="num_envs"):
        TfaldaTrackVectorEnv(0)
    with pytest.raises(ValueError, match="workers"):
        TfaldaTrackVectorEnv(2, workers=0)
    with pytest.raises(ValueError, match="autoreset_mode must be"):
        TfaldaTrackVectorEnv(2, autoreset_mode="Disabled")
    with pytest.raises(ValueError, match="autoreset_mode must be"):
        TfaldaTrackVectorEnv(2, autoreset_mode="whenever")
    venv = TfaldaTrackVectorEnv(2)
    try:
        with pytest.raises(ValueError, match="one seed per env"):
            venv.reset(seed=[1, 2, 3])
    finally:
        venv.close()


def test_call_and_close() -> None:
    venv = TfaldaTrackVectorEnv(2, workers=2, track="oval")
    venv.reset(seed=0)
    assert venv.get_attr("observation_mode")[0].value == "lanes"
    frames = venv.call("camera_frame")
    assert len(frames) == 2 and frames[0].shape == (480, 752)
    procs = [w.process for w in venv._workers]
    assert len(procs) == 1  # env 0 in this process, env 1 in the worker
    venv.close()
    assert all(not p.is_alive() for p in procs)
    with pytest.raises(RuntimeError, match="closed"):
        venv.step(np.zeros((2, 1), np.float32))
    venv.close()  # twice is fine


def test_merged_infos_match_gymnasiums_layout_also_nested_and_missing_keys() -> None:
    from tfalda_sim.envs.vector import _merge_infos

    cases = [
        [{"a": 1.0, "b": {"c": 2, "d": "x"}, "e": np.zeros(3, np.float32)},
         {"a": 3.0, "b": {"c": 4}}],
        # plain scalars of one type per key (an env step's info): the fast path
        [{"x": 0.5, "n": 2, "ok": True, "y": -1.5}, {"x": 1.5, "n": -3, "ok": False, "y": 2.0},
         {"x": 2.5, "n": 7, "ok": True, "y": 0.0}],
        [{"x": 0.5, "track": "oval"}, {"x": 1.5, "track": "thesis"}],  # a named track
        [{"x": 0.5, "n": 2}, {"x": 1, "n": 3}],  # a key's type differs between envs
        [{"x": 0.5, "n": 2}, {"n": 3, "x": 1.5}],  # the keys in another order
    ]
    for infos in cases:
        sync = gym.vector.SyncVectorEnv([lambda: gym.make("CartPole-v1")] * len(infos))
        want: dict[str, Any] = {}
        for i, info in enumerate(infos):
            want = sync._add_info(want, info, i)
        sync.close()
        got = _merge_infos(infos)
        assert list(got) == list(want)
        assert_same(got, want)
    got = _merge_infos(cases[1])
    got["x"][0] = 9.0  # each key's array is its own
    assert got["y"][0] == -1.5 and got["n"].dtype == np.int64 and got["ok"].dtype == np.bool_


def test_a_dead_worker_is_a_clear_error() -> None:
    venv = TfaldaTrackVectorEnv(2, workers=2, track="oval")
    procs = [w.process for w in venv._workers]
    try:
        venv.reset(seed=0)
        venv._workers[0].process.kill()
        venv._workers[0].process.join()
        with pytest.raises(RuntimeError, match="died"):
            venv.step(np.zeros((2, 1), np.float32))
            venv.step(np.zeros((2, 1), np.float32))
    finally:
        venv.close()
    assert all(not p.is_alive() for p in procs)


def test_set_attr_reaches_the_env_under_the_wrappers_as_sync_vector_envs_does() -> None:
    venv = TfaldaTrackVectorEnv(2, workers=2, track="oval")
    sync = gym.make_vec("TfaldaTrack-v0", num_envs=2, vectorization_mode="sync",
                        track="oval")
    try:
        for v in (venv, sync):
            v.set_attr("speed_m_s", [1.0, 2.0])
        venv.set_attr("speed_m_s", 1.25, indices=[1])
        sync.unwrapped.envs[1].set_wrapper_attr("speed_m_s", 1.25)
        ours = [env.speed_m_s for env in venv.get_attr_on([0, 1], "unwrapped")]
        theirs = [env.unwrapped.speed_m_s for env in sync.unwrapped.envs]
        assert ours == theirs == [1.0, 1.25]
        assert venv.get_attr("speed_m_s") == (1.0, 1.25)
        with pytest.raises(ValueError, match="indices must lie"):
            venv.set_attr("speed_m_s", 1.0, indices=[2])
    finally:
        venv.close()
        sync.close()


def test_a_ctrl_c_in_this_processs_env_keeps_the_pipes_in_step() -> None:
    """A KeyboardInterrupt in the env this process steps: the worker's answer is read
    before it is raised, so the next call gets its own answers (not the step's)."""
    venv = TfaldaTrackVectorEnv(2, workers=2, track="oval")
    try:
        venv.reset(seed=0)
        env0 = venv._local[0]
        real = env0.step

        def interrupted(action: Any) -> Any:
            env0.step = real
            raise KeyboardInterrupt

        env0.step = interrupted
        with pytest.raises(KeyboardInterrupt):
            venv.step(np.zeros((2, 1), np.float32))
        obs, info = venv.reset(seed=3)
        want, _ = gym.make_vec("TfaldaTrack-v0", num_envs=2, vectorization_mode="sync",
                               track="oval").reset(seed=3)
        assert np.array_equal(obs, want) and set(info) >= {"cross_track_m", "_cross_track_m"}
        obs, *_ = venv.step(np.zeros((2, 1), np.float32))
        assert obs.shape == (2, 42)
    finally:
        venv.close()


def test_steps_go_through_the_board_and_equal_the_pipes_and_sync() -> None:
    """On x86 the workers take steps from the shared board: only a worker's first step
    (its infos' layout is not known yet) comes through the pipe; with the board off (as
    on other machines), after a pause past the workers' spin, and with int actions (the
    pipe path), the rollouts equal SyncVectorEnv's."""
    from tfalda_sim.envs import vector

    def run(venv: gym.vector.VectorEnv, pause: bool = False) -> list[Any]:
        out: list[Any] = [venv.reset(seed=4)]
        rng = np.random.default_rng(4)
        for k in range(40):
            if pause and k in (5, 6):
                time.sleep(3 * vector.WAIT_SPIN_S)  # the workers nap between board looks
            action = rng.uniform(-0.2, 1.0, (3, 1)).astype(np.float32)
            out.append(venv.step(np.rint(action).astype(np.int64) if k == 7 else action))
        return out

    sync = gym.make_vec("TfaldaTrack-v0", num_envs=3, vectorization_mode="sync",
                        max_laps=1)
    want = run(sync)
    sync.close()
    ours = TfaldaTrackVectorEnv(3, workers=3, max_laps=1)
    try:
        got = run(ours, pause=True)
        if vector.FAST_STEPS:
            assert ours._board is not None
            assert ours._piped == 2  # each worker's first step, then the board
    finally:
        ours.close()
    assert_same(got, want)
    assert any(np.any(step[2] | step[3]) for step in got[1:])  # autoresets happened
    real = vector.FAST_STEPS
    vector.FAST_STEPS = False
    try:
        piped = TfaldaTrackVectorEnv(3, workers=3, max_laps=1)
        assert piped._board is None
        got = run(piped)
        piped.close()
    finally:
        vector.FAST_STEPS = real
    assert_same(got, want)


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_a_worker_prepares_its_next_reset_while_this_process_resets(
        mode: AutoresetMode) -> None:
    """Two envs, in both autoreset modes: while the env this process steps resets (made
    slow here), the worker generates its env's next track, builds its scene and paints
    its first frame (a later ``prepare_reset`` finds nothing to do), and the rollout
    equals ``SyncVectorEnv``'s. Both slots say on the board when they took a step."""
    venv = TfaldaTrackVectorEnv(2, workers=2, autoreset_mode=mode)
    sync = gym.make_vec("TfaldaTrack-v0", num_envs=2, vectorization_mode="sync",
                        vector_kwargs={"autoreset_mode": mode})
    try:
        assert_same(venv.reset(seed=5), sync.reset(seed=5))
        env0 = venv._local[0].unwrapped
        real = env0.reset

        def slow(**kw: Any) -> Any:
            time.sleep(1.0)  # the worker prepares in ≈ 3 ms, here and with far more load
            return real(**kw)

        env0.reset = slow
        action = np.array([[1.0], [0.0]], np.float32)  # env 0 leaves the road
        board = venv._board
        for _ in range(200):
            assert_same(venv.step(action), sync.step(action))
            # Both slots said they took the step, the worker also when its results went
            # through its pipe (SAME_STEP: a reset's final observation).
            assert board.ctrl[board.finished] == board.ctrl[board.finished + 1] == venv._seq
            if venv.call_on([0], "_step_count") == (0,):  # env 0 has reset
                break
        else:
            pytest.fail("env 0 never left the road")
        assert venv.call_on([1], "prepare_reset") == (False,)  # prepared already
        for _ in range(60):
            assert_same(venv.step(action[::-1]), sync.step(action[::-1]))
    finally:
        venv.close()
        sync.close()


def _abandon_next_wait(monkeypatch: pytest.MonkeyPatch) -> None:
    """The next wait for a worker's posted step raises KeyboardInterrupt (a Ctrl-C)."""
    from tfalda_sim.envs import vector
    real = vector.await_results

    def interrupted(*args: Any) -> Any:
        monkeypatch.setattr(vector, "await_results", real)
        raise KeyboardInterrupt

    monkeypatch.setattr(vector, "await_results", interrupted)


def _board_and_sync() -> tuple[TfaldaTrackVectorEnv, gym.vector.VectorEnv]:
    """Two envs on the oval: ours with a worker (skipped where there is no board) and
    SyncVectorEnv's, both reset with seed 2."""
    venv = TfaldaTrackVectorEnv(2, workers=2, track="oval")
    if venv._board is None:
        venv.close()
        pytest.skip("no step board on this machine (pipes only)")
    sync = gym.make_vec("TfaldaTrack-v0", num_envs=2, vectorization_mode="sync", track="oval")
    venv.reset(seed=2)
    sync.reset(seed=2)
    return venv, sync


def test_a_ctrl_c_while_waiting_for_a_worker_keeps_the_board_in_step(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A KeyboardInterrupt while this process waits for a worker's posted step: the
    worker's answer (here through the pipe, its first: it teaches the info layouts) is
    read before the next step's results are taken from the board, which equal
    SyncVectorEnv's."""
    venv, sync = _board_and_sync()
    try:
        first, second = np.full((2, 1), 0.3, np.float32), np.full((2, 1), -0.2, np.float32)
        _abandon_next_wait(monkeypatch)
        with pytest.raises(KeyboardInterrupt):
            venv.step(first)
        sync.step(first)
        env0 = venv._local[0]
        step0 = env0.step

        def slow(action: Any) -> Any:  # the worker's results are on the board by now
            env0.step = step0
            time.sleep(0.2)
            return step0(action)

        env0.step = slow
        assert_same(venv.step(second), sync.step(second))
        assert venv._piped == 1  # the first step's answer, read before the second's post
        for _ in range(3):
            assert_same(venv.step(first), sync.step(first))
    finally:
        venv.close()
        sync.close()



def test_after_a_step_given_up_on_commands_and_steps_stay_in_step(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Ctrl-C while waiting for a posted step (its answer through the pipe: the first
    one), then a reset that fails in this process (the worker's answer is drained) and
    a good reset: every answer is the right one's; and a step given up on before the
    worker took it (the worker stopped, as a loaded machine may) is not skipped."""
    venv, sync = _board_and_sync()
    try:
        action = np.full((2, 1), 0.3, np.float32)
        _abandon_next_wait(monkeypatch)
        with pytest.raises(KeyboardInterrupt):
            venv.step(action)
        with pytest.raises(ValueError, match="unknown reset option"):
            venv.reset(options={"bogus": 1})
        assert_same(venv.reset(seed=0), sync.reset(seed=0))
        for _ in range(3):
            assert_same(venv.step(action), sync.step(action))
        worker = venv._workers[0].process
        os.kill(worker.pid, signal.SIGSTOP)  # it cannot take the next steps yet
        wake = threading.Timer(0.3, os.kill, (worker.pid, signal.SIGCONT))
        try:
            _abandon_next_wait(monkeypatch)
            with pytest.raises(KeyboardInterrupt):
                venv.step(-action)
            sync.step(-action)
            wake.start()  # it wakes while the next step is posted (or waits to be)
            for _ in range(3):
                assert_same(venv.step(action), sync.step(action))
        finally:
            wake.cancel()
            os.kill(worker.pid, signal.SIGCONT)
        time.sleep(0.3)  # past the workers' spin: asleep on their pipes, woken by a step
        assert venv._board.ctrl[venv._board.asleep + 1] == 1
        assert_same(venv.step(action), sync.step(action))
    finally:
        venv.close()
        sync.close()
