"""Stop signals: a Ctrl-C wrapped by numba is still a Ctrl-C; SIGTERM raises it too;
saving is shielded from a second one."""

from __future__ import annotations

import os
import signal
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tfalda_sim.interrupts import (
    deferring_stops,
    ignoring_stops,
    is_interrupt,
    last_stop_signal,
    stop_signals_interrupt,
)
from tfalda_sim.sweep_runner import consume


@pytest.fixture(autouse=True)
def _ctrl_c_raises() -> Iterator[None]:
    """Python's own Ctrl-C handler during each test, whatever the shell left: a suite
    started in the background (``make test &``) inherits SIGINT ignored."""
    before = signal.getsignal(signal.SIGINT)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, before)


def _numba_style() -> SystemError:
    """What numba's dispatcher raises when a Ctrl-C lands as a kernel returns."""
    try:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt:
            raise SystemError("CPUDispatcher(...) returned a result with an exception set")  # noqa: B904 (numba sets only the context)
    except SystemError as exc:
        return exc


def test_a_wrapped_ctrl_c_is_an_interrupt_and_other_errors_are_not() -> None:
    assert is_interrupt(KeyboardInterrupt()) and is_interrupt(_numba_style())
    assert not is_interrupt(SystemError("a real one")) and not is_interrupt(ValueError())

    def handle(x: int) -> None:
        if x == 2:
            raise _numba_style()

    seen = []
    end = consume(iter(range(5)), lambda x: (handle(x), seen.append(x)))
    assert end.interrupted and seen == [0, 1]
    with pytest.raises(SystemError):
        consume(iter([1]), lambda x: (_ for _ in ()).throw(SystemError("a bug")))


def _spin(seconds: float = 0.05) -> None:
    """Run bytecode for a while, so that a pending signal handler runs (one delivered
    again from a thread, ``REDELIVER_DELAY_S`` later, included)."""
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        pass


def test_sigterm_raises_the_interrupt_inside_and_not_outside() -> None:
    before = signal.getsignal(signal.SIGTERM)
    with stop_signals_interrupt():
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGTERM)
            _spin()
        assert last_stop_signal() == signal.SIGTERM
        with ignoring_stops():
            os.kill(os.getpid(), signal.SIGTERM)  # ignored while saving
            _spin()
    assert signal.getsignal(signal.SIGTERM) == before  # restored after the command
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_deferred_stop_acts_after_the_block_and_is_not_lost() -> None:
    with stop_signals_interrupt():
        done = []
        with pytest.raises(KeyboardInterrupt):
            with deferring_stops():
                os.kill(os.getpid(), signal.SIGTERM)
                _spin()
                done.append("rest of the block")  # not cut short
        assert done == ["rest of the block"] and last_stop_signal() == signal.SIGTERM
        with deferring_stops():  # nothing came: nothing happens
            _spin()
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_ctrl_c_while_a_sweep_writes_a_result_keeps_that_result_whole(
        tmp_path: Path) -> None:
    """A Ctrl-C landing between two lines of one result's side output (a track's frames
    in ``evaluate --jsonl``) stops the sweep after that result, with all its lines and
    its journal record, not in the middle of them."""
    from tfalda_sim.parallel import Backend
    from tfalda_sim.sweep_runner import SweepSpec, run_sweep

    spec = SweepSpec(command="demo", config={"seeds": "0:5"}, jobs=range(5), total=5,
                     fn=abs, record=lambda j, r: {"x": j}, check=lambda j, r: None)
    frames = tmp_path / "frames.txt"
    journal = tmp_path / "r.jsonl"
    with stop_signals_interrupt(), open(frames, "w") as fh:
        def write_frames(job: int, result: int) -> None:
            fh.write(f"{job} a\n")
            if job == 1:
                os.kill(os.getpid(), signal.SIGINT)
                _spin()
            fh.write(f"{job} b\n")

        seen: list[dict[str, int]] = []
        end = run_sweep(spec, Backend("local", 1), seen.append, results=journal,
                        progress=False, on_result=write_frames)
    assert end.interrupted
    assert seen == [{"x": 0}, {"x": 1}]
    assert frames.read_text() == "0 a\n0 b\n1 a\n1 b\n"
    assert journal.read_text().splitlines()[1:] == ['{"x": 0}', '{"x": 1}']


class _StoppedInFinalizer:
    """Raises a Ctrl-C as it is freed (what a signal handler does when the next bytecode
    runs inside a finalizer, e.g. cffi's callback freeing a pymunk space)."""

    def __del__(self) -> None:
        raise KeyboardInterrupt


def test_a_ctrl_c_dropped_inside_a_finalizer_is_delivered_again() -> None:
    with stop_signals_interrupt():
        with pytest.raises(KeyboardInterrupt):
            doomed = _StoppedInFinalizer()
            del doomed  # CPython reports the exception as unraisable and goes on
            _spin()
        with pytest.raises(KeyboardInterrupt):  # SIGTERM's too, as SIGTERM
            os.kill(os.getpid(), signal.SIGTERM)
            _spin()
        assert last_stop_signal() == signal.SIGTERM
        with pytest.raises(KeyboardInterrupt):
            doomed = _StoppedInFinalizer()
            del doomed
            _spin()
        assert last_stop_signal() == signal.SIGTERM
    with stop_signals_interrupt():
        doomed = _StoppedInFinalizer()
        del doomed  # dropped as the block ends: not delivered to what follows it
    _spin()
    seen: list[object] = []
    previous = sys.unraisablehook
    sys.unraisablehook = seen.append
    try:
        doomed = _StoppedInFinalizer()
        del doomed  # outside the block: CPython's behaviour, nothing delivered
        _spin()
    finally:
        sys.unraisablehook = previous
    assert len(seen) == 1


def test_a_held_stop_is_noted_not_raised_and_a_command_then_exits_with_it(
        monkeypatch, capsys) -> None:
    """``holding_stops`` (a finished command saving its results) neither cuts the block
    nor raises after it, but notes the first stop; ``tfalda-sim`` then ends the command
    with that stop's exit code and a line saying all was kept (the CLI fuzz's Ctrl-C,
    landing there, had been swallowed: exit 0)."""
    import argparse

    from tfalda_sim import cli
    from tfalda_sim.interrupts import held_stop, holding_stops

    with stop_signals_interrupt():
        assert held_stop() is None
        done = []
        with holding_stops():
            os.kill(os.getpid(), signal.SIGTERM)
            _spin()
            os.kill(os.getpid(), signal.SIGINT)  # a second one: the first counts
            _spin()
            done.append("rest of the block")
        assert done == ["rest of the block"]
        assert held_stop() == signal.SIGTERM and last_stop_signal() == signal.SIGTERM
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler

    def finished_then_saved(args: argparse.Namespace) -> int:
        with holding_stops():
            os.kill(os.getpid(), signal.SIGINT)
            _spin()
        print("results")
        return 0

    def parser() -> argparse.ArgumentParser:
        p = argparse.ArgumentParser()
        p.set_defaults(func=finished_then_saved)
        return p

    monkeypatch.setattr(cli, "build_parser", parser)
    assert cli.main([]) == 130
    out, err = capsys.readouterr()
    assert out == "results\n" and "interrupted (Ctrl-C)" in err and "kept" in err
    p = argparse.ArgumentParser()
    p.set_defaults(func=lambda args: 0)
    monkeypatch.setattr(cli, "build_parser", lambda: p)
    assert cli.main([]) == 0  # a new command starts with nothing held
