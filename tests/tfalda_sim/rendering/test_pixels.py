"""The pixel geometry: kept per camera and bonnet values, read-only."""

from __future__ import annotations

import numpy as np
import pytest

from tfalda_sim.camera import Bonnet, load_camera
from tfalda_sim.rendering import Renderer
from tfalda_sim.rendering.pixels import _KEPT, PIXEL_GEOMETRIES_KEPT, _compute, pixel_geometry


def test_a_camera_read_again_shares_its_pixel_geometry_and_it_is_read_only() -> None:
    """Every env's renderer needs its camera's pixel geometry (1–2 s to compute): a camera
    read from its profile again (a new object, the same numbers) gets the one kept."""
    first, again = load_camera("thesis"), load_camera("thesis")
    assert first is not again
    geometry = Renderer(first).geometry
    assert Renderer(again).geometry is geometry
    with pytest.raises(ValueError, match="read-only"):
        geometry.gx[0, 0] = 1.0
    fresh = _compute(first, first.bonnet)  # what was kept is what would be computed
    for name, value in vars(fresh).items():
        np.testing.assert_array_equal(getattr(geometry, name), value)


def test_another_mount_or_bonnet_gets_its_own_geometry_and_few_are_kept() -> None:
    camera = load_camera("thesis")
    base = pixel_geometry(camera)
    lower = pixel_geometry(camera.with_mount(height_m=camera.mount.height_m - 0.02))
    bare = pixel_geometry(camera, Bonnet.none())
    assert lower is not base and bare is not base
    assert not np.array_equal(lower.gx, base.gx)
    assert base.bonnet.any() and not bare.bonnet.any()
    assert len(_KEPT) <= PIXEL_GEOMETRIES_KEPT
