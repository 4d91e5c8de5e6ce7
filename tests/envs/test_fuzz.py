"""Property tests: any reset options and any action either work or raise TypeError /
ValueError, never another exception. The envs are built once per module and
reused across examples, on the cheap "oval" track."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tfalda_sim.envs import TfaldaTrackEnv
from tfalda_sim.envs.tfalda_track import RESET_OPTIONS
from tfalda_sim.faults import (
    Blackout,
    CameraShake,
    FrameDropBurst,
    Glare,
    LatencySpike,
    LateralKick,
    MarkingGap,
    ServoOffset,
    WetPatch,
)

# derandomize: the same examples every run; no database: nothing written to the repo.
FUZZ = settings(max_examples=300, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow])


@pytest.fixture(scope="module")
def envs() -> dict[bool, TfaldaTrackEnv]:
    """Steering-only and throttle envs, by ``throttle``. One track seed: a ``track=None``
    option always draws the same generated track (built once, then cached)."""
    return {throttle: TfaldaTrackEnv(track="oval", track_seeds=(0, 1), throttle=throttle)
            for throttle in (False, True)}


# Beyond the float range (built by map: the strategies' reprs stay short).
BEYOND_FLOAT = st.sampled_from([1, -1]).map(lambda sign: sign * 10**400)
HUGE = st.one_of(BEYOND_FLOAT, st.sampled_from([2**70, 1e308]))

NUMPY_SCALARS = st.sampled_from([
    np.float32("nan"), np.float64(1.0), np.float64("-inf"), np.float16(0.5), np.int64(2),
    np.uint64(2**64 - 1), np.int8(-3), np.bool_(True), np.complex128(1j), np.str_("oval"),
    np.datetime64("2008"), np.timedelta64(1, "s")])

SCALARS = st.one_of(
    st.none(), st.booleans(),
    st.integers(-2**70, 2**70), st.sampled_from([0, 1, 3, -1]), HUGE,
    st.floats(allow_nan=True, allow_infinity=True),
    st.complex_numbers(max_magnitude=10), st.text(max_size=6), st.binary(max_size=3),
    st.sampled_from(["oval", "ovl", "thesis", "", "1.5", "nan", "True"]),
    st.just("x").map(lambda x: x * 500),
    NUMPY_SCALARS,
)

SHAPES = hnp.array_shapes(min_dims=0, max_dims=2, min_side=0, max_side=4)
DTYPES = st.sampled_from([np.float64, np.float32, np.float16, np.int64, np.uint8, np.bool_,
                          np.complex64, np.dtype("U2"), np.dtype("m8[s]")])
ARRAYS = st.one_of(hnp.arrays(DTYPES, SHAPES),
                   hnp.arrays(np.dtype(object), SHAPES, elements=SCALARS))

FAULTS = st.one_of(
    st.builds(Blackout, start_s=st.floats(0, 0.1), duration_s=st.floats(0.001, 0.06)),
    st.builds(LateralKick, start_s=st.floats(0, 0.1), offset_m=st.floats(-0.2, 0.2)),
    st.builds(CameraShake, start_s=st.floats(0, 0.1), duration_s=st.floats(0.001, 0.06)),
    st.builds(Glare, start_s=st.floats(0, 0.1), duration_s=st.floats(0.001, 0.06),
              ahead_m=st.floats(-1, 3), left_m=st.floats(-1, 1)),
    st.builds(MarkingGap, s_m=st.floats(0, 20)),
    st.builds(LatencySpike, start_s=st.floats(0, 0.1), duration_s=st.floats(0.001, 0.06),
              extra_s=st.floats(0.001, 1.0)),
    st.builds(FrameDropBurst, start_s=st.floats(0, 0.1), duration_s=st.floats(0.001, 0.06)),
    st.builds(WetPatch, s_m=st.floats(0, 20), mu_scale=st.floats(0, 1)),
    st.builds(ServoOffset, start_s=st.floats(0, 0.1), duration_s=st.floats(0.001, 0.06),
              offset_rad=st.floats(-0.5, 0.5)),
)


def _unchecked(cls: type, **values: object) -> object:
    """A fault with ``values`` set past its own __post_init__ checks (which refuse most of
    these now): the env must refuse it all the same."""
    fault = object.__new__(cls)
    defaults = {f.name: f.default for f in dataclasses.fields(cls)}
    for name, value in (defaults | values).items():
        object.__setattr__(fault, name, value)
    return fault


# Faults with wrong field types or sizes.
BAD_FAULTS = st.one_of(
    st.builds(lambda v: _unchecked(Blackout, start_s=v, duration_s=0.02),
              st.sampled_from([np.int64(-1), np.float32("nan"), "3", None, 1e300])),
    st.builds(lambda v: _unchecked(LatencySpike, start_s=0.0, duration_s=0.02, extra_s=v),
              st.sampled_from([0.0, -1.0, 5.0, "x"])),
    st.builds(lambda v: _unchecked(WetPatch, s_m=1.0, length_m=1.0, mu_scale=v),
              st.sampled_from([-0.1, 2.0, np.float32("inf")])),
    st.builds(lambda v: _unchecked(MarkingGap, s_m=v, length_m=1.0),
              st.sampled_from(["3", None, np.float32("nan")])),
    st.builds(lambda v: _unchecked(LateralKick, step=1, offset_m=v),
              st.sampled_from([np.float32("inf"), "x", 1e6])),
)

VALUES = st.recursive(
    st.one_of(SCALARS, ARRAYS, FAULTS, BAD_FAULTS),
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.tuples(inner),
                            st.tuples(inner, inner, inner),
                            st.dictionaries(st.text(max_size=3), inner, max_size=2),
                            st.frozensets(st.integers(), max_size=3)),
    max_leaves=6,
)


def option_values(plausible: st.SearchStrategy) -> st.SearchStrategy:
    """Any value, or one near the valid ones (so that some resets succeed)."""
    return st.one_of(VALUES, plausible)


PLAUSIBLE = {
    "track": st.sampled_from(["oval", "oval", "thesis", "straight", None, 0, -1, 2.0]),
    "start": st.one_of(st.tuples(st.floats(-50, 50), st.floats(-0.6, 0.6), st.floats(-4, 4)),
                       st.tuples(st.one_of(HUGE, st.just(1.0)), st.just(-0.2), HUGE),
                       hnp.arrays(np.float64, st.sampled_from([(3,), (2,), (3, 1)]),
                                  elements=st.floats(-1, 1)),
                       st.lists(st.floats(-1, 1), min_size=3, max_size=3)),
    "speed_m_s": st.one_of(st.floats(-1, 10), st.integers(-1, 10), HUGE),
    "domain_randomization": st.booleans(),
    "faults": st.one_of(st.lists(FAULTS, max_size=3), st.tuples(FAULTS),
                        st.lists(st.one_of(FAULTS, BAD_FAULTS), min_size=1, max_size=2)),
}
assert set(PLAUSIBLE) == set(RESET_OPTIONS)

NEAR_VALID_OPTIONS = st.fixed_dictionaries({}, optional=PLAUSIBLE)
KNOWN_OPTIONS = st.fixed_dictionaries(
    {}, optional={k: option_values(v) for k, v in PLAUSIBLE.items()})
ANY_OPTIONS = st.dictionaries(
    st.one_of(st.sampled_from(RESET_OPTIONS), st.sampled_from(["spedd", "seed", "", "Track"]),
              st.integers(-2, 2), st.none()),
    VALUES, max_size=3)
# Mostly dicts of the known keys; also unknown keys, None and values that are no mapping.
OPTIONS = st.one_of(NEAR_VALID_OPTIONS, NEAR_VALID_OPTIONS, KNOWN_OPTIONS, KNOWN_OPTIONS,
                    KNOWN_OPTIONS, ANY_OPTIONS, st.none(), VALUES)


def check_result(env: TfaldaTrackEnv, obs: np.ndarray, info: dict) -> None:
    assert env.observation_space.contains(obs)
    assert math.isfinite(info["cross_track_m"]) and math.isfinite(info["speed_m_s"])


@FUZZ
@given(options=OPTIONS)
def test_any_reset_options_work_or_raise_type_or_value_error(
        envs: dict[bool, TfaldaTrackEnv], options: object) -> None:
    env = envs[False]
    try:
        obs, info = env.reset(seed=0, options=options)  # type: ignore[arg-type]
    except (TypeError, ValueError) as err:
        assert str(err), "the error says what is wrong"
        return
    check_result(env, obs, info)
    obs, reward, _, _, info = env.step(np.zeros(1, np.float32))  # the episode runs
    check_result(env, obs, info)
    assert math.isfinite(reward)


def actions(size: int) -> st.SearchStrategy:
    """Actions for an env whose action has ``size`` entries: mostly of that shape."""
    entry = st.one_of(st.floats(-1.5, 1.5), st.floats(-1, 1), SCALARS,
                      st.lists(st.floats(-1, 1), max_size=2))
    return st.one_of(
        hnp.arrays(DTYPES, (size,)),  # NaN, inf, huge, wrong dtypes
        hnp.arrays(np.float32, (size,), elements=st.floats(-1.5, 1.5, width=32)),
        hnp.arrays(np.float64, (size,), elements=st.floats(-1, 1)),
        hnp.arrays(np.dtype(object), (size,), elements=SCALARS),
        hnp.arrays(DTYPES, hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=3)),
        st.lists(entry, min_size=size, max_size=size),
        st.lists(entry, max_size=3),
        VALUES,
    )


THROTTLE_AND_ACTION = st.booleans().flatmap(
    lambda throttle: st.tuples(st.just(throttle), actions(2 if throttle else 1)))


@FUZZ
@given(throttle_and_action=THROTTLE_AND_ACTION)
def test_any_action_works_or_raises_type_or_value_error(
        envs: dict[bool, TfaldaTrackEnv], throttle_and_action: tuple[bool, object]) -> None:
    throttle, action = throttle_and_action
    env = envs[throttle]
    env.reset(seed=0, options={"start": (1.0, -0.2, 0.0)})
    try:
        obs, reward, terminated, truncated, info = env.step(action)  # type: ignore[arg-type]
    except (TypeError, ValueError) as err:
        assert str(err), "the error says what is wrong"
        # A refused action leaves the episode intact: the next step works.
        obs, reward, terminated, truncated, info = env.step(
            np.zeros(env.action_space.shape, np.float32))
    check_result(env, obs, info)
    assert math.isfinite(reward) and isinstance(terminated, bool)
    assert isinstance(truncated, bool)
