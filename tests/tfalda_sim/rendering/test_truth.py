"""Per-frame ground truth agrees with the rendered image."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import generated
from tfalda_sim.camera import load_camera
from tfalda_sim.rendering import Effects, Renderer, build_scene, frame_truth
from tfalda_sim.tracks import Marking, load_named

ROIS = {"upper_left": (195, 260, 150, 75), "upper_right": (365, 260, 150, 75),
        "lower_left": (80, 340, 180, 85), "lower_right": (429, 340, 180, 85)}


@pytest.fixture(scope="module")
def renderer() -> Renderer:
    return Renderer()


def pose_on(track, s: float) -> tuple[float, float, float]:
    x, y, h = track.pose(s, -0.5 * track.lane_width_m)
    return float(x), float(y), float(h)


def test_labels_sit_on_the_painted_lines(renderer: Renderer) -> None:
    track = load_named("oval")
    pose = pose_on(track, 1.5)
    frame = renderer.render(build_scene(track, Effects.off()), pose)
    truth = frame_truth(track, renderer.camera, pose)
    near = np.zeros_like(truth.labels, bool)
    near[300:440] = True  # rows where lines are several pixels wide
    for mark in (Marking.RIGHT_LINE, Marking.LEFT_LINE):
        px = frame[(truth.labels == mark) & near]
        assert len(px) > 300 and np.median(px) > 150
    bare = (truth.labels == 0) & near
    assert np.percentile(frame[bare], 95) < 120


def test_dashed_centre_line_is_labelled_continuous(renderer: Renderer) -> None:
    track = load_named("straight")
    pose = pose_on(track, 1.0)
    truth = frame_truth(track, renderer.camera, pose)
    frame = renderer.render(build_scene(track, Effects.off()), pose)
    left = truth.left_boundary_px
    rows = [int(v) for _, v in left if 280 < v < 430]
    labelled = [np.any(truth.labels[r] == Marking.CENTRE_LINE) for r in rows]
    assert all(labelled)  # no gaps in the label, though the paint has gaps
    painted = [frame[r, int(np.interp(r, left[::-1, 1], left[::-1, 0]))] > 100 for r in rows]
    assert 0.2 < np.mean(painted) < 0.9


def test_ego_boundaries_follow_the_lane_and_avoid_the_bonnet(renderer: Renderer) -> None:
    track = load_named("left-curve")
    pose = pose_on(track, 2.0)
    truth = frame_truth(track, renderer.camera, pose)
    assert len(truth.left_boundary_px) > 20 and len(truth.right_boundary_px) > 20
    for pts, mark in ((truth.left_boundary_px, Marking.CENTRE_LINE),
                      (truth.right_boundary_px, Marking.RIGHT_LINE)):
        on = [truth.labels[int(round(v)), int(round(u))] == mark for u, v in pts if v > 240]
        assert np.mean(on) > 0.9
    assert truth.labels[460:].max() == 0  # under the bonnet nothing is visible


@pytest.mark.parametrize("name", ROIS)
def test_thesis_rois_hold_the_ego_lane_markings_in_rendered_truth(renderer: Renderer,
                                                                  name: str) -> None:
    track = load_named("straight")
    truth = frame_truth(track, renderer.camera, pose_on(track, 1.0))
    x, y, w, h = ROIS[name]
    mark = Marking.CENTRE_LINE if name.endswith("left") else Marking.RIGHT_LINE
    window = truth.labels[y:y + h, x:x + w]
    assert (window == mark).any(axis=1).all()  # the marking crosses every ROI row


def test_intersection_stop_lines_and_obstacles_in_truth(renderer: Renderer) -> None:
    track = generated(3)
    x = track.intersections[0]
    truth = frame_truth(track, renderer.camera, pose_on(track, x.s1_m - 1.2))
    assert (truth.labels == Marking.STOP_LINE).sum() > 50
    ob = track.obstacles[0]
    truth = frame_truth(track, renderer.camera, pose_on(track, ob.s_m - 1.0))
    assert (truth.labels == Marking.OBSTACLE).sum() > 100


def test_the_ego_boundaries_alone_are_frame_truths() -> None:
    from tfalda_sim.rendering.truth import ego_boundaries

    track = load_named("oval")
    camera = load_camera("reference-car")
    for pose in ((0.5, -0.2, 0.0), (3.0, -0.25, 0.1)):
        truth = frame_truth(track, camera, pose)
        left, right = ego_boundaries(track, camera, pose)
        np.testing.assert_array_equal(left, truth.left_boundary_px)
        np.testing.assert_array_equal(right, truth.right_boundary_px)
        assert len(left) > 10
