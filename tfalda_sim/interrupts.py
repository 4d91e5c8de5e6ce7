"""Stopping a long command: Ctrl-C, SIGTERM and SIGHUP take the same clean path.

Inside ``stop_signals_interrupt()`` SIGTERM (``timeout``, a CI cancel, ``kill``) and SIGHUP
(a closed terminal) raise ``KeyboardInterrupt`` as Ctrl-C does, so the commands' one
interrupt path — keep what was finished, say what, exit ``128 + signal`` — serves all
three. ``ignoring_stops()`` shields the few seconds in which a command saves what it
finished: a second Ctrl-C there would otherwise throw away the first one's results.
``deferring_stops()`` holds a stop back while one finished result goes to its outputs;
``holding_stops()`` while a finished command saves its results (the command then says so
and exits 130, ``held_stop()``).
A stop whose handler ran inside a finalizer (where CPython drops exceptions) is raised
again a moment later, so no Ctrl-C is lost.
"""

from __future__ import annotations

import _thread
import contextlib
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from types import FrameType
from typing import Any

STOP_SIGNALS: tuple[signal.Signals, ...] = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
"""The signals that stop a command cleanly."""

_last_signal: int = signal.SIGINT

_held: list[int] = []
"""Stops that came inside ``holding_stops()`` since ``stop_signals_interrupt()`` began."""


def _raise_interrupt(signum: int, frame: FrameType | None) -> None:
    global _last_signal
    _last_signal = signum
    raise KeyboardInterrupt(signal.Signals(signum).name)


def _note_sigint(signum: int, frame: FrameType | None) -> None:
    global _last_signal
    _last_signal = signum
    signal.default_int_handler(signum, frame)


_Handler = Callable[[int, FrameType | None], Any] | int | None
"""What ``signal.getsignal`` returns."""


@contextlib.contextmanager
def _handling(choose: Callable[[dict[signal.Signals, _Handler]],
                               dict[signal.Signals, _Handler]]
              ) -> Iterator[dict[signal.Signals, _Handler] | None]:
    """Install ``choose(saved)``'s handlers for the stop signals inside the block (given
    the ones in force, ``saved``, which the block gets), then restore them. Signals can be
    handled in the main thread only: elsewhere nothing is installed and the block gets
    None."""
    if threading.current_thread() is not threading.main_thread():
        yield None
        return
    saved = {sig: signal.getsignal(sig) for sig in STOP_SIGNALS}
    for sig, handler in choose(saved).items():
        signal.signal(sig, handler)
    try:
        yield saved
    finally:
        for sig, handler in saved.items():
            signal.signal(sig, handler)


@contextlib.contextmanager
def stop_signals_interrupt() -> Iterator[None]:
    """Inside the block SIGTERM and SIGHUP raise KeyboardInterrupt (main thread only; a
    signal ignored by whoever started us stays ignored, as Ctrl-C does under ``nohup``);
    the handlers are restored after it."""
    global _last_signal
    _last_signal = signal.SIGINT
    _held.clear()

    def choose(saved: dict[signal.Signals, _Handler]) -> dict[signal.Signals, _Handler]:
        chosen: dict[signal.Signals, _Handler] = {}
        if saved[signal.SIGINT] is signal.default_int_handler:
            chosen[signal.SIGINT] = _note_sigint
        for sig in (signal.SIGTERM, signal.SIGHUP):
            if saved[sig] is not signal.SIG_IGN:
                chosen[sig] = _raise_interrupt
        return chosen

    with _handling(choose) as saved:
        if saved is None:  # not the main thread: no signals here
            yield
            return
        previous = sys.unraisablehook
        active = threading.Event()
        active.set()
        sys.unraisablehook = _redeliver(previous, active)
        try:
            yield
        finally:
            active.clear()  # a stop delivered again after the block would hit its caller
            sys.unraisablehook = previous


def _redeliver(previous: Callable[[Any], object], active: threading.Event
               ) -> Callable[[Any], object]:
    """An ``unraisablehook`` that delivers a stop again when CPython dropped it: a signal
    handler runs at the next bytecode, which may be inside a finalizer (cffi's callback
    freeing a pymunk space, a ``__del__``), where a raised exception is only reported as
    unraisable and the Ctrl-C would be lost. Other unraisable errors go to ``previous``."""

    def hook(unraisable: Any) -> object:
        exc = unraisable.exc_value
        if exc is not None and is_interrupt(exc):
            # Raised again in the main flow: from a thread, a moment later (the handler
            # would run at this hook's next bytecode, and be dropped again).
            threading.Thread(target=_interrupt_main_soon, args=(_last_signal, active),
                             daemon=True).start()
            return None
        return previous(unraisable)

    return hook


REDELIVER_DELAY_S: float = 0.002
"""How long a dropped stop waits before it is raised again [s]: long enough for the main
thread to leave the finalizer and the hook that reported it."""


def _interrupt_main_soon(signum: int, active: threading.Event) -> None:
    time.sleep(REDELIVER_DELAY_S)
    if active.is_set():  # still inside ``stop_signals_interrupt()``
        _thread.interrupt_main(signum)


def last_stop_signal() -> int:
    """The signal of the last interrupt (SIGINT if none was seen)."""
    return _last_signal


@contextlib.contextmanager
def ignoring_stops() -> Iterator[None]:
    """Ignore the stop signals inside the block (saving what was finished), then restore
    the handlers; a no-op outside the main thread."""
    with _handling(lambda saved: dict.fromkeys(saved, signal.SIG_IGN)):
        yield


@contextlib.contextmanager
def holding_stops() -> Iterator[None]:
    """Hold the stop signals back inside the block (saving what was finished) and do not
    act on them after it, but note them (``held_stop``): a first Ctrl-C that lands while
    a finished command saves its results then ends it with exit 130 and a line saying
    all was kept (``tfalda_sim.cli``), instead of being swallowed; a second one, after a
    first that cut the work, changes nothing. Unlike ``ignoring_stops`` the disposition
    is a handler, which a child process started inside the block does not inherit. A
    no-op outside the main thread."""

    def hold(signum: int, frame: FrameType | None) -> None:
        global _last_signal
        if not _held:
            _last_signal = signum
        _held.append(signum)

    with _handling(lambda saved: {sig: hold for sig, handler in saved.items()
                                  if handler is not signal.SIG_IGN}):
        yield


def held_stop() -> int | None:
    """The first stop signal ``holding_stops()`` held back since
    ``stop_signals_interrupt()`` began, or None."""
    return _held[0] if _held else None


@contextlib.contextmanager
def deferring_stops() -> Iterator[None]:
    """Hold back the stop signals inside the block, then act on the first one that came
    (the handler in force before the block: a Ctrl-C raises KeyboardInterrupt after it):
    for the few milliseconds in which one finished result goes to all of its outputs, so
    that a Ctrl-C keeps it whole or not at all, and is never lost. A no-op outside the
    main thread."""
    held: list[int] = []

    def hold(signum: int, frame: FrameType | None) -> None:
        held.append(signum)

    with _handling(lambda saved: {sig: hold for sig, handler in saved.items()
                                  if handler is not signal.SIG_IGN}) as saved:
        yield
    if held and saved is not None:
        handler = saved[signal.Signals(held[0])]
        if callable(handler):
            handler(held[0], None)
        elif handler == signal.SIG_DFL:
            signal.raise_signal(held[0])


INTERRUPTS = (KeyboardInterrupt, SystemError)
"""What to catch for a Ctrl-C: numba's dispatcher reports a KeyboardInterrupt raised as
a compiled kernel returns as a SystemError ("returned a result with an exception set")
whose context is the interrupt. Catch these, then ask ``is_interrupt``."""


def is_interrupt(exc: BaseException) -> bool:
    """``exc`` is a Ctrl-C (or SIGTERM, SIGHUP): a KeyboardInterrupt, or a SystemError
    caused by one."""
    seen: BaseException | None = exc
    for _ in range(8):  # a short chain; never loop on a cyclic one
        if seen is None:
            return False
        if isinstance(seen, KeyboardInterrupt):
            return True
        if not isinstance(seen, SystemError):
            return False
        seen = seen.__cause__ or seen.__context__
    return False
