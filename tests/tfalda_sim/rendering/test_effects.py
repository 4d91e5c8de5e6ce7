"""Effects parameters and their domain randomisation."""

from __future__ import annotations

from dataclasses import fields

import numpy as np
import pytest

from tfalda_sim.rendering import DomainRandomization, Effects


def test_randomization_draws_within_the_declared_ranges() -> None:
    dr = DomainRandomization()
    rng = np.random.default_rng(0)
    draws = [dr.sample(rng) for _ in range(200)]
    for f in fields(dr):
        if f.name == "timing":  # not an effect: the env draws it (tests/envs/test_timing.py)
            assert dr.timing is None
            continue
        lo, hi = getattr(dr, f.name)
        values = [getattr(d, f.name) for d in draws]
        assert lo <= min(values) and max(values) <= hi
        assert len(set(values)) > 1  # the range is actually used


def test_randomization_is_reproducible() -> None:
    dr = DomainRandomization()
    assert dr.sample(np.random.default_rng(5)) == dr.sample(np.random.default_rng(5))
    assert dr.sample(np.random.default_rng(5)) != dr.sample(np.random.default_rng(6))


@pytest.mark.parametrize(("field", "value"), [("gain", -1.0), ("vignetting", 1.5),
                                              ("noise_dn", float("nan")), ("wear", 2.0),
                                              ("glare_spots", 2.5), ("shadows", 1.2),
                                              ("gain", "1.0"), ("shadows", True)])
def test_bad_effect_values_are_refused(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=field):
        Effects(**{field: value})


def test_spot_counts_are_integers() -> None:
    e = Effects(glare_spots=2.0, shadows=np.int64(3))
    assert type(e.glare_spots) is int and type(e.shadows) is int
    assert (e.glare_spots, e.shadows) == (2, 3)
