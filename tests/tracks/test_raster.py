"""Rasterised marking and label maps."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from tfalda_sim.tracks import (
    VIRTUAL,
    Gap,
    Line,
    Marking,
    Pose,
    Straight,
    Track,
    load_named,
    rasterize,
)
from tfalda_sim.tracks.dimensions import LINE_WIDTH_M
from tfalda_sim.tracks.raster import memory_of, untouched_zeros


def strip(heading: float = 0.0, **kw) -> Track:
    return Track((Straight(4.0),), closed=False, start=Pose(0.0, 0.0, heading), **kw)


def value_at(m, track: Track, s: float, lateral: float) -> tuple[int, int]:
    col, row = np.rint(m.world_to_pixel(track.position(s, lateral))).astype(int)
    return int(m.intensity[row, col]), int(m.labels[row, col])


def test_default_resolution_is_at_most_4_mm() -> None:
    assert rasterize(strip()).resolution_m <= 0.004


def test_lines_sit_where_the_model_puts_them() -> None:
    track = strip(0.3)
    m = rasterize(track)
    assert value_at(m, track, 1.0, -0.4) == (255, Marking.RIGHT_LINE)
    assert value_at(m, track, 1.0, 0.4) == (255, Marking.LEFT_LINE)
    assert value_at(m, track, 1.0, -0.2) == (0, Marking.NONE)  # asphalt
    assert value_at(m, track, 1.0, -0.45) == (0, Marking.NONE)  # beyond the road
    assert value_at(m, track, 0.1, 0.0) == (255, Marking.CENTRE_LINE)  # first dash
    assert value_at(m, track, 0.3, 0.0) == (0, Marking.CENTRE_LINE | VIRTUAL)  # dash gap


def test_painted_area_is_conserved_by_anti_aliasing() -> None:
    track = strip(0.37)  # an oblique strip: every line edge is anti-aliased
    m = rasterize(track)
    painted = m.intensity.astype(np.float64).sum() / 255.0 * m.resolution_m**2
    expected = LINE_WIDTH_M * track.length_m * (2 + 0.5)  # two solid lines, half a dashed one
    assert painted == pytest.approx(expected, rel=0.01)
    edge = (m.intensity > 0) & (m.intensity < 255)
    assert edge.sum() > 0.3 * (m.intensity == 255).sum()


def test_gap_leaves_a_virtual_line() -> None:
    track = strip(gaps=(Gap(Line.LEFT, 1.0, 0.8),))
    m = rasterize(track)
    assert value_at(m, track, 1.4, 0.4) == (0, Marking.LEFT_LINE | VIRTUAL)
    assert value_at(m, track, 2.2, 0.4) == (255, Marking.LEFT_LINE)


def test_start_line_across_the_road() -> None:
    oval = load_named("oval")
    m = rasterize(oval)
    for lateral in (-0.3, -0.1, 0.1, 0.3):
        assert value_at(m, oval, 0.0, lateral) == (255, Marking.START_LINE)
    assert value_at(m, oval, 0.06, -0.2)[0] == 0


def test_intersection_has_stop_lines_and_no_lines_inside() -> None:
    eight = load_named("figure-eight")
    m = rasterize(eight)
    x = eight.intersections[0]
    half = eight.half_road_m
    for s in (x.s1_m, x.s2_m):
        for lateral in (-0.4, 0.0, 0.4):
            assert value_at(m, eight, s + 0.1, lateral)[0] == 0  # inside the crossing
        assert value_at(m, eight, s - half - 0.02, -0.2) == (255, Marking.STOP_LINE)
        assert value_at(m, eight, s + half + 0.02, 0.2) == (255, Marking.STOP_LINE)
        assert value_at(m, eight, s - half - 0.02, 0.2)[1] != Marking.STOP_LINE
        assert value_at(m, eight, s - half - 0.3, -0.4) == (255, Marking.RIGHT_LINE)


def test_pixel_world_round_trip() -> None:
    m = rasterize(strip())
    pts = np.array([[0.5, 0.1], [3.2, -0.33]])
    assert np.allclose(m.pixel_to_world(m.world_to_pixel(pts)), pts)


def test_curves_are_painted_continuously() -> None:
    curve = load_named("left-curve")
    m = rasterize(curve)
    s = np.linspace(0.05, curve.length_m - 0.05, 400)
    for lateral, label in ((-0.4, Marking.RIGHT_LINE), (0.4, Marking.LEFT_LINE)):
        cols, rows = np.rint(m.world_to_pixel(curve.position(s, lateral))).astype(int).T
        assert np.all(m.intensity[rows, cols] > 200)
        assert np.all(m.labels[rows, cols] == label)


def test_bad_resolution() -> None:
    with pytest.raises(ValueError, match="resolution_m"):
        rasterize(strip(), resolution_m=0.0)
    with pytest.raises(ValueError, match="too large"):
        rasterize(replace(strip(), segments=(Straight(4000.0),)), resolution_m=0.0001)


def test_map_is_deterministic() -> None:
    a, b = rasterize(load_named("figure-eight")), rasterize(load_named("figure-eight"))
    assert np.array_equal(a.intensity, b.intensity) and np.array_equal(a.labels, b.labels)
    assert math.isclose(a.origin_m[0], b.origin_m[0])


# ---------------------------------------------------------------- painted tile by tile
def test_tile_wise_raster_equals_whole_raster() -> None:
    """Tiles painted on demand, in random batches, hold exactly the whole map's values
    (intensity and labels) and the rest stays 0: on generated tracks with cartons, gaps
    and crossings, and on the named ones."""
    from tests.conftest import generated
    from tfalda_sim.tracks.raster import TiledMarkingMap

    rng = np.random.default_rng(0)
    eight = next(generated(s) for s in range(100) if generated(s).intersections)
    for track in (generated(2), generated(9), eight, load_named("thesis"), strip(0.37)):
        whole = rasterize(track)
        for tile_px in (32, 57):
            tiled = TiledMarkingMap(track, tile_px=tile_px)
            for _ in range(3):
                tiled.fill(rng.random(tiled.filled.shape) < 0.3)
            rows, cols = whole.shape
            done = np.repeat(np.repeat(tiled.filled.astype(bool), tile_px, 0), tile_px, 1)
            done = done[:rows, :cols]
            assert 0.2 < done.mean() < 0.9
            np.testing.assert_array_equal(tiled.intensity[done], whole.intensity[done])
            np.testing.assert_array_equal(tiled.labels[done], whole.labels[done])
            assert not tiled.intensity[~done].any() and not tiled.labels[~done].any()
            full = tiled.fill_all()
            assert tiled.complete and full.origin_m == whole.origin_m
            np.testing.assert_array_equal(full.intensity, whole.intensity)
            np.testing.assert_array_equal(full.labels, whole.labels)


def _marked_rows(tiled, index: int) -> np.ndarray:
    """The rows of tile ``index`` its row mask marks (bools, one per pixel row)."""
    t = tiled.tile_px
    tr = index // tiled.filled.shape[1]
    n = min(t, tiled.shape[0] - tr * t)
    mask = int(tiled.nonzero_rows[index])
    return np.array([bool(mask & (1 << k)) if k < 64 else mask != 0 for k in range(n)])


def test_row_masks_mark_every_row_with_paint() -> None:
    """A painted tile's row mask marks every pixel row that holds paint (a lazy scene
    neither reads nor clears the others), and not many more; unpainted tiles have none.
    Tracks with cartons, gaps, crossings and a start line; tiles of 64 px and of 57 (a
    row past a mask's 64 bits, with 96 px tiles, marks the whole tile)."""
    from tests.conftest import generated
    from tfalda_sim.tracks.raster import TiledMarkingMap

    rng = np.random.default_rng(1)
    eight = next(generated(s) for s in range(100) if generated(s).intersections)
    marked_total = painted_total = 0
    for track in (generated(2), eight, load_named("thesis"), strip(0.37)):
        for tile_px in (64, 57, 96):
            tiled = TiledMarkingMap(track, tile_px=tile_px, labels=tile_px != 64)
            tiled.fill(rng.random(tiled.filled.shape) < 0.4)
            flat = tiled.filled.reshape(-1)
            assert not tiled.nonzero_rows[flat == 0].any()
            for index in np.flatnonzero(flat):
                tr, tc = divmod(int(index), tiled.filled.shape[1])
                block = tiled.intensity[tr * tile_px:(tr + 1) * tile_px,
                                        tc * tile_px:(tc + 1) * tile_px]
                painted = block.any(axis=1)
                marked = _marked_rows(tiled, int(index))
                assert not (painted & ~marked).any(), (track.name, tile_px, index)
                if tile_px <= 64:
                    marked_total += int(marked.sum())
                    painted_total += int(painted.sum())
    assert painted_total > 1000
    # A mask marks the rows its spans visit: a few more than hold paint (1.23× here);
    # a tile marked whole would be 3× and more.
    assert marked_total <= 1.5 * painted_total


def test_fill_listed_paints_the_listed_tiles_once_and_refuses_others() -> None:
    """``fill_listed`` paints what is listed and not painted yet (a tile listed twice in a
    call is painted and recorded once; one painted already is neither painted nor
    recorded again),
    leaves the kernel's mask clear, and refuses indices outside the tile grid and arrays
    that are no 1-D int lists before it paints or records anything."""
    from tfalda_sim.tracks.raster import TiledMarkingMap

    track = load_named("oval")
    tiled = TiledMarkingMap(track, labels=False)
    whole = rasterize(track)
    step = tiled.tile_px
    grid = tiled.filled.size
    painted = np.flatnonzero(whole.intensity[::step, ::step])  # tiles of the road, roughly
    some = np.array([painted[0], painted[0], painted[1]], np.int64)
    tiled.fill_listed(some)
    assert np.flatnonzero(tiled.filled).tolist() == sorted({int(t) for t in some})
    assert not tiled._todo.any()
    tiled.fill_listed(some[:1])  # painted already: nothing recorded
    assert tiled.painted_tiles().tolist() == [int(painted[0]), int(painted[1])]
    before = tiled.intensity.copy()
    for bad, error in ((np.array([painted[2], grid]), IndexError),
                       (np.array([painted[2], -1]), IndexError),
                       (np.array([float(painted[2])]), TypeError),
                       (np.array([[painted[2]]]), TypeError)):
        with pytest.raises(error, match=r"tile grid|1-D array of tile indices"):
            tiled.fill_listed(bad)
    assert tiled.filled.sum() == 2 and not tiled._todo.any()
    assert np.array_equal(tiled.intensity, before)
    assert len(tiled.painted_tiles()) == 2  # the refused calls recorded nothing


def test_paint_level0_skips_tiles_past_the_grid_and_old_pickles_keep_their_record() -> None:
    """A scene hands the map its list of all levels' tiles (level 0 first): indices past
    the map's grid (and negative ones) are skipped. A map pickled with the older list of
    painted arrays (a tile twice, or one a Ctrl-C kept from being painted) or with no list
    restores its record: each painted tile once, in order."""
    import pickle

    from tfalda_sim.tracks.raster import TiledMarkingMap

    track = load_named("oval")
    tiled = TiledMarkingMap(track, labels=False)
    grid = tiled.filled.size
    road = np.flatnonzero(rasterize(track).intensity[::tiled.tile_px, ::tiled.tile_px])
    assert tiled.paint_level0(np.array([road[0], -1, road[1], grid, grid + 7], np.int64)) == 2
    assert tiled.painted_tiles().tolist() == [road[0], road[1]]
    assert tiled.paint_level0(np.array([road[1], grid], np.int64)) == 0
    def pickled_before() -> dict:  # a state of its own each time (arrays not shared)
        state = pickle.loads(pickle.dumps(tiled)).__dict__
        del state["_record"], state["_n_record"], state["nonzero_rows"], state["_shape"]
        state["intensity"] = state.pop("_intensity")  # before it was mapped on demand
        return state

    # The older list: a tile twice, and one recorded but never painted (a Ctrl-C).
    old = TiledMarkingMap.__new__(TiledMarkingMap)
    old.__setstate__({**pickled_before(), "_painted": [np.array([road[1], road[0]]),
                                            np.array([road[0], road[2]])]})
    assert old.painted_tiles().tolist() == [road[1], road[0]]
    old.fill_listed(np.array([road[2], road[3]]))
    assert old.painted_tiles().tolist() == [road[1], road[0], road[2], road[3]]
    older = TiledMarkingMap.__new__(TiledMarkingMap)  # before any list: the filled tiles
    older.__setstate__(pickled_before())
    assert older.painted_tiles().tolist() == [road[0], road[1]]
    # Before the row masks: every row of every tile may hold paint; a tile painted after
    # the load gets its own.
    assert (older.nonzero_rows == -1).all()
    assert older.shape == tiled.shape
    np.testing.assert_array_equal(older.intensity, tiled.intensity)
    assert old.nonzero_rows[road[0]] == -1 and old.nonzero_rows[road[3]] not in (0, -1)
    old.fill(np.ones(old.filled.shape, bool))  # each tile recorded once: inside the record
    assert sorted(old.painted_tiles().tolist()) == list(range(grid))


def test_a_map_without_labels_paints_the_same_intensity() -> None:
    """``labels=False`` (a scene's map) writes no labels and the same intensity, tile by
    tile; it cannot become a MarkingMap."""
    from tests.conftest import generated
    from tfalda_sim.tracks import Arc
    from tfalda_sim.tracks.raster import TiledMarkingMap

    rng = np.random.default_rng(1)
    eight = next(generated(s) for s in range(100) if generated(s).intersections)
    gaps = next(generated(s) for s in range(100) if len(generated(s).gaps) >= 2)
    # Without labels, pixels of the side lines in chunks without crossings or gaps take a
    # shortcut (no arc length, no atan2): tight and wide arcs, open strips, gaps, crossings.
    tight = Track((Arc(0.45, 2 * math.pi),), closed=True)
    # Lanes narrower than a line and a pixel: a side line's pixels hold the centre line too.
    narrow = [strip(0.37, lane_width_m=w) for w in (0.015, 0.02, 0.0239)] + [
        Track((Arc(1.0, math.pi), Straight(0.5)), closed=False, lane_width_m=0.02)]
    for track in (generated(4), generated(2), gaps, eight, load_named("thesis"),
                  load_named("oval"), strip(0.37), tight, *narrow):
        with_labels = TiledMarkingMap(track)
        bare = TiledMarkingMap(track, labels=False)
        assert bare.labels is None
        for _ in range(3):
            tiles = rng.random(bare.filled.shape) < 0.3
            with_labels.fill(tiles)
            bare.fill(tiles)
        assert bare.intensity.any()
        np.testing.assert_array_equal(bare.intensity, with_labels.intensity)
        with pytest.raises(ValueError, match="labels=False"):
            bare.fill_all()


def test_crossings_start_lines_and_gaps_paint_without_labels_as_with_them() -> None:
    """Without labels, the pixels of a chunk with a crossing, a start line or a rule gap
    take the plain chunk's values where none of those reaches them, and nothing inside a
    crossing: the same intensity as the labelled map's per-pixel sums, also where the
    elements straddle a closed track's seam or sit near an open track's ends (whose arc
    lengths do not wrap), on arcs and straights."""
    from tests.conftest import generated
    from tfalda_sim.tracks import Arc, Intersection
    from tfalda_sim.tracks.raster import TiledMarkingMap

    oval = load_named("oval")
    total = oval.length_m
    seam = oval.with_elements(
        start_line_s_m=total - 0.03,
        intersections=(Intersection(0.1, 0.1), Intersection(0.5 * total, 0.5 * total)),
        gaps=(Gap(Line.LEFT, total - 0.2, 0.4), Gap(Line.CENTRE, 3.0, 0.5)))
    # A crossing near an open strip's start: on a closed track of the same length its
    # inside would reach round to the other end (here the lines there are painted).
    open_strip = Track((Straight(2.0), Arc(1.5, 1.2), Straight(1.0)), closed=False,
                       start_line_s_m=0.05, intersections=(Intersection(0.2, 0.2),),
                       gaps=(Gap(Line.RIGHT, 4.0, 0.3),))
    crossings = [generated(s) for s in range(60) if generated(s).intersections][:3]
    gaps = [generated(s) for s in range(60) if len(generated(s).gaps) >= 2][:3]
    for track in (seam, open_strip, *crossings, *gaps):
        labelled = TiledMarkingMap(track)
        bare = TiledMarkingMap(track, labels=False)
        everything = np.ones(bare.filled.shape, bool)
        labelled.fill(everything)
        bare.fill(everything)
        np.testing.assert_array_equal(bare.intensity, labelled.intensity)
    # The strip's far end keeps its lines (a crossing's inside does not wrap round).
    m = rasterize(open_strip)
    assert value_at(m, open_strip, open_strip.length_m - 0.1, -open_strip.lane_width_m)[0] == 255


def test_tight_and_wide_arcs_are_painted_whole() -> None:
    """The arc chunks' row spans skip only pixels outside the road: a full circle of a
    tight, a medium and a wide radius paints its lines' whole area."""
    from tfalda_sim.tracks import Arc

    for radius in (0.45, 1.0, 6.0):
        track = Track((Arc(radius, 2 * math.pi),), closed=True)
        m = rasterize(track)
        painted = m.intensity.astype(np.float64).sum() / 255.0 * m.resolution_m**2
        w = LINE_WIDTH_M
        solid = 2 * math.pi * ((radius + 0.4) + max(0.0, radius - 0.4)) * w
        dashed = 0.5 * 2 * math.pi * radius * w
        assert painted == pytest.approx(solid + dashed, rel=0.02), radius


def test_chunk_boxes_hold_every_pixel_a_chunk_paints(eight: Track) -> None:
    """Each chunk's pixel box (``_chunk_boxes``: the bounding box of its footprint, not a
    padded box around its centre line) holds every pixel the kernel paints for it: maps
    painted with those boxes equal maps painted with every box the whole map, labels
    included, on straights at several headings, arcs tighter than the road's half width,
    generated tracks with gaps and crossings, and the named ones."""
    from tests.conftest import generated
    from tfalda_sim.tracks import Arc
    from tfalda_sim.tracks.raster import CHUNK_M, TiledMarkingMap

    tracks = [generated(2), generated(9), eight, load_named("thesis"), load_named("oval"),
              strip(0.37), strip(math.pi / 2), strip(-2.0)]
    tracks += [Track((Arc(r, 2 * math.pi),), closed=True) for r in (0.3, 0.45, 1.7)]
    for track in tracks:
        tight = TiledMarkingMap(track)
        tight.fill_all()
        wide = TiledMarkingMap(track)
        n_chunks = len(tight._boxes)
        wide._boxes = np.tile(np.array([0, wide.shape[0] - 1, 0, wide.shape[1] - 1],
                                       np.int64), (n_chunks, 1))
        wide.fill_all()
        np.testing.assert_array_equal(tight.intensity, wide.intensity)
        np.testing.assert_array_equal(tight.labels, wide.labels)
        assert tight.intensity.any()
    # A road running up the map: a box is a chunk's length high (and a pixel of room
    # each side), not the road's width more.
    up = TiledMarkingMap(strip(math.pi / 2))
    assert up.paint_args  # makes the boxes
    rows = up._boxes[:, 1] - up._boxes[:, 0] + 1
    assert rows.max() <= CHUNK_M / up.resolution_m + 6


def _with_chunk(track: Track, chunk_m: float | None, labels: bool = True):
    """``(intensity, labels)`` of ``track`` painted in chunks of ``chunk_m`` [m] (None: the
    default): whole with labels, else (as a lazy scene paints) in random batches of tiles."""
    from tfalda_sim.tracks.raster import TiledMarkingMap

    tiled = TiledMarkingMap(track, labels=labels)
    if chunk_m is not None:
        tiled._args = (*tiled._args[:-1], chunk_m)
    if labels:
        full = tiled.fill_all()
        return full.intensity, full.labels
    order = np.random.default_rng(0).permutation(tiled.filled.size)
    for batch in np.array_split(order, 9):
        tiled.fill_listed(batch)
    assert tiled.complete
    return tiled.intensity, None


def test_the_map_does_not_depend_on_the_chunk_length(eight: Track) -> None:
    """Chunks are only how the kernel walks the road: maps painted in chunks of 0.1 m,
    0.25 m and the default are equal, labels included, and so are maps without labels
    painted tile batch by tile batch (the plain path a lazy scene takes). A pixel centre on
    a junction of segments once fell outside both by a rounding error with some chunk
    lengths and not others (the thesis track had such a hole in its right line); a seam
    of a closed track and a full turn shorter than a chunk are junctions too."""
    from tests.conftest import generated
    from tfalda_sim.tracks import Arc
    from tfalda_sim.tracks.raster import CHUNK_M

    assert CHUNK_M not in (0.1, 0.25)
    tracks = [load_named("thesis"), load_named("oval"), load_named("left-curve"), eight,
              generated(2), generated(9), strip(0.37),
              Track((Arc(0.3, 2 * math.pi),), closed=True),
              # a circle shorter than one default chunk, its seam on pixel centres
              Track((Arc(0.11399999999999991, 2 * math.pi),), closed=True,
                    start=Pose(0.0, 0.0, math.pi / 2)),
              # and one inside an open track (no seam: the full turn's end is its start)
              Track((Straight(0.5), Arc(0.11399999999999991, 2 * math.pi), Straight(0.5)),
                    closed=False, start=Pose(0.0, 0.0, math.pi / 2))]
    for track in tracks:
        for labels in (True, False):
            intensity, label_map = _with_chunk(track, None, labels)
            for chunk_m in (0.1, 0.25):
                other, other_labels = _with_chunk(track, chunk_m, labels)
                np.testing.assert_array_equal(other, intensity)
                np.testing.assert_array_equal(other_labels, label_map)


def test_solid_lines_have_no_hole_at_a_junction_of_segments() -> None:
    """Across every junction of segments of the named tracks without crossings, the
    side lines' middle is painted in full. The thesis track's grid puts pixel centres
    exactly on the junction of its curve and its last straight (checked here: the case
    this test is for); they belong to both segments' ends."""
    thesis = load_named("thesis")
    m = rasterize(thesis)
    x_junction = float(thesis.table.x0[2])  # where the kernel starts the last straight
    col = (x_junction - m.origin_m[0]) / m.resolution_m - 0.5
    assert col == round(col), "the thesis grid no longer meets a junction: pick a track that does"
    for name in ("thesis", "oval", "left-curve"):
        track = load_named(name)
        m = rasterize(track)
        for s_k in track.table.s0[1:]:
            for lateral in (-track.lane_width_m, track.lane_width_m):
                for s in s_k + np.linspace(-0.02, 0.02, 41):
                    assert value_at(m, track, s, lateral)[0] == 255, (name, s_k, lateral, s)


def test_a_detached_map_paints_fresh_zeros_mapped_when_asked() -> None:
    """``detach`` drops the map's memory (another scene took it) and maps fresh zeros
    only when the intensity is next asked for; the map then paints the same tiles as a
    new map."""
    from tfalda_sim.tracks.raster import TiledMarkingMap

    track = load_named("oval")
    tiled = TiledMarkingMap(track, labels=False)
    tiles = np.arange(0, tiled.filled.size, 7, dtype=np.int64)
    tiled.paint_level0(tiles)
    old = tiled.intensity
    tiled.detach()
    assert tiled._intensity is None and tiled.shape == old.shape
    assert not tiled.filled.any() and not tiled.painted_tiles().size
    assert not tiled.intensity.any() and tiled.intensity is not old
    tiled.paint_level0(tiles)
    fresh = TiledMarkingMap(track, labels=False)
    fresh.paint_level0(tiles)
    np.testing.assert_array_equal(tiled.intensity, fresh.intensity)
    np.testing.assert_array_equal(old, fresh.intensity)


def test_untouched_zeros_takes_memory_it_is_given_or_new_memory_of_the_reserve() -> None:
    a = untouched_zeros((10, 20), reserve_bytes=4096)
    memory = memory_of(a)
    assert a.shape == (10, 20) and not a.any() and len(memory) == 4096
    assert memory_of(untouched_zeros((64, 64), memory)) is memory  # fits: taken
    bigger = memory_of(untouched_zeros((65, 64), memory, reserve_bytes=1000))
    assert bigger is not memory and len(bigger) == 65 * 64  # the size, above the reserve
    assert len(memory_of(untouched_zeros((3, 3)))) == 9  # no reserve: the size


def test_turn_mod_is_pythons_modulo_for_differences_of_two_angles() -> None:
    """``_turn_mod`` (no fmod) equals Python's ``x % 2π`` for every difference of two
    atan2 results, the ends ±2π and values next to 0 and 2π included."""
    from tfalda_sim.tracks.raster import _turn_mod

    rng = np.random.default_rng(3)
    a = rng.uniform(-math.pi, math.pi, 20000)
    b = rng.uniform(-math.pi, math.pi, 20000)
    two_pi = 2.0 * math.pi
    edges = [two_pi, -two_pi, 0.0, 1e-300, -1e-300, np.nextafter(two_pi, 0.0),
             np.nextafter(-two_pi, 0.0), math.pi, -math.pi]
    for x in [*(a - b), *(b - a), *edges]:
        assert _turn_mod(float(x)) == float(x) % two_pi, x
