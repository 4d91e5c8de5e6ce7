"""Lazy scenes: the marking map and its mip levels are filled tile by tile as
the renderer looks at them, and every frame equals the eager scene's bit for bit."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import cv2
import numpy as np
import pytest

from tests.conftest import generated
from tfalda_sim.rendering import DomainRandomization, Effects, Renderer, build_scene
from tfalda_sim.rendering.scene import (
    ATLAS_RESERVE_BYTES,
    MipTiles,
    _atlas,
    _atlas_layout,
    _level_sizes,
    _mip_tiles,
    _propagate,
)
from tfalda_sim.tracks import Track, load_named
from tfalda_sim.tracks.raster import TiledMarkingMap, memory_of, untouched_zeros

ROIS = [(195, 260, 150, 75), (365, 260, 150, 75), (80, 340, 180, 85), (429, 340, 180, 85)]


@pytest.fixture(scope="module")
def renderer() -> Renderer:
    return Renderer()


def _effects(kind: str, seed: int) -> tuple[Effects, int]:
    """Effects and the scene seed: default, "off", or randomised with wear, shadows and
    glare spots forced on (the lazy paths of all three)."""
    if kind == "default":
        return Effects(), 0
    if kind == "off":
        return Effects.off(), 0
    fx = DomainRandomization().sample(np.random.default_rng(seed))
    return replace(fx, wear=max(fx.wear, 0.3), shadows=max(fx.shadows, 2),
                   glare_spots=max(fx.glare_spots, 2)), 1000 + seed


def _poses(track: Track, n: int, seed: int) -> list[tuple[float, float, float]]:
    """Car poses anywhere on the loop (far from the start too), across the road, turned."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        s = track.length_m * (k + rng.random()) / n
        x, y, h = track.pose(s, float(rng.uniform(-0.35, 0.35)))
        out.append((float(x), float(y), float(h) + float(rng.uniform(-0.5, 0.5))))
    return out


@pytest.mark.parametrize("seed", [3, 7, 19])
@pytest.mark.parametrize("kind", ["default", "off", "randomised"])
def test_lazy_frames_equal_eager_frames(renderer: Renderer, seed: int, kind: str) -> None:
    track = generated(seed)  # with its cartons
    assert track.obstacles or seed != 19  # at least some of these tracks have cartons
    fx, scene_seed = _effects(kind, seed)
    eager = build_scene(track, fx, np.random.default_rng(scene_seed), lazy=False)
    lazy = build_scene(track, fx, np.random.default_rng(scene_seed))
    assert eager.tiles is None and lazy.tiles is not None
    for k, pose in enumerate(_poses(track, 6, seed)):
        speed = (0.0, 2.5)[k % 2]  # motion blur on every other pose
        want = renderer.render_windows(eager, pose, ROIS, speed_m_s=speed, frame_seed=k)
        got = renderer.render_windows(lazy, pose, ROIS, speed_m_s=speed, frame_seed=k)
        for w, g in zip(want, got, strict=True):
            np.testing.assert_array_equal(g, w)
        if k % 3 == 0:
            np.testing.assert_array_equal(
                renderer.render(lazy, pose, speed_m_s=speed, frame_seed=k),
                renderer.render(eager, pose, speed_m_s=speed, frame_seed=k))
    assert not lazy.tiles.complete  # a few views fill only part of the map
    lazy.fill_all()
    np.testing.assert_array_equal(lazy.atlas, eager.atlas)
    np.testing.assert_array_equal(lazy.level_origin, eager.level_origin)
    assert (lazy.wall_origin, lazy.wall_size, lazy.level0_size, lazy.origin) == (
        eager.wall_origin, eager.wall_size, eager.level0_size, eager.origin)
    if eager.light is not None:
        np.testing.assert_array_equal(lazy.light, eager.light)


def test_lazy_scene_on_named_tracks_and_a_far_start(renderer: Renderer) -> None:
    for name in ("thesis", "figure-eight"):
        track = load_named(name)
        eager = build_scene(track, lazy=False)
        lazy = build_scene(track)
        # The far end of the loop first: nothing near the start is filled before.
        for pose in _poses(track, 4, 1)[::-1]:
            np.testing.assert_array_equal(renderer.render(lazy, pose, frame_seed=3),
                                          renderer.render(eager, pose, frame_seed=3))


def test_a_roi_view_fills_a_small_part_of_the_map(renderer: Renderer) -> None:
    track = replace(generated(5), name="a fresh copy")  # another track: its own map
    scene = build_scene(track, Effects())
    renderer.render_windows(scene, _poses(track, 1, 0)[0], ROIS)
    filled = scene.tiles.marking.filled
    assert 0 < filled.mean() < 0.15
    assert not scene.tiles.wall_filled.any()  # the ROIs see no wall: none copied in


def test_lazy_scene_draws_the_same_random_numbers() -> None:
    """Everything random is drawn at build time, in the eager order: the generator ends
    in the same state, so whatever the env draws next does not change."""
    track = generated(7)
    fx, _ = _effects("randomised", 7)
    a, b = np.random.default_rng(5), np.random.default_rng(5)
    build_scene(track, fx, a, lazy=False)
    build_scene(track, fx, b)
    assert a.bit_generator.state == b.bit_generator.state
    # A cached wall texture leaves the generator where drawing it would.
    c = np.random.default_rng(5)
    build_scene(track, fx, c)
    assert c.bit_generator.state == a.bit_generator.state


def _fill_listed(t: MipTiles, atlas: np.ndarray, filled: np.ndarray, need: np.ndarray,
                 rng: np.random.Generator) -> None:
    """Fill the tiles marked in ``need`` and those under them, as ``MipTiles._fill`` does."""
    queue = np.empty(len(need), np.int64)
    listed = np.flatnonzero(need)
    rng.shuffle(listed)  # any order: _propagate sorts the list by level
    queue[:len(listed)] = listed
    n = _propagate(queue, len(listed), need, filled, t.sizes, t.tile, t.grids, t.offsets)
    assert np.all(np.diff(queue[:n]) > 0)  # sorted, each tile once
    assert set(queue[:n]) == set(np.flatnonzero(need))
    _mip_tiles(atlas, t.origins, queue[:n], t.sizes, t.tile, t.grids, t.offsets,
               t.nonzero_rows[:t.grids[0, 0] * t.grids[0, 1]], t.nonzero_rows)
    filled[queue[:n]] = 1


def test_tile_wise_mips_equal_whole_mips() -> None:
    """Level L of the atlas filled tile by tile, in any order, equals OpenCV's INTER_AREA
    halving of the whole level L − 1 (odd sizes and partial tiles included)."""
    rng = np.random.default_rng(0)
    for shape0 in ((300, 517), (257, 129), (64, 64), (1000, 333)):
        level0 = rng.integers(0, 256, shape0, dtype=np.uint8)
        level0[rng.random(shape0) < 0.5] = 0  # runs of mat, as on a map
        level0[rng.random(shape0[0]) < 0.6] = 0  # rows of mat: the masks skip them
        wall = rng.integers(0, 256, (20, 40), dtype=np.uint8)
        eager, origins, wall_origin = _atlas(level0, wall)
        (height, width), sizes, level_xy, wall_xy = _atlas_layout(shape0, wall.shape)
        assert (height, width) == eager.shape and wall_xy == wall_origin
        np.testing.assert_array_equal(np.array(level_xy, np.float32), origins)
        assert sizes == _level_sizes(shape0)
        for tile0 in (1, 8, 32):
            atlas = untouched_zeros((height, width))
            g = 4
            atlas[g:g + shape0[0], g:g + shape0[1]] = level0
            t = MipTiles.__new__(MipTiles)  # only the tiling: no marking map
            t.sizes = np.array(sizes, np.int64)
            t.origins = np.array(level_xy, np.int64)
            t.tile = np.array([max(1, tile0 >> lv) for lv in range(len(sizes))], np.int64)
            t.grids = -(-t.sizes // t.tile[:, None])
            counts = t.grids[:, 0] * t.grids[:, 1]
            t.offsets = np.concatenate(([0], np.cumsum(counts)[:-1])).astype(np.int64)
            filled = np.zeros(int(counts.sum()), np.uint8)
            filled[:counts[0]] = 1  # level 0 is there
            # its row masks, exact (each non-zero row's bit): the levels above skip the
            # zero rows and must still equal the whole-level halving
            t.nonzero_rows = np.zeros(len(filled), np.int64)
            nonzero = (level0 != 0).any(axis=1)
            for index in range(int(counts[0])):
                tr = index // int(t.grids[0, 1])
                for k, row in enumerate(range(tr * tile0, min((tr + 1) * tile0, shape0[0]))):
                    tc = index % int(t.grids[0, 1])
                    if level0[row, tc * tile0:(tc + 1) * tile0].any():
                        t.nonzero_rows[index] |= np.int64(1) << k
            assert nonzero.any() and not nonzero.all()
            for _ in range(3):  # random batches of the coarsest level's tiles
                need = np.zeros_like(filled)
                top = len(sizes) - 1
                n_top = int(counts[top])
                need[t.offsets[top]:t.offsets[top] + n_top] = rng.random(n_top) < 0.5
                need &= filled == 0
                _fill_listed(t, atlas, filled, need, rng)
            _fill_listed(t, atlas, filled, (filled == 0).astype(np.uint8), rng)
            wx, wy = wall_xy
            atlas[wy:wy + 20, wx:wx + 40] = wall
            atlas[wy:wy + 20, wx + 40] = wall[:, 0]
            np.testing.assert_array_equal(atlas, eager)
            # and each level is INTER_AREA of the one below, as the eager atlas makes it
            for lv in range(1, len(sizes)):
                (r, c), (pr, pc) = sizes[lv], sizes[lv - 1]
                (x, y), (px, py) = level_xy[lv], level_xy[lv - 1]
                below = atlas[py:py + pr, px:px + pc][:2 * r, :2 * c]
                np.testing.assert_array_equal(
                    atlas[y:y + r, x:x + c],
                    cv2.resize(below, (c, r), interpolation=cv2.INTER_AREA))


def test_scenes_of_one_track_share_its_marking_map() -> None:
    track = generated(11)
    a = build_scene(track, Effects())
    b = build_scene(replace(track, name=track.name), Effects.off())  # an equal track
    assert a.tiles.marking is b.tiles.marking
    c = build_scene(generated(12), Effects())
    assert c.tiles.marking is not a.tiles.marking
    assert isinstance(c.tiles.marking, TiledMarkingMap)


def test_a_view_s_boxes_cover_every_ground_pixel_it_reads(renderer: Renderer) -> None:
    """The per-block table is made once per pixel layout; a view takes the rows of the
    blocks its windows touch, and every ground pixel of the windows lies inside a box of
    its own mip level from its own block."""
    from tfalda_sim.rendering.renderer import FOOTPRINT_BLOCK_PX, _view_bounds

    scene = build_scene(generated(3), Effects())
    layout = renderer._layout(scene).pixel
    level = np.clip(np.rint(renderer.geometry.log2_fp - np.log2(scene.resolution_m)), 0,
                    scene.levels - 1).astype(np.int64)
    rng = np.random.default_rng(0)
    block = FOOTPRINT_BLOCK_PX
    for _ in range(20):
        w, h = int(rng.integers(1, 200)), int(rng.integers(1, 120))
        x0, y0 = int(rng.integers(0, 752 - w + 1)), int(rng.integers(0, 480 - h + 1))
        bounds, _, _ = _view_bounds(np.array([[x0, y0, w, h]], np.int64),
                                    layout.block_start, layout.block_bounds,
                                    layout.block_walls, block, layout.block_cols)
        blocks = {(r // block, c // block) for r in range(y0, y0 + h)
                  for c in range(x0, x0 + w)}
        rows = sum(int(layout.block_start[i * layout.block_cols + j + 1]
                       - layout.block_start[i * layout.block_cols + j]) for i, j in blocks)
        assert len(bounds) == rows  # the touched blocks' rows, no more
        for r in range(y0, y0 + h, 3):
            for c in range(x0, x0 + w, 3):
                if not layout.flags[r, c] & 1:
                    continue
                gx, gy = layout.coord_a[r, c], layout.coord_b[r, c]
                inside = ((bounds[:, 0] == level[r, c]) & (bounds[:, 1] <= gx)
                          & (gx <= bounds[:, 2]) & (bounds[:, 3] <= gy) & (gy <= bounds[:, 4]))
                assert inside.any(), (r, c)


def test_moving_windows_cost_no_pass_over_the_pixels(renderer: Renderer, monkeypatch) -> None:
    """New windows every frame (the env's ROIs) reuse the per-block table: it is built
    with the pixel layout, never per window list."""
    from tfalda_sim.rendering import renderer as module

    calls = []
    real = module._block_bounds
    monkeypatch.setattr(module, "_block_bounds", lambda *a: calls.append(1) or real(*a))
    r = Renderer()
    track = replace(generated(9), name="moving windows")
    scene = build_scene(track, Effects())
    pose = _poses(track, 1, 0)[0]
    for dx in range(0, 40, 4):
        r.render_windows(scene, pose, [(x + dx, y, w, h) for x, y, w, h in ROIS])
    assert len(calls) == 1


def test_alternating_atlases_keep_their_own_offsets() -> None:
    """Scenes of tracks of other sizes (other atlas layouts) rendered in turn by one
    renderer, whose per-pixel atlas offsets are filled block by block per layout, give
    the frames of a renderer that saw only that scene."""
    shared = Renderer()
    tracks = [generated(3), generated(7)]
    scenes = [build_scene(t, Effects(), lazy=False) for t in tracks]
    assert not np.array_equal(scenes[0].level_origin, scenes[1].level_origin)
    poses = [_poses(t, 2, 0) for t in tracks]
    for k in (0, 1, 0, 1):
        pose = poses[k][0]
        got = shared.render_windows(scenes[k], pose, ROIS, frame_seed=1)
        alone = Renderer().render_windows(scenes[k], pose, ROIS, frame_seed=1)
        for g, w in zip(got, alone, strict=True):
            np.testing.assert_array_equal(g, w)
        np.testing.assert_array_equal(shared.render(scenes[k], poses[k][1], frame_seed=2),
                                      Renderer().render(scenes[k], poses[k][1], frame_seed=2))


def test_prepare_without_wall_rows_copies_every_wall_row() -> None:
    scene = build_scene(replace(generated(4), name="walls"), Effects())
    scene.prepare(np.zeros((0, 5)), np.zeros((1, 6)))
    assert scene.tiles.wall_filled.all()
    eager = build_scene(generated(4), Effects(), lazy=False)
    (wx, wy), (cols, rows) = eager.wall_origin, eager.wall_size
    np.testing.assert_array_equal(scene.atlas[wy:wy + rows, wx:wx + cols + 1],
                                  eager.atlas[wy:wy + rows, wx:wx + cols + 1])


def test_a_scene_without_wear_paints_level_0_in_its_atlas() -> None:
    scene = build_scene(generated(31), Effects.off())
    assert scene.tiles.level0_in_atlas and scene.tiles.marking.labels is None
    assert np.shares_memory(scene.tiles.marking.intensity, scene.atlas)
    worn = build_scene(generated(32), replace(Effects(), wear=0.5), np.random.default_rng(1))
    assert not worn.tiles.level0_in_atlas
    assert not np.shares_memory(worn.tiles.marking.intensity, worn.atlas)


def _random_effects(rng: np.random.Generator) -> tuple[Effects, int]:
    return _effects(("default", "off", "randomised")[int(rng.integers(3))],
                    int(rng.integers(100)))


def _random_views_equal(renderer: Renderer, held: list[tuple[Any, Any]],
                        rng: np.random.Generator) -> None:
    """Two views of held (lazy, eager) pairs, drawn at random: the lazy frames equal the
    eager ones."""
    for k in range(2):
        got_scene, want_scene = held[int(rng.integers(len(held)))]
        pose = _poses(got_scene.track, 1, int(rng.integers(1000)))[0]
        for got, want in zip(renderer.render_windows(got_scene, pose, ROIS, frame_seed=k),
                             renderer.render_windows(want_scene, pose, ROIS, frame_seed=k),
                             strict=True):
            np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("seed", [0, 1])
def test_scenes_sharing_a_marking_map_all_render_the_eager_frames(renderer: Renderer,
                                                                   seed: int) -> None:
    """Scenes built one after another on a few tracks (the same track again shares the
    marking map painted into an earlier scene's atlas), with and without wear, some held
    while newer ones are built: every view of each, old or new, equals its eager scene's."""
    rng = np.random.default_rng(seed)
    tracks = [generated(3), generated(7), load_named("oval")]
    held: list[tuple[Any, Any]] = []
    shared = 0
    for _ in range(14):
        track = tracks[int(rng.integers(len(tracks)))]
        fx, scene_seed = _random_effects(rng)
        lazy = build_scene(track, fx, np.random.default_rng(scene_seed))
        eager = build_scene(track, fx, np.random.default_rng(scene_seed), lazy=False)
        shared += any(lazy.tiles.marking is old.tiles.marking for old, _ in held)
        held = [*held[-3:], (lazy, eager)]
        _random_views_equal(renderer, held, rng)
    assert shared  # some scene did reuse an earlier scene's marking map


@pytest.mark.parametrize("how", ["pickle", "deepcopy"])
def test_a_copied_lazy_scene_keeps_painting_into_its_own_atlas(renderer: Renderer,
                                                               how: str) -> None:
    """A scene without wear paints level 0 in its atlas; a copy of it (half filled) must
    go on doing so in the copy's atlas: new views of the copy equal the eager frames."""
    import copy
    import pickle

    track = generated(11)
    build_scene(load_named("oval"), Effects.off())  # the last marking map: another track's
    lazy = build_scene(track, Effects.off())
    eager = build_scene(track, Effects.off(), lazy=False)
    poses = _poses(track, 6, 11)
    for pose in poses[:2]:
        renderer.render_windows(lazy, pose, ROIS, frame_seed=0)
    twin = pickle.loads(pickle.dumps(lazy)) if how == "pickle" else copy.deepcopy(lazy)
    assert twin.tiles.level0_in_atlas
    assert np.shares_memory(twin.tiles.marking.intensity, twin.atlas)
    for k, pose in enumerate(poses[2:]):
        for got, want in zip(renderer.render_windows(twin, pose, ROIS, frame_seed=k),
                             renderer.render_windows(eager, pose, ROIS, frame_seed=k),
                             strict=True):
            np.testing.assert_array_equal(got, want)


def test_a_retired_scene_hands_over_all_zero_memory_and_cannot_render(
        renderer: Renderer) -> None:
    """``build_scene(reuse=old)`` on another track: the old scene's atlas memory, written
    by its views (level 0, mip levels, walls), is all zeros again and taken over; the old
    scene raises a clear error instead of rendering from memory that is not its own."""
    old_track, new_track = generated(13), generated(3)
    old = build_scene(old_track, Effects())
    for k, pose in enumerate(_poses(old_track, 3, 13)):
        renderer.render_windows(old, pose, ROIS, frame_seed=k)
    renderer.render(old, _poses(old_track, 1, 1)[0])  # a full frame: walls too
    assert old.tiles.wall_filled.any() and old.tiles.n_filled > 0
    memory = memory_of(old.atlas)
    assert memory is not None and np.frombuffer(memory, np.uint8).any()
    new = build_scene(new_track, Effects(), reuse=old)
    assert old.tiles.retired
    assert not np.frombuffer(memory, np.uint8).any()  # nothing painted by the new one yet
    assert memory_of(new.atlas) is memory  # room enough: ``ATLAS_RESERVE_BYTES``
    with pytest.raises(RuntimeError, match="retired"):
        renderer.render_windows(old, _poses(old_track, 1, 2)[0], ROIS)
    with pytest.raises(RuntimeError, match="retired"):
        old.fill_all()
    eager = build_scene(new_track, Effects(), lazy=False)
    for k, pose in enumerate(_poses(new_track, 4, 3)):
        np.testing.assert_array_equal(renderer.render(new, pose, frame_seed=k),
                                      renderer.render(eager, pose, frame_seed=k))
    # The same track again: nothing to hand over (its map is shared instead).
    again = build_scene(new_track, Effects.off(), reuse=new)
    assert not new.tiles.retired and again.tiles.marking is new.tiles.marking
    with pytest.raises(TypeError, match="reuse must be a Scene"):
        build_scene(new_track, reuse="scene")  # type: ignore[arg-type]


def test_a_new_atlas_reserves_room_for_the_larger_atlases_that_take_it_over(
        renderer: Renderer) -> None:
    """New atlas memory is at least ``ATLAS_RESERVE_BYTES`` (address space, untouched): the
    scene of a larger track (here 6.4 → 23.3 MiB) takes over the memory its views wrote
    instead of new memory whose every page faults again, and renders the eager frames."""
    small, large = generated(17), generated(32)
    first = build_scene(small, Effects())
    memory = memory_of(first.atlas)
    assert memory is not None and len(memory) >= ATLAS_RESERVE_BYTES > first.atlas.size
    for k, pose in enumerate(_poses(small, 3, 17)):
        renderer.render_windows(first, pose, ROIS, frame_seed=k)
    second = build_scene(large, Effects(), reuse=first)
    assert first.atlas.size < second.atlas.size <= ATLAS_RESERVE_BYTES
    assert memory_of(second.atlas) is memory
    eager = build_scene(large, Effects(), lazy=False)
    for k, pose in enumerate(_poses(large, 3, 32)):
        np.testing.assert_array_equal(renderer.render(second, pose, frame_seed=k),
                                      renderer.render(eager, pose, frame_seed=k))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_scenes_reusing_retired_memory_all_render_the_eager_frames(renderer: Renderer,
                                                                   seed: int) -> None:
    """A chain of scenes, each built with ``reuse=`` an earlier one (as the env does on a
    new track), others held that share a retired scene's marking map, with and without
    wear: every live scene's views equal its eager scene's, whatever came before."""
    rng = np.random.default_rng(seed)
    tracks = [generated(3), generated(7), load_named("oval"), generated(19)]
    held: list[tuple[Any, Any]] = []
    retired = 0
    for _ in range(16):
        track = tracks[int(rng.integers(len(tracks)))]
        fx, scene_seed = _random_effects(rng)
        reuse = held[int(rng.integers(len(held)))][0] if held and rng.random() < 0.7 else None
        lazy = build_scene(track, fx, np.random.default_rng(scene_seed), reuse=reuse)
        eager = build_scene(track, fx, np.random.default_rng(scene_seed), lazy=False)
        if reuse is not None and reuse.tiles.retired:
            retired += 1
            held = [(s, e) for s, e in held if s is not reuse]
        held = [*held[-3:], (lazy, eager)]
        _random_views_equal(renderer, held, rng)
    assert retired >= 3


def test_a_scene_sharing_a_retired_scene_s_marking_map_repaints_it(renderer: Renderer) -> None:
    """Scene b shares the marking map that paints into scene a's atlas; a is retired: the
    map starts again on its own memory, and b's new views still equal the eager frames."""
    track = replace(generated(21), name="shared then retired")
    a = build_scene(track, Effects.off())
    poses = _poses(track, 6, 21)
    renderer.render_windows(a, poses[0], ROIS)
    b = build_scene(track, Effects())  # the same track: shares a's map, copies level 0
    assert b.tiles.marking is a.tiles.marking and a.tiles.level0_in_atlas
    renderer.render_windows(b, poses[1], ROIS)
    build_scene(generated(3), Effects(), reuse=a)
    assert a.tiles.retired
    assert not np.shares_memory(b.tiles.marking.intensity, a.atlas)
    eager = build_scene(track, Effects(), lazy=False)
    for k, pose in enumerate(poses):
        for got, want in zip(renderer.render_windows(b, pose, ROIS, frame_seed=k),
                             renderer.render_windows(eager, pose, ROIS, frame_seed=k),
                             strict=True):
            np.testing.assert_array_equal(got, want)


def test_a_map_on_its_own_memory_paints_with_the_atlas_s_kernels(renderer: Renderer) -> None:
    """A marking map paints into a scene's atlas (a strided view), or into its own memory
    once that scene is retired, or after a pickle: its intensity is the same array type
    in all three (``paintable_zeros``), so the paint kernels are compiled once (a second
    set cost ≈ 8 s in the middle of the first run after an install)."""
    import pickle

    from tfalda_sim.rendering.renderer import _fill_render
    from tfalda_sim.tracks.raster import _paint_listed, _raster_kernel, paintable_zeros

    own = paintable_zeros((5, 7))
    assert own.shape == (5, 7) and not own.flags.c_contiguous and not own.any()
    track = replace(generated(23), name="own memory")
    a = build_scene(track, Effects.off())
    poses = _poses(track, 3, 23)
    renderer.render_windows(a, poses[0], ROIS)
    b = build_scene(track, Effects())  # shares a's map
    build_scene(generated(3), Effects(), reuse=a)  # a retired: the map on its own memory
    renderer.render_windows(b, poses[1], ROIS)
    marking = b.tiles.marking
    assert not marking.intensity.flags.c_contiguous
    copy = pickle.loads(pickle.dumps(marking))
    assert not copy.intensity.flags.c_contiguous
    np.testing.assert_array_equal(copy.intensity, marking.intensity)
    copy.fill(np.ones(copy.filled.shape, bool))
    # Kernels called from Python in this process (others only inside them): the
    # intensity as _paint_listed's argument, and in the fill tuple of _fill_render (the
    # one it paints into, and the one _store_level0 copies from).
    assert _paint_listed.signatures and _fill_render.signatures
    for kernel, arg in ((_paint_listed, 5), (_raster_kernel, 0)):
        layouts = {str(signature[arg]) for signature in kernel.signatures}
        assert layouts <= {"array(uint8, 2d, A)"}, (kernel.__name__, layouts)
    fills = [signature[1] for signature in _fill_render.signatures]
    layouts = {str(t) for fill in fills for t in (fill.types[3].types[4], fill.types[7])}
    assert layouts == {"array(uint8, 2d, A)"}, layouts


def test_a_fill_that_fails_is_filled_by_the_next_view(renderer: Renderer, monkeypatch) -> None:
    """An error in a fill before its kernel runs (here the worn paint's first use, made
    with the fill's arguments) leaves its tiles unfilled and not marked needed: the next
    view fills them, and equals the eager frame."""
    import tfalda_sim.rendering.scene as scene_module

    track = replace(generated(6), name="failing fill")
    fx = replace(Effects(), wear=0.4)
    lazy = build_scene(track, fx, np.random.default_rng(2))
    eager = build_scene(track, fx, np.random.default_rng(2), lazy=False)
    real = scene_module._wear_remaining
    calls = []

    def fail_once(*args: Any) -> np.ndarray:
        calls.append(1)
        if len(calls) == 1:
            raise MemoryError("simulated")
        return real(*args)

    monkeypatch.setattr(scene_module, "_wear_remaining", fail_once)
    pose = _poses(track, 1, 6)[0]
    with pytest.raises(MemoryError):
        renderer.render_windows(lazy, pose, ROIS)
    assert not lazy.tiles.need.any() and lazy.tiles.n_filled == 0
    for got, want in zip(renderer.render_windows(lazy, pose, ROIS, frame_seed=1),
                         renderer.render_windows(eager, pose, ROIS, frame_seed=1), strict=True):
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("path", ["windows", "full frame"])
def test_an_error_inside_the_fill_kernel_leaves_the_log_counting_filled_tiles(
        renderer: Renderer, monkeypatch, path: str) -> None:
    """An exception raised inside the fill kernel (a MemoryError), after it logged its
    tiles and before it marked them filled (simulated: the kernel's logging, then the
    error, in place of the windows' ``_fill_render`` or the full frame's ``_fill_tiles``),
    leaves the log counting only filled tiles (or it would overflow its room, one entry
    a tile, and count the scene complete too early), nothing marked needed, the tiles it
    logged on the list ``retire`` zeroes; the next views render the eager frames, and
    the scene retires to all-zero memory."""
    import tfalda_sim.rendering.renderer as renderer_module
    import tfalda_sim.rendering.scene as scene_module

    track = replace(generated(24), name=f"error inside a fill ({path})")
    fx = replace(Effects(), wear=0.4)
    lazy = build_scene(track, fx, np.random.default_rng(24))
    eager = build_scene(track, fx, np.random.default_rng(24), lazy=False)
    windows = ROIS if path == "windows" else [(0, 0, 752, 480)]
    module, name = ((renderer_module, "_fill_render") if path == "windows"
                    else (scene_module, "_fill_tiles"))
    real = getattr(module, name)

    def logs_then_fails(n: int, fill: tuple, *rest: Any) -> int:
        queue, written, n_written = fill[:3]
        m = int(n_written[0])
        written[m:m + n] = queue[:n]
        n_written[0] = m + n
        monkeypatch.setattr(module, name, real)
        raise MemoryError("simulated, inside the fill kernel")

    monkeypatch.setattr(module, name, logs_then_fails)
    poses = _poses(track, 3, 24)
    with pytest.raises(MemoryError, match="simulated"):
        renderer.render_windows(lazy, poses[0], windows)
    t = lazy.tiles
    assert not t.need.any()
    assert t.n_filled == np.count_nonzero(t.filled) == 0
    assert len(t._retire_extra) > 0  # what the failed fill logged, maybe written
    for k, pose in enumerate(poses):
        for got, want in zip(renderer.render_windows(lazy, pose, windows, frame_seed=k),
                             renderer.render_windows(eager, pose, windows, frame_seed=k),
                             strict=True):
            np.testing.assert_array_equal(got, want)
    assert t.n_filled == np.count_nonzero(t.filled) > 0
    assert sorted(t._written[:t.n_filled].tolist()) == np.flatnonzero(t.filled).tolist()
    memory = memory_of(lazy.atlas)
    assert memory is not None and np.frombuffer(memory, np.uint8).any()
    build_scene(generated(16), Effects(), reuse=lazy)
    assert not np.frombuffer(memory, np.uint8).any()


FULL_FRAME = [(0, 0, 752, 480)]
"""A full frame: rendered kernel by kernel (``Scene.prepare`` lists the tiles, then
``_fill_tiles`` fills them), where the ROIs take ``_render_lazy``, which lists them
itself, then ``_fill_render``, which fills them and renders."""

KERNELS_CALLED_FROM_PYTHON = [("_needed_tiles", FULL_FRAME), ("_render_lazy", ROIS),
                              ("_fill_tiles", FULL_FRAME), ("_fill_render", ROIS)]
"""Where a lazy scene's kernels return to Python (where a Ctrl-C can land), and the
windows that take that path."""


@pytest.mark.parametrize(("where", "windows"), KERNELS_CALLED_FROM_PYTHON)
def test_a_ctrl_c_as_a_fill_kernel_returns_leaves_consistent_state(
        renderer: Renderer, monkeypatch, where: str, windows: list) -> None:
    """A Ctrl-C is raised when the kernel running at that moment returns, after it
    changed the arrays: after listing the needed tiles (``_needed_tiles`` for a frame
    rendered kernel by kernel, ``_render_lazy`` for windows), after filling them
    (``_fill_tiles``; ``_fill_render``, which renders the windows too). In each case
    nothing stays marked needed (or those tiles would never be listed again), the filled
    count matches ``filled`` (or the scene would never count as complete), every tile
    filled or painted into the atlas is on the lists a retiring scene zeroes, and the
    next view renders the eager frames."""
    import tfalda_sim.rendering.renderer as renderer_module
    import tfalda_sim.rendering.scene as scene_module

    track = replace(generated(8), name=f"interrupted at {where}")
    lazy = build_scene(track, Effects(), np.random.default_rng(4))
    eager = build_scene(track, Effects(), np.random.default_rng(4), lazy=False)
    module = scene_module if where in ("_needed_tiles", "_fill_tiles") else renderer_module
    real = getattr(module, where)
    calls = []

    def interrupted(*args: Any) -> Any:
        out = real(*args)
        calls.append(1)
        if len(calls) == 1:
            raise KeyboardInterrupt
        return out

    monkeypatch.setattr(module, where, interrupted)
    pose = _poses(track, 1, 8)[0]
    with pytest.raises(KeyboardInterrupt):
        renderer.render_windows(lazy, pose, windows)
    listing_only = where in ("_needed_tiles", "_render_lazy")
    t = lazy.tiles
    assert not t.need.any()
    assert t.n_filled == np.count_nonzero(t.filled)
    assert (t.n_filled > 0) == (not listing_only)
    assert set(np.flatnonzero(t.filled).tolist()) == set(t._written[:t.n_filled].tolist())
    # The marking map's own list (what a scene sharing the map zeroes when it retires).
    painted = np.flatnonzero(t.marking.filled)
    assert (len(painted) > 0) == (not listing_only)
    assert set(painted.tolist()) <= set(t.marking.painted_tiles().tolist())
    for got, want in zip(renderer.render_windows(lazy, pose, windows, frame_seed=1),
                         renderer.render_windows(eager, pose, windows, frame_seed=1),
                         strict=True):
        np.testing.assert_array_equal(got, want)
    assert t.n_filled == np.count_nonzero(t.filled) > 0 and not t.need.any()


def _tile_rows_of(t: MipTiles, index: int) -> np.ndarray:
    """The atlas rows ``(level, rows [texels], columns slice, marked)`` of tile ``index``."""
    lv = int(np.searchsorted(t.offsets, index, side="right") - 1)
    tr, tc = divmod(index - int(t.offsets[lv]), int(t.grids[lv, 1]))
    size = int(t.tile[lv])
    x, y = (int(v) for v in t.origins[lv])
    n_rows = min(size, int(t.sizes[lv, 0]) - tr * size)
    cols = slice(x + tc * size, x + min((tc + 1) * size, int(t.sizes[lv, 1])))
    mask = int(t._level0_rows()[index] if lv == 0 else t.nonzero_rows[index])
    marked = np.array([bool(mask & (1 << k)) if k < 64 else mask != 0 for k in range(n_rows)])
    return lv, np.arange(y + tr * size, y + tr * size + n_rows), cols, marked


@pytest.mark.parametrize("kind", ["default", "randomised"])
def test_row_masks_of_every_level_cover_its_non_zero_rows(renderer: Renderer,
                                                          kind: str) -> None:
    """After views of a lazy scene (level 0 painted in the atlas, or worn and copied in),
    every filled tile of every level holds zeros in the rows its mask leaves unmarked
    (the mips skip reading them, ``retire`` skips clearing them), and the masks leave
    most rows of the tiles a view fills unmarked."""
    track = replace(generated(14), name=f"row masks {kind}")
    fx, scene_seed = _effects(kind, 14)
    lazy = build_scene(track, fx, np.random.default_rng(scene_seed))
    for k, pose in enumerate(_poses(track, 5, 14)):
        renderer.render_windows(lazy, pose, ROIS, frame_seed=k)
    t = lazy.tiles
    assert t.level0_in_atlas == (kind == "default")
    unmarked = marked = 0
    levels = set()
    for index in np.flatnonzero(t.filled):
        lv, rows, cols, keep = _tile_rows_of(t, int(index))
        block = lazy.atlas[rows, cols]
        assert not block[~keep].any(), (lv, index)
        unmarked += int((~keep).sum())
        marked += int(keep.sum())
        levels.add(lv)
    assert {0, 1, 2} <= levels
    assert unmarked > marked  # most rows need neither a read nor a clear


@pytest.mark.parametrize("kind", ["default", "worn"])  # worn: level 0 copied in
@pytest.mark.parametrize(("where", "windows"), KERNELS_CALLED_FROM_PYTHON[2:])
def test_a_scene_interrupted_in_a_fill_retires_to_all_zero_memory(
        renderer: Renderer, monkeypatch, where: str, windows: list, kind: str) -> None:
    """A Ctrl-C raised as a fill kernel returns (the tiles listed, painted or copied in,
    the mips made, maybe the windows rendered too): the scene, retired, still hands over
    all-zero memory (every tile written is on its list)."""
    import tfalda_sim.rendering.renderer as renderer_module
    import tfalda_sim.rendering.scene as scene_module

    track = replace(generated(15), name=f"interrupted {where} {kind}")
    fx, scene_seed = (replace(Effects(), wear=0.4), 15) if kind == "worn" else (Effects(), 0)
    lazy = build_scene(track, fx, np.random.default_rng(scene_seed))
    renderer.render_windows(lazy, _poses(track, 1, 1)[0], ROIS)  # some tiles filled first
    module = renderer_module if where == "_fill_render" else scene_module
    real = getattr(module, where)

    def interrupted(*args: Any) -> Any:
        real(*args)  # the kernel's work done, then the Ctrl-C
        raise KeyboardInterrupt

    monkeypatch.setattr(module, where, interrupted)
    with pytest.raises(KeyboardInterrupt):
        renderer.render_windows(lazy, _poses(track, 1, 2)[0], windows)
    monkeypatch.setattr(module, where, real)
    memory = memory_of(lazy.atlas)
    assert memory is not None and np.frombuffer(memory, np.uint8).any()
    build_scene(generated(16), Effects(), reuse=lazy)
    assert lazy.tiles.retired
    assert not np.frombuffer(memory, np.uint8).any()


def test_a_scene_pickled_before_the_row_masks_renders_the_eager_frames(
        renderer: Renderer) -> None:
    """A lazy scene pickled before the row masks existed loads with every row of every
    tile marked (nothing skipped: the old behaviour) and goes on rendering the eager
    frames."""
    import pickle

    track = replace(generated(17), name="pickled before the row masks")
    lazy = build_scene(track, Effects.off())
    eager = build_scene(track, Effects.off(), lazy=False)
    poses = _poses(track, 5, 17)
    renderer.render_windows(lazy, poses[0], ROIS)
    twin = pickle.loads(pickle.dumps(lazy))
    for obj, cls in ((twin.tiles, MipTiles), (twin.tiles.marking, TiledMarkingMap)):
        state = obj.__dict__.copy()
        del state["nonzero_rows"]
        obj.__dict__.clear()
        cls.__setstate__(obj, state)
        assert (obj.nonzero_rows == -1).all()
    for k, pose in enumerate(poses[1:]):
        for got, want in zip(renderer.render_windows(twin, pose, ROIS, frame_seed=k),
                             renderer.render_windows(eager, pose, ROIS, frame_seed=k),
                             strict=True):
            np.testing.assert_array_equal(got, want)


def test_a_pickled_lazy_scene_keeps_its_fill_log_without_its_spare_room(
        renderer: Renderer) -> None:
    """A lazy scene's pickle holds the tiles it filled, not the log's room for every tile
    of the map (≈ 8 bytes a tile, ~10⁵ tiles); the copy gets that room back, fills on
    and renders the eager frames."""
    import pickle

    track = replace(generated(19), name="pickled fill log")
    lazy = build_scene(track, Effects.off())
    eager = build_scene(track, Effects.off(), lazy=False)
    poses = _poses(track, 4, 19)
    renderer.render_windows(lazy, poses[0], ROIS)
    t = lazy.tiles
    n = t.n_filled
    assert 0 < n < len(t.filled) // 10
    assert len(t._written) == len(t.filled)  # room for every tile of the map
    np.testing.assert_array_equal(t.__getstate__()["_written"], t._written[:n])
    twin = pickle.loads(pickle.dumps(lazy))
    assert len(twin.tiles._written) == len(twin.tiles.filled)
    assert twin.tiles.n_filled == n
    np.testing.assert_array_equal(twin.tiles._written[:n], t._written[:n])
    for k, pose in enumerate(poses[1:]):
        for got, want in zip(renderer.render_windows(twin, pose, ROIS, frame_seed=k),
                             renderer.render_windows(eager, pose, ROIS, frame_seed=k),
                             strict=True):
            np.testing.assert_array_equal(got, want)
    assert twin.tiles.n_filled == np.count_nonzero(twin.tiles.filled) > n


def test_a_retired_scene_pickled_before_the_fill_log_does_not_render(
        renderer: Renderer) -> None:
    """A scene retired and pickled with the earlier bookkeeping (its fill marks kept, all
    filled) loads retired and not complete: rendering it raises the retired scene's
    error instead of reading its atlas."""
    import pickle

    track = replace(generated(20), name="retired, pickled before the log")
    lazy = build_scene(track, Effects.off())
    lazy.fill_all()
    twin = pickle.loads(pickle.dumps(lazy))
    t = twin.tiles
    state = t.__dict__.copy()
    for name in ("_written", "_n_written", "_retire_extra", "_fill_args", "_walls_complete"):
        del state[name]
    state.update(n_filled=len(t.filled), complete=False, _tiles_complete=False,
                 _written_runs=[np.flatnonzero(t.filled)], retired=True)
    t.__dict__.clear()
    MipTiles.__setstate__(t, state)
    assert t.retired and t.filled.all() and t.wall_filled.all()
    assert not t.complete
    with pytest.raises(RuntimeError, match="retired"):
        renderer.render_windows(twin, _poses(track, 1, 20)[0], ROIS)


def test_a_shallow_copy_of_the_tiles_keeps_its_own_fill_count(renderer: Renderer) -> None:
    """``copy.copy`` of a scene's tiles gets its own log and its own count of it: fills of
    the original do not make the copy's log list entries it never held."""
    import copy

    track = replace(generated(21), name="shallow copy")
    lazy = build_scene(track, Effects.off())
    poses = _poses(track, 3, 21)
    renderer.render_windows(lazy, poses[0], ROIS)
    t = lazy.tiles
    twin = copy.copy(t)
    n = twin.n_filled
    for pose in poses[1:]:
        renderer.render_windows(lazy, pose, ROIS)
    assert t.n_filled > n == twin.n_filled
    np.testing.assert_array_equal(twin._written[:n], t._written[:n])


@pytest.mark.parametrize("layout", ["fill lists", "no lists"])
def test_a_scene_pickled_before_the_fill_log_renders_and_lists_what_retire_zeroes(
        renderer: Renderer, layout: str) -> None:
    """A lazy scene pickled with the earlier fill bookkeeping (a list of arrays of the
    tiles each fill listed, a filled count and flags; or before that none of them) loads
    with a log of its filled tiles, keeps the listed tiles a fill left unfilled (an
    interrupted one) for ``retire`` to zero, fills what it lacks and renders the eager
    frames, then counts as complete once all is filled."""
    import pickle

    track = replace(generated(18), name=f"pickled with {layout}")
    lazy = build_scene(track, Effects.off())
    eager = build_scene(track, Effects.off(), lazy=False)
    poses = _poses(track, 4, 18)
    renderer.render_windows(lazy, poses[0], ROIS)
    twin = pickle.loads(pickle.dumps(lazy))
    t = twin.tiles
    filled = np.flatnonzero(t.filled)
    unfilled = np.flatnonzero(t.filled == 0)[:3]  # listed by a fill that was interrupted
    state = t.__dict__.copy()
    for name in ("_written", "_n_written", "_retire_extra", "_fill_args", "_walls_complete"):
        del state[name]
    if layout == "fill lists":
        state.update(n_filled=len(filled), complete=False, _tiles_complete=False,
                     _written_runs=[filled[:5], filled, unfilled])
    t.__dict__.clear()
    MipTiles.__setstate__(t, state)
    assert t.n_filled == len(filled) and not t.complete
    assert sorted(t._written[:t.n_filled].tolist()) == filled.tolist()
    expected_extra = unfilled.tolist() if layout == "fill lists" else []
    assert t._retire_extra.tolist() == expected_extra
    for k, pose in enumerate(poses[1:]):
        for got, want in zip(renderer.render_windows(twin, pose, ROIS, frame_seed=k),
                             renderer.render_windows(eager, pose, ROIS, frame_seed=k),
                             strict=True):
            np.testing.assert_array_equal(got, want)
    assert t.n_filled == np.count_nonzero(t.filled) > len(filled)
    twin.fill_all()
    assert t.complete
    np.testing.assert_array_equal(twin.atlas, eager.atlas)


@pytest.mark.parametrize("where", ["_zero_tiles", "detach"])
def test_a_ctrl_c_while_a_scene_retires_leaves_its_marking_map_right(
        renderer: Renderer, monkeypatch, where: str) -> None:
    """A Ctrl-C as the retiring scene's clear returns, or as its marking map's ``detach``
    returns: the next scene on that track (which shares the map) still renders the eager
    frames. Before, the map could count as painted the tiles just cleared."""
    import tfalda_sim.rendering.scene as scene_module
    from tfalda_sim.tracks.raster import TiledMarkingMap

    track = replace(generated(18), name=f"retire interrupted at {where}")
    pose = _poses(track, 1, 18)[0]
    a = build_scene(track, Effects())
    renderer.render_windows(a, pose, ROIS)
    assert a.tiles.level0_in_atlas and a.tiles.marking.filled.any()
    module = scene_module if where == "_zero_tiles" else TiledMarkingMap
    real = getattr(module, where)
    calls = []

    def interrupted(*args: Any) -> Any:
        real(*args)  # done, then the Ctrl-C
        calls.append(1)
        raise KeyboardInterrupt

    monkeypatch.setattr(module, where, interrupted)
    with pytest.raises(KeyboardInterrupt):
        build_scene(generated(19), Effects(), reuse=a)
    monkeypatch.setattr(module, where, real)
    assert calls and a.tiles.retired
    fx = replace(Effects(), wear=0.3)
    b = build_scene(track, fx, np.random.default_rng(1))
    eager = build_scene(track, fx, np.random.default_rng(1), lazy=False)
    for got, want in zip(renderer.render_windows(b, pose, ROIS, frame_seed=1),
                         renderer.render_windows(eager, pose, ROIS, frame_seed=1), strict=True):
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("kind", ["default", "randomised"])
def test_prefill_fills_what_the_render_fills_and_the_render_stays_the_same(
        kind: str) -> None:
    """``Renderer.prefill`` (a vector env's lane painting a next episode's first frame
    ahead): it fills exactly the tiles (of every level) and wall rows a render of those
    windows at that pose fills, renders nothing, leaves the renderer's current scene as
    it was, and the render after it fills nothing more and equals the render of a scene
    that was not prefilled; an eager scene is left alone."""
    track = generated(7)
    fx, scene_seed = _effects(kind, 7)
    renderer = Renderer()
    views = (ROIS, ROIS[2:], [(0, 0, 752, 480)])
    for k, (pose, windows) in enumerate(zip(_poses(track, 3, 5), views, strict=True)):
        plain = build_scene(track, fx, np.random.default_rng(scene_seed))
        ahead = build_scene(track, fx, np.random.default_rng(scene_seed))
        want = renderer.render_windows(plain, pose, windows, frame_seed=k)
        current = renderer._current
        renderer.prefill(ahead, pose, windows)
        assert renderer._current is current  # the scene last rendered stays current
        assert ahead.tiles.n_filled > 0
        np.testing.assert_array_equal(ahead.tiles.filled, plain.tiles.filled)
        np.testing.assert_array_equal(ahead.tiles.wall_filled, plain.tiles.wall_filled)
        filled = ahead.tiles.n_filled
        got = renderer.render_windows(ahead, pose, windows, frame_seed=k)
        assert ahead.tiles.n_filled == filled  # nothing was left to paint
        for w, g in zip(want, got, strict=True):
            np.testing.assert_array_equal(g, w)
    eager = build_scene(track, fx, np.random.default_rng(scene_seed), lazy=False)
    atlas = eager.atlas.copy()
    renderer.prefill(eager, _poses(track, 1, 0)[0], ROIS)
    np.testing.assert_array_equal(eager.atlas, atlas)
    with pytest.raises(ValueError, match="finite"):
        renderer.prefill(build_scene(track, fx), (0.0, float("nan"), 0.0), ROIS)
    with pytest.raises(ValueError, match="inside"):
        renderer.prefill(build_scene(track, fx), (0.0, 0.0, 0.0), [(700, 0, 100, 10)])
