"""Shared fixtures: generated tracks are cached for the whole test run (generation is
deterministic); stable-baselines3's log folders go to the run's temporary folder; Ctrl-C
raises KeyboardInterrupt in the test process however the run was started."""

from __future__ import annotations

import functools
import signal
from collections.abc import Iterator

import pytest

from tfalda_sim.tracks import Track, generate


@functools.cache
def generated(seed: int) -> Track:
    return generate(seed)


@pytest.fixture(scope="session")
def eight() -> Track:
    """A generated figure-eight (first seed that yields an intersection)."""
    for seed in range(100):
        if generated(seed).intersections:
            return generated(seed)
    raise AssertionError("no figure-eight among the first 100 seeds")


@pytest.fixture(autouse=True, scope="session")
def ctrl_c_raises() -> Iterator[None]:
    """The Ctrl-C tests send SIGINT to this process and expect KeyboardInterrupt. A shell
    starts a background job (``make test &``, a CI runner's) with SIGINT ignored, and
    Python then installs no handler of its own: put Python's in for the run."""
    before = signal.getsignal(signal.SIGINT)
    if before == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    if before == signal.SIG_IGN:
        signal.signal(signal.SIGINT, before)


@pytest.fixture(autouse=True, scope="session")
def sb3_log_folder(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """SB3's logger makes a folder for a model that learns without a log folder (several
    tests train such models): $SB3_LOGDIR, else a new tempdir/SB3-<time> each time, left
    behind empty. Here it is one folder under pytest's temporary folders, which pytest
    prunes (the console scripts the tests run inherit it)."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("SB3_LOGDIR", str(tmp_path_factory.mktemp("sb3-logs")))
        yield
