"""The vector env's multiprocess runtime (``tfalda_sim.envs.workers``): the step board,
a slot's spare time, the waits; workers that start from any kind of script and that,
when they die, say why."""

from __future__ import annotations

import math
import subprocess
import sys
import textwrap
from typing import Any

import numpy as np
import pytest

import tfalda_sim  # noqa: F401
from tfalda_sim.envs.vector import TfaldaTrackVectorEnv

# A user's script with no ``if __name__ == "__main__":`` guard: a 2-env vector env with a
# worker process, stepped; what it prints is checked.
SCRIPT = textwrap.dedent("""\
    import gymnasium as gym
    import numpy as np
    import tfalda_sim
    print("main module ran", flush=True)
    venv = gym.make_vec("TfaldaTrack-v0", num_envs=2, workers=2, track="oval")
    obs, info = venv.reset(seed=0)
    result = venv.step(np.zeros((2, 1), np.float32))
    print("stepped", obs.shape, result[1].shape, len(venv._workers), flush=True)
    venv.close()
    """)


def _run(args: list[str], stdin: str | None = None, cwd: Any = None) -> str:
    done = subprocess.run([sys.executable, *args], input=stdin, capture_output=True,
                          text=True, timeout=300, cwd=cwd)
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout


def _assert_stepped_once(out: str) -> None:
    # The main module ran once: a worker that re-ran it would print again (or die).
    assert out.count("main module ran") == 1, out
    assert "stepped (2, 42) (2,) 1" in out, out


def test_a_script_without_a_main_guard_steps_a_vector_env(tmp_path: Any) -> None:
    script = tmp_path / "user_script.py"
    script.write_text(SCRIPT)
    _assert_stepped_once(_run([str(script)], cwd=tmp_path))


def test_python_dash_c_steps_a_vector_env() -> None:
    _assert_stepped_once(_run(["-c", SCRIPT]))


def test_a_script_read_from_standard_input_steps_a_vector_env(tmp_path: Any) -> None:
    _assert_stepped_once(_run(["-"], stdin=SCRIPT, cwd=tmp_path))


def test_a_module_run_with_dash_m_steps_a_vector_env(tmp_path: Any) -> None:
    (tmp_path / "user_module.py").write_text(SCRIPT)
    _assert_stepped_once(_run(["-m", "user_module"], cwd=tmp_path))


def test_an_interactive_session_steps_a_vector_env() -> None:
    """``python -i`` reading its input (a ``__main__`` without ``__file__``), one
    statement per line as typed at the prompt."""
    _assert_stepped_once(_run(["-i", "-q"], stdin=SCRIPT + "\nexit()\n"))


def test_a_notebook_kernels_main_module_steps_a_vector_env() -> None:
    """A kernel (IPython's) runs cells in a ``__main__`` module of its own making, with
    no ``__file__`` and a ``__spec__`` of None: the same here."""
    kernel = textwrap.dedent(f"""\
        import sys, types
        main = types.ModuleType("__main__")
        sys.modules["__main__"] = main
        exec(compile({SCRIPT!r}, "<cell>", "exec"), main.__dict__)
        """)
    _assert_stepped_once(_run(["-c", kernel]))


def test_an_argument_only_the_users_script_defines_is_a_clear_error() -> None:
    """What a worker needs must reach it without running the user's script: a class of
    the script is refused before any step, naming the fix."""
    script = textwrap.dedent("""\
        import dataclasses
        import tfalda_sim
        from tfalda_sim.envs import RewardWeights
        from tfalda_sim.envs.vector import TfaldaTrackVectorEnv

        @dataclasses.dataclass(frozen=True)
        class MyWeights(RewardWeights):
            pass

        try:
            TfaldaTrackVectorEnv(2, workers=2, track="oval", reward=MyWeights())
        except ValueError as exc:
            print("refused:", exc)
        """)
    out = _run(["-c", script])
    assert "refused: the vector env's arguments cannot reach its worker processes" in out
    assert "workers=1" in out and "MyWeights" in out


class _DiesSaying:
    """Unpickled in a worker (a ``set_attr`` value), it writes a line to the worker's
    standard error and ends the process with exit code 3."""

    def __reduce__(self) -> tuple[Any, tuple[str]]:
        return exec, ("import os, sys; sys.stderr.write('the last words\\n'); "
                      "sys.stderr.flush(); os._exit(3)",)


def test_a_dead_worker_is_named_with_its_exit_code_and_last_stderr_line(
        capfd: pytest.CaptureFixture[str]) -> None:
    venv = TfaldaTrackVectorEnv(2, workers=2, track="oval")
    try:
        venv.reset(seed=0)
        with pytest.raises(RuntimeError, match=r"worker 1 of the vector env died \(exit code "
                           r"3; its last line on stderr: the last words\)"):
            venv.set_attr("anything", _DiesSaying(), indices=[1])
    finally:
        venv.close()
    assert "the last words" in capfd.readouterr().err  # forwarded as it was written


def test_a_worker_killed_by_a_signal_is_named_with_the_signal() -> None:
    venv = TfaldaTrackVectorEnv(2, workers=2, track="oval")
    try:
        venv.reset(seed=0)
        venv._workers[0].process.kill()
        venv._workers[0].process.join()
        with pytest.raises(RuntimeError, match=r"died \(killed by signal SIGKILL"):
            venv.step(np.zeros((2, 1), np.float32))
            venv.step(np.zeros((2, 1), np.float32))
    finally:
        venv.close()


def test_the_board_carries_infos_exactly_or_refuses_them() -> None:
    import multiprocessing

    from tfalda_sim.envs.workers import (
        BOARD_INFO_CELLS,
        Board,
        info_layout,
        post_results,
        read_results,
    )

    board = Board(multiprocessing.get_context("spawn"), 3, (1,), 2)
    infos = [{"x": 0.1, "n": 2**62, "ok": True, "track": "oval", "y": -0.0},
             {"x": math.nextafter(1.0, 2.0), "n": -5, "ok": False, "track": "oval",
              "y": math.nan, "z": math.inf}]
    answers = [(0.5, False, True, infos[0]), (-1.25, True, False, infos[1])]
    known: list[tuple | None] = [None, info_layout(infos[0]), info_layout(infos[1])]
    assert post_results(board, 1, answers, known[1:])
    got = read_results(board, 1, 3, known)
    for (reward, term, trunc, info), want in zip(got, answers, strict=True):
        assert (reward, term, trunc) == want[:3]
        assert repr(list(info.items())) == repr(list(want[3].items()))  # nan, -0.0 too
        assert [type(v) for v in info.values()] == [type(v) for v in want[3].values()]
    # Anything but the known layout is refused (the pipe carries it): another key order,
    # type or string, an int beyond int64, an array, too many numbers.
    for bad in ({"n": 2, "x": 0.1, "ok": True, "track": "oval", "y": 0.0},
                {"x": 1, "n": 2, "ok": True, "track": "oval", "y": 0.0},
                {"x": 0.1, "n": 2, "ok": True, "track": "thesis", "y": 0.0},
                {"x": 0.1, "n": 2**64, "ok": True, "track": "oval", "y": 0.0}):
        assert not post_results(board, 1, [(0.0, False, False, bad)], known[1:2])
    assert info_layout({"a": np.zeros(2)}) is None
    assert info_layout({f"k{i}": 1.0 for i in range(BOARD_INFO_CELLS + 1)}) is None
    assert info_layout({f"k{i}": 1.0 for i in range(BOARD_INFO_CELLS)}) is not None


class _Preparing:
    """An env's ``unwrapped`` as ``SpareTime`` sees it: records each ``prepare_reset(stop)``
    and what ``stop()`` said then; ``then`` runs after (a slot finishing meanwhile)."""

    def __init__(self, then: Any = None) -> None:
        self.calls: list[bool] = []
        self.then = then
        self.unwrapped = self

    def prepare_reset(self, stop: Any) -> bool:
        self.calls.append(stop())
        if self.then is not None:
            self.then()
        return True


def _board(slots: int) -> Any:
    import multiprocessing

    from tfalda_sim.envs.workers import Board
    return Board(multiprocessing.get_context("spawn"), 2 * slots, (1,), slots)


@pytest.mark.parametrize("slot", [0, 1, 2])
def test_a_lane_prepares_while_another_lane_resets_until_the_others_are_done(
        slot: int) -> None:
    """``SpareTime`` of a slot of three: nothing while no other slot resets in the step (its
    own reset does not count), then ``prepare_reset`` on its envs with a ``stop`` that
    says whether every other slot took the step (this process after its own envs, the
    workers when they hand their results over), at most once a step; ``mark`` flags the
    slot's reset in the step posted."""
    from tfalda_sim.envs.workers import SpareTime

    board = _board(3)
    ctrl = board.ctrl
    done = [board.finished + other for other in range(3)]
    others_done = done[:slot] + done[slot + 1:]

    def finish() -> None:  # the other slots take step ctrl[0], the first is on to the next
        for k, cell in enumerate(others_done):
            ctrl[cell] = ctrl[0] + (k == 0)

    first, second = _Preparing(then=finish), _Preparing()
    idle = SpareTime(board, slot, [first, second])
    seq = ctrl[0] = 7
    assert not idle(seq) and not first.calls  # nobody resets
    idle.mark()
    assert ctrl[board.resetting + slot] == seq
    assert not idle(seq) and not first.calls  # only this slot
    other = (slot + 1) % 3
    SpareTime(board, other, []).mark()
    assert idle(seq)
    # The others still stepped when it began, and were done after the first env.
    assert first.calls == [False] and second.calls == []
    assert not idle(seq) and len(first.calls) == 1  # once a step
    ctrl[0] = 8
    SpareTime(board, other, []).mark()  # the other slot resets in step 8 too
    assert idle(8) and first.calls == [False, False]
    assert not idle(9)  # flags of older steps count no more


def test_waits_prepare_resets_while_another_lane_resets() -> None:
    """This process waiting for a worker's results, and a worker waiting for the next
    step: each prepares its envs' next resets when another slot resets in the step (and
    goes on waiting), until the others are done."""
    from tfalda_sim.envs.workers import SpareTime, await_command, await_results

    class Quiet:  # a pipe with nothing on it (a wait that never ends fails instead)
        polls = 0

        def poll(self, timeout: float = 0.0) -> bool:
            self.polls += 1
            assert self.polls < 100_000, "waited on and on: nothing was prepared"
            return False

    board = _board(2)
    ctrl = board.ctrl
    seq = ctrl[0] = 3
    # This process waits for worker 1, which resets; the worker is done after one stage.
    parent_env = _Preparing(then=lambda: ctrl.__setitem__(2, seq))  # results on the board
    SpareTime(board, 1, []).mark()
    assert await_results(Quiet(), board, 1, seq, SpareTime(board, 0, [parent_env])) is None
    assert parent_env.calls == [False]
    # Worker 1 waits for step 4 while this process resets in step 3 and then posts.
    worker_env = _Preparing(then=lambda: ctrl.__setitem__(0, seq + 1))
    SpareTime(board, 0, []).mark()
    assert await_command(Quiet(), board, seq, 0.5, 1, SpareTime(board, 1, [worker_env])) == (
        "post", seq + 1)
    assert worker_env.calls == [False]

