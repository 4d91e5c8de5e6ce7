"""Stop signals: a Ctrl-C wrapped by numba is still a Ctrl-C; SIGTERM raises it too;
saving is shielded from a second one."""

from __future__ import annotations

import os
import signal

import pytest

from tfalda_sim.cli_common import consume
from tfalda_sim.interrupts import (
    ignoring_stops,
    is_interrupt,
    last_stop_signal,
    stop_signals_interrupt,
)


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


def _spin() -> None:
    """Run bytecode, so that a pending signal handler runs."""
    for _ in range(10**5):
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
