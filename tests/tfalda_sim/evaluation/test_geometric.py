"""The hit rate from the track geometry agrees with the thesis' painted-truth hit rate."""

from __future__ import annotations

import numpy as np

from tfalda_sim.evaluation import ScenarioKind, thesis_scenario
from tfalda_sim.evaluation.geometric import geometric_hit_rates
from tfalda_sim.evaluation.metrics import score_frame
from tfalda_sim.perception import TfaldaDetector
from tfalda_sim.rendering import Effects, Renderer, build_scene, frame_truth


def test_geometric_hit_rate_matches_the_label_image_hit_rate() -> None:
    renderer = Renderer()
    scenario = thesis_scenario(ScenarioKind.CURVE)
    scene = build_scene(scenario.track, Effects(), np.random.default_rng(0))
    det = TfaldaDetector()
    painted, geometric, shifted = [], [], []
    for k in range(0, len(scenario.trajectory), 4):
        pose = scenario.trajectory.pose(k)
        obs = det.process(renderer.render(scene, pose, frame_seed=k))
        truth = frame_truth(scenario.track, renderer.camera, pose)
        painted.append(score_frame(obs.lanes, obs.rois, truth).hit_rates)
        geometric.append(geometric_hit_rates(obs.lanes, renderer.geometry, scenario.track,
                                             pose))
        moved = obs.lanes + np.array([30.0, 0.0, 30.0, 0.0])
        shifted.append(geometric_hit_rates(moved, renderer.geometry, scenario.track, pose))
    painted, geometric = np.array(painted), np.array(geometric)
    assert np.abs(painted.mean(axis=0) - geometric.mean(axis=0)).max() < 0.05
    assert np.corrcoef(painted.mean(axis=1), geometric.mean(axis=1))[0, 1] > 0.9
    assert np.mean(shifted) < 0.1  # lanes moved 30 px off the lines miss


def test_points_off_the_ground_miss() -> None:
    renderer = Renderer()
    track = thesis_scenario(ScenarioKind.STRAIGHT).track
    x, y, h = (float(v) for v in track.pose(1.0, -0.2))
    lanes = np.array([[100.0, 10.0, 200.0, 50.0],  # walls
                      [300.0, 470.0, 400.0, 479.0],  # bonnet
                      [np.nan, 300.0, 200.0, 400.0]])  # missing
    assert np.all(geometric_hit_rates(lanes, renderer.geometry, track, (x, y, h))[:2] == 0)
    assert geometric_hit_rates(lanes, renderer.geometry, track, (x, y, h))[2] == 0


def test_the_one_call_kernel_equals_the_numpy_formulation() -> None:
    """``geometric_hit_rates`` runs as one numba call (every env step reports it); it
    equals, bit for bit, the numpy formulation it replaced: sample points located with
    ``Track.locate_many``, distance to the nearest line, per-lane mean of the hits."""
    from tests.conftest import generated
    from tfalda_sim.evaluation.geometric import HIT_SAMPLES, _ground_points
    from tfalda_sim.evaluation.metrics import EPSILON_PX
    from tfalda_sim.tracks.dimensions import LINE_WIDTH_M

    g = Renderer().geometry
    rng = np.random.default_rng(4)
    checked = 0
    for track in (generated(3), generated(8), thesis_scenario(ScenarioKind.CURVE).track):
        for _ in range(20):
            s = rng.uniform(0, track.length_m)
            x, y, h = (float(v) for v in track.pose(s, rng.uniform(-0.3, 0.3)))
            h += rng.uniform(-0.3, 0.3)
            lanes = np.column_stack([rng.uniform(0, 752, 8), rng.uniform(200, 480, 8),
                                     rng.uniform(0, 752, 8), rng.uniform(200, 480, 8)])
            lanes[rng.random(8) < 0.1, 0] = np.nan
            pts, ok, footprint = _ground_points(lanes, g.gx, g.gy, g.rho, g.bonnet,
                                                g.log2_fp, x, y, h, HIT_SAMPLES)
            _, lateral, _ = track.locate_many(pts)
            off_line = np.minimum(np.abs(lateral), np.abs(np.abs(lateral) - track.lane_width_m))
            hit = ok & (off_line <= 0.5 * LINE_WIDTH_M + EPSILON_PX * footprint)
            want = hit.reshape(len(lanes), HIT_SAMPLES).mean(axis=1)
            got = geometric_hit_rates(lanes, g, track, (x, y, h))
            np.testing.assert_array_equal(got, want)
            checked += int(np.count_nonzero((want > 0) & (want < 1)))
    assert checked > 10  # lanes partly on a line, not only all-or-nothing ones
