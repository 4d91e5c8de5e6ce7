"""Shared fixtures: generated tracks are cached for the whole test run (generation is
deterministic)."""

from __future__ import annotations

import functools

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
