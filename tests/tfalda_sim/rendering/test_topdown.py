"""The top-down inset shows the car where it is."""

from __future__ import annotations

import numpy as np

from tfalda_sim.rendering.topdown import TopDownMap
from tfalda_sim.tracks import load_named


def test_car_is_drawn_at_its_pose() -> None:
    track = load_named("oval")
    m = TopDownMap.of(track, 160)
    assert m.base.shape == (160, 160, 3)
    for s in (1.0, 8.0):
        x, y, h = (float(v) for v in track.pose(s, -0.2))
        img = m.draw((x, y, h))
        red = np.argwhere((img[..., 2] > 200) & (img[..., 1] < 80))
        assert len(red) > 4
        u, v = (x - m.origin_m[0]) * m.scale_px_m, (m.origin_m[1] - y) * m.scale_px_m
        assert np.abs(red.mean(axis=0) - (v, u)).max() < 4.0
    assert not np.array_equal(m.base, img)  # drawing leaves the base map alone
    assert (m.base[..., 2] > 200).sum() < (img[..., 2] > 200).sum()
