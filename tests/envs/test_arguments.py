"""TfaldaTrack-v0's constructor arguments and reset options: the right type or a TypeError /
ValueError naming the argument, what was given and what is accepted."""

from __future__ import annotations

import math
import re
import types

import gymnasium as gym
import numpy as np
import pytest

import tfalda_sim  # noqa: F401  (registers TfaldaTrack-v0)
from tfalda_sim.envs import RewardWeights, TfaldaTrackEnv
from tfalda_sim.envs._checks import show
from tfalda_sim.faults import Blackout, LateralKick
from tfalda_sim.perception import DetectorConfig
from tfalda_sim.rendering import DomainRandomization, Effects
from tfalda_sim.vehicle import CarParams


@pytest.fixture(scope="module")
def oval_env() -> TfaldaTrackEnv:
    return TfaldaTrackEnv(track="oval")


def _unchecked(cls: type, **values: object) -> object:
    """A fault with ``values`` set past its own checks: the env checks it again."""
    fault = object.__new__(cls)
    for name, value in values.items():
        object.__setattr__(fault, name, value)
    return fault


def raises(exc: type[Exception], *parts: str) -> pytest.RaisesContext:
    """``pytest.raises`` whose message must contain every part, in order."""
    return pytest.raises(exc, match=".*".join(map(re.escape, parts)))


# ---------------------------------------------------------------- the reproductions
def test_a_detector_preset_name_is_accepted_through_gymnasium_make() -> None:
    env = gym.make("TfaldaTrack-v0", detector="thesis", track="oval")
    assert env.unwrapped.detector_config == DetectorConfig.thesis()
    env.close()


@pytest.mark.parametrize("name, factory", [("thesis", DetectorConfig.thesis),
                                           ("improved", DetectorConfig.improved),
                                           ("without_lis", DetectorConfig.without_lis)])
def test_every_detector_preset_maps_to_its_classmethod(name: str, factory) -> None:
    env = TfaldaTrackEnv(track="oval", detector=name)
    assert env.detector_config == factory()
    assert env.reset(seed=0)[0].shape == env.observation_space.shape


def test_an_unknown_detector_preset_lists_the_names() -> None:
    with raises(ValueError, "detector", "'fancy'", "'thesis'", "'improved'", "'without_lis'"):
        TfaldaTrackEnv(detector="fancy")
    with raises(TypeError, "detector", "DetectorConfig", "got 3"):
        TfaldaTrackEnv(detector=3)


def test_car_of_the_wrong_type_is_a_type_error() -> None:
    with raises(TypeError, "car", "CarParams", "got 5"):
        gym.make("TfaldaTrack-v0", car=5)


def test_max_laps_nan_is_a_type_error_naming_max_laps() -> None:
    with raises(TypeError, "max_laps", "int", "got nan"):
        gym.make("TfaldaTrack-v0", max_laps=math.nan)


@pytest.mark.parametrize("name", ["obstacles", "throttle", "domain_randomization"])
@pytest.mark.parametrize("value", ["no", "maybe", "yes", 1, 0, None, 1.0, [True]])
def test_flags_take_only_booleans(name: str, value: object) -> None:
    with raises(TypeError, name, "bool", f"got {value!r}"):
        TfaldaTrackEnv(track="oval", **{name: value})


def test_flags_accept_python_and_numpy_booleans() -> None:
    env = TfaldaTrackEnv(track="oval", throttle=np.bool_(True), obstacles=True,
                         domain_randomization=np.bool_(False))
    assert env.throttle is True and env.obstacles is True and env.domain_randomization is False
    assert env.action_space.shape == (2,)


def test_reset_options_must_be_a_mapping(oval_env: TfaldaTrackEnv) -> None:
    with raises(TypeError, "options", "mapping", "got 'str'"):
        oval_env.reset(options="str")
    with raises(TypeError, "options", "got [('speed_m_s', 1.0)]"):
        oval_env.reset(options=[("speed_m_s", 1.0)])
    # Any Mapping will do, not only a dict.
    _, info = oval_env.reset(seed=0, options=types.MappingProxyType({"speed_m_s": 1.0}))
    assert info["speed_m_s"] == 1.0


# ---------------------------------------------------------------- every constructor argument
BAD_ARGUMENTS = [
    # (argument, value, exception, what the message says is accepted[, what it shows])
    ("render_mode", "human", ValueError, "'rgb_array'"),
    ("render_mode", 3, TypeError, "'rgb_array'"),
    ("observation", "pixels", ValueError, "'lanes', 'image', 'dict'"),
    ("observation", ["lanes"], TypeError, "'lanes', 'image', 'dict'"),
    ("track", "ovl", ValueError, "oval"),
    ("track", -3, ValueError, "≥ 0"),
    ("track", 5.0, TypeError, "generator seed"),
    ("track", True, TypeError, "generator seed"),
    ("track_seeds", (5, 5), ValueError, "0 ≤ low < high"),
    ("track_seeds", (0, 2**64), ValueError, "2**63"),
    ("track_seeds", (0.0, 10), TypeError, "pair (low, high) of ints"),
    ("track_seeds", (1, 2, 3), ValueError, "pair"),
    ("track_seeds", "ab", TypeError, "pair"),
    ("track_seeds", 7, TypeError, "pair"),
    ("speed_m_s", 20.0, ValueError, "[0.05, "),
    ("speed_m_s", 0.0, ValueError, "[0.05, "),
    ("speed_m_s", math.inf, ValueError, "finite"),
    ("speed_m_s", math.nan, ValueError, "finite"),
    ("speed_m_s", 10**400, ValueError, "finite"),
    ("speed_m_s", "1.5", TypeError, "real number"),
    ("speed_m_s", True, TypeError, "real number"),
    ("speed_m_s", None, TypeError, "real number"),
    ("randomization", {}, TypeError, "DomainRandomization"),
    ("effects", "bright", TypeError, "Effects"),
    ("car", CarParams, TypeError, "CarParams"),
    ("reward", (1.0, 0.5), TypeError, "RewardWeights"),
    ("max_laps", -1, ValueError, "≥ 0"),
    ("max_laps", 2.0, TypeError, "int"),
    ("max_laps", True, TypeError, "int"),
    ("max_laps", "2", TypeError, "int"),
    ("faults", "no", TypeError, "sequence"),
    ("faults", None, TypeError, "sequence"),
    ("faults", Blackout(start_s=0.06, duration_s=0.02), TypeError, "sequence"),
    ("faults", ["blackout"], TypeError, "Blackout", "faults[0]: unknown fault 'blackout'"),
    ("faults", [_unchecked(Blackout, start_s="3", duration_s=0.02)], TypeError, "real number",
     "faults[0]: Blackout.start_s"),
    ("faults", [Blackout(0.04, 0.02), _unchecked(Blackout, start_s=1.0, duration_s=np.int64(0))],
     ValueError, "> 0", "faults[1]: Blackout.duration_s"),
]


@pytest.mark.parametrize("row", BAD_ARGUMENTS, ids=[f"{a}={show(v)}" for a, v, *_ in BAD_ARGUMENTS])
def test_a_bad_constructor_argument_names_itself_the_value_and_what_is_accepted(
        row: tuple) -> None:
    name, value, exc, accepted, *shown = row
    with pytest.raises(exc) as err:
        TfaldaTrackEnv(**{"track": "oval", name: value})
    message = str(err.value)
    assert name in message and accepted in message
    assert (shown[0] if shown else show(value)) in message


def test_a_long_value_is_shortened_in_the_message() -> None:
    with pytest.raises(TypeError) as err:
        TfaldaTrackEnv(faults="x" * 10_000)
    assert "'xxx" in str(err.value) and "..." in str(err.value) and len(str(err.value)) < 300


def test_valid_values_of_other_types_give_the_same_rollout() -> None:
    """numpy scalars, a list of seeds and None for the defaults change nothing."""
    def run(env: TfaldaTrackEnv) -> tuple[list, list]:
        obs, info = env.reset(seed=4)
        observations, rewards = [obs], [info["track"]]
        for _ in range(20):
            obs, reward, *_ = env.step(np.array([0.1], np.float32))
            observations.append(obs)
            rewards.append(reward)
        return observations, rewards

    plain = TfaldaTrackEnv(track_seeds=(10, 20), speed_m_s=1.5, max_laps=2)
    numpy = TfaldaTrackEnv(track_seeds=[np.int64(10), np.uint16(20)],
                           speed_m_s=np.float32(1.5), max_laps=np.int8(2),
                           throttle=np.bool_(False), detector=None, car=None, reward=None,
                           effects=None, randomization=None, faults=[])
    assert numpy.track_seeds == (10, 20) and type(numpy.speed_m_s) is float
    assert type(numpy.max_laps) is int
    a, b = run(plain), run(numpy)
    assert a[1] == b[1]
    assert all(np.array_equal(x, y) for x, y in zip(a[0], b[0], strict=True))


def test_given_objects_are_used() -> None:
    car, reward = CarParams(max_speed_m_s=3.0), RewardWeights(crash=1.0)
    effects, randomization = Effects(), DomainRandomization()
    env = TfaldaTrackEnv(track="oval", car=car, reward=reward, effects=effects,
                         randomization=randomization, speed_m_s=3)
    assert env.car is car and env.reward_weights is reward
    assert env.effects is effects and env.randomization is randomization
    with raises(ValueError, "speed_m_s", "[0.05, 3]", "got 3.5"):
        TfaldaTrackEnv(track="oval", car=car, speed_m_s=3.5)  # the car's top speed


# ---------------------------------------------------------------- every reset option
BAD_OPTIONS = [
    # (option, value, exception, what the message says is accepted[, what it shows])
    ("track", 2.5, TypeError, "generator seed"),
    ("track", "ovl", ValueError, "oval"),
    ("track", [1], TypeError, "tfalda_sim.tracks.Track"),
    ("start", "abc", TypeError, "three finite real numbers"),
    ("start", (1.0, 2.0), ValueError, "three"),
    ("start", (True, 0.0, 0.0), TypeError, "real numbers"),
    ("start", ("1", "0", "0"), TypeError, "real numbers"),
    ("start", (1.0, math.nan, 0.0), ValueError, "finite"),
    ("start", np.zeros((3, 1)), ValueError, "three"),
    ("start", (1.0, 0.9, 0.0), ValueError, "off the road", "lateral_m 0.9"),
    ("start", (1.0, 1e300, 0.0), ValueError, "off the road", "lateral_m 1e+300"),
    ("start", (1e300, -0.2, 0.0), ValueError, "more than a lap", "s_m 1e+300"),
    ("start", (-23.0, -0.2, 0.0), ValueError, "more than a lap", "s_m -23"),
    ("start", (1.0, -0.2, 1e300), ValueError, "half turn", "heading_error_rad 1e+300"),
    ("start", (1.0, -0.2, -3.2), ValueError, "half turn", "heading_error_rad -3.2"),
    ("speed_m_s", "2", TypeError, "real number"),
    ("speed_m_s", None, TypeError, "real number"),
    ("speed_m_s", np.array([1.0]), TypeError, "real number"),
    ("speed_m_s", -0.1, ValueError, "[0, "),
    ("speed_m_s", math.inf, ValueError, "finite"),
    ("domain_randomization", None, TypeError, "bool"),
    ("domain_randomization", "yes", TypeError, "bool"),
    ("domain_randomization", 1, TypeError, "bool"),
    ("faults", None, TypeError, "sequence"),
    ("faults", "blackout", TypeError, "sequence"),
    ("faults", ["blackout"], TypeError, "unknown fault", "faults[0]: unknown fault 'blackout'"),
]


@pytest.mark.parametrize("row", BAD_OPTIONS, ids=[f"{a}={show(v)}" for a, v, *_ in BAD_OPTIONS])
def test_a_bad_reset_option_names_itself_the_value_and_what_is_accepted(
        oval_env: TfaldaTrackEnv, row: tuple) -> None:
    name, value, exc, accepted, *shown = row
    with pytest.raises(exc) as err:
        oval_env.reset(seed=0, options={name: value})
    message = str(err.value)
    assert name in message and accepted in message
    assert (shown[0] if shown else show(value)) in message


def test_valid_reset_options_of_other_types(oval_env: TfaldaTrackEnv) -> None:
    _, info = oval_env.reset(seed=0, options={
        "start": np.array([4.0, -0.15, 0.05]), "speed_m_s": np.float32(2.5),
        "domain_randomization": np.bool_(False),
        "faults": (Blackout(start_s=np.int64(2), duration_s=np.float32(0.5)),)})
    assert info["s_m"] == pytest.approx(4.0, abs=1e-6) and info["speed_m_s"] == 2.5
    _, same = oval_env.reset(seed=0, options={"start": [4, -0.15, 0.05], "speed_m_s": 2.5})
    assert same["s_m"] == info["s_m"] and same["cross_track_m"] == info["cross_track_m"]


def test_unknown_option_keys_of_any_type_are_listed(oval_env: TfaldaTrackEnv) -> None:
    with raises(ValueError, "unknown reset option", "'spedd'", "known: track"):
        oval_env.reset(options={1: 2, "spedd": 3, None: 4})


def test_a_refused_reset_leaves_the_episode_as_it_was() -> None:
    """The options are checked before the env changes: the drive goes on unchanged."""
    a, b = TfaldaTrackEnv(track="oval"), TfaldaTrackEnv(track="oval")
    for env in (a, b):
        env.reset(seed=1)
        env.step(np.array([0.2], np.float32))
    with pytest.raises(TypeError):
        a.reset(seed=5, options={"faults": [Blackout(0.02, 0.02)], "speed_m_s": "fast"})
    for _ in range(5):
        obs_a, reward_a, *_ = a.step(np.array([0.1], np.float32))
        obs_b, reward_b, *_ = b.step(np.array([0.1], np.float32))
        assert np.array_equal(obs_a, obs_b) and reward_a == reward_b


def test_unconvertible_actions_are_named() -> None:
    """np.asarray raised its own UnicodeDecodeError/ValueError for these before."""
    env = TfaldaTrackEnv(track="oval")
    env.reset(seed=0)
    for action in ([b"\xff", "y"], [[1.0, 2.0], [3.0]]):
        with pytest.raises(ValueError, match="action must be an array of shape"):
            env.step(action)


def test_fault_sizes_are_refused_when_the_fault_is_made() -> None:
    """A NaN (numpy's too) or an absurd size fails at construction, naming the field; a
    huge glare or shake overflowed inside step() before."""
    from tfalda_sim.faults import CameraShake, Glare

    for make, field in ((lambda: LateralKick(0.04, offset_m=np.float32("nan")),
                         "LateralKick.offset_m"),
                        (lambda: LateralKick(0.04, offset_m=1e6), "LateralKick.offset_m"),
                        (lambda: Glare(0.02, 0.1, radius_m=1e300), "Glare.radius_m"),
                        (lambda: Glare(0.02, 0.1, peak_dn=1e9), "Glare.peak_dn"),
                        (lambda: CameraShake(0.02, 0.04, amplitude_rad=1e308),
                         "CameraShake.amplitude_rad")):
        with pytest.raises(ValueError, match=re.escape(field) + " must be finite and in"):
            make()


def test_a_start_at_the_bounds_is_accepted(oval_env: TfaldaTrackEnv) -> None:
    """A closed track wraps (a lap back is the start line); the road's edge and a half turn
    are starts too."""
    length = oval_env._default_track.length_m
    _, info = oval_env.reset(seed=0, options={"start": (-length + 1.0, -0.4, -3.14)})
    assert info["s_m"] == pytest.approx(1.0, abs=1e-6)
