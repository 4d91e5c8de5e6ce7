"""Exact ground truth of a camera frame, drawn from the track's geometry.

The thesis painted every marking of its test images by hand, the dashed centre line as a
continuous one (ch. 4); here each visible marking is projected from the track model. The
label image uses ``tfalda_sim.tracks.Marking`` ids; the ego lane's two boundaries (the centre line
and the right side line) come as pixel polylines, the reference for a lane detector.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cv2
import numpy as np

from tfalda_sim.tracks import Marking, Track
from tfalda_sim.tracks.dimensions import LINE_WIDTH_M, START_LINE_WIDTH_M, STOP_LINE_WIDTH_M
from tfalda_sim.tracks.rules import obstacle_corners

from ..camera import Bonnet, Camera
from .obstacles import BoxFaces, obstacle_faces

TRUTH_STEP_M: float = 0.02
"""Arc-length step [m] of the polylines the markings are drawn from."""

TRUTH_RANGE_M: float = 8.0
"""Markings farther from the camera than this [m] are left out (a few pixels at most)."""

EGO_AHEAD_M: float = 3.0
"""How far ahead of the camera [m] the ego lane's boundaries are given."""

_TRUTH_BGR = {Marking.RIGHT_LINE: (0, 0, 255), Marking.CENTRE_LINE: (0, 255, 255),
              Marking.LEFT_LINE: (255, 0, 0), Marking.START_LINE: (0, 255, 0),
              Marking.STOP_LINE: (255, 0, 255), Marking.OBSTACLE: (128, 128, 128)}


@dataclass(frozen=True)
class FrameTruth:
    """Ground truth of one frame: ``labels`` ``(H, W)`` uint8 ``Marking`` ids, and the ego
    lane's left (centre line) and right (side line) boundaries as ``(N, 2)`` pixels."""

    labels: np.ndarray
    left_boundary_px: np.ndarray
    right_boundary_px: np.ndarray

    def colour(self) -> np.ndarray:
        """BGR picture of the labels (right red, centre yellow, left blue, start green,
        stop magenta, obstacle grey)."""
        out = np.zeros((*self.labels.shape, 3), np.uint8)
        for mark, bgr in _TRUTH_BGR.items():
            out[self.labels == mark] = bgr
        return out


@functools.lru_cache(maxsize=8)
def _line_samples(track: Track) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Arc lengths and, per line (right, centre, left), the two edges ``(3, 2, N, 3)`` [m]
    and whether the line is painted there ``(3, N)``: the dashed centre counts as
    continuous, rule gaps and crossings do not."""
    total = track.length_m
    n = max(2, math.ceil(total / TRUTH_STEP_M))
    s = np.linspace(0.0, total, n + 1)
    edges = np.zeros((3, 2, len(s), 3))
    painted = np.ones((3, len(s)), bool)
    half_road = track.half_road_m
    for li, line in enumerate(("right", "centre", "left")):
        d = (li - 1) * track.lane_width_m
        for e, side in enumerate((-0.5, 0.5)):
            edges[li, e, :, :2] = track.position(s, d + side * LINE_WIDTH_M)
        for g in track.gaps:
            if g.line.value == line:
                for shift in ((-total, 0.0, total) if track.closed else (0.0,)):
                    painted[li] &= ~((s >= g.s_m + shift) & (s <= g.s_m + g.length_m + shift))
        for x in track.intersections:
            for sx in (x.s1_m, x.s2_m):
                for shift in ((-total, 0.0, total) if track.closed else (0.0,)):
                    painted[li] &= ~((s > sx - half_road + shift) & (s < sx + half_road + shift))
    return s, edges, painted


def _cross_band(track: Track, s_lo: float, s_hi: float, d_lo: float, d_hi: float) -> np.ndarray:
    """Outline ``(M, 3)`` [m] of a band across the road (start or stop line)."""
    d = np.linspace(d_lo, d_hi, 12)
    near = track.position(np.full_like(d, s_lo), d)
    far = track.position(np.full_like(d, s_hi), d[::-1])
    pts = np.zeros((2 * len(d), 3))
    pts[:, :2] = np.vstack([near, far])
    return pts


def frame_truth(track: Track, camera: Camera, pose: tuple[float, float, float], *,
                bonnet: Bonnet | None = None, s_hint_m: float | None = None) -> FrameTruth:
    """Ground truth for a car at ``pose = (x [m], y [m], yaw [rad])`` on ``track`` (the
    camera's own bonnet unless ``bonnet`` is given)."""
    bonnet = bonnet or camera.bonnet
    h, w = camera.height, camera.width
    labels = np.zeros((h, w), np.uint8)
    x, y, yaw = pose
    cam_xy = np.array([x + math.cos(yaw) * camera.mount.forward_m,
                       y + math.sin(yaw) * camera.mount.forward_m])

    def to_px(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        cam_pts = camera.world_to_camera(points, pose)
        return camera.project(cam_pts), cam_pts[:, 2] > 0.05

    _, edges, painted = _line_samples(track)
    for li, mark in enumerate((Marking.RIGHT_LINE, Marking.CENTRE_LINE, Marking.LEFT_LINE)):
        near = np.hypot(*(edges[li, 0, :, :2] - cam_xy).T) < TRUTH_RANGE_M
        keep = near & painted[li]
        if not np.any(keep):
            continue
        idx = np.flatnonzero(keep)
        a_uv, a_ok = to_px(edges[li, 0, idx])
        b_uv, b_ok = to_px(edges[li, 1, idx])
        ok = a_ok & b_ok
        # One polygon per unbroken run of samples (a strip: one edge out, the other
        # back): the same outline as the run's quads, drawn in one call.
        sel = np.flatnonzero(ok)
        for run in np.split(sel, np.flatnonzero(np.diff(idx[sel]) != 1) + 1):
            if len(run) < 2:
                continue
            strip = np.concatenate([a_uv[run], b_uv[run][::-1]])
            cv2.fillPoly(labels, [np.rint(strip * 16).astype(np.int32)], int(mark),
                         lineType=cv2.LINE_8, shift=4)
    bands: list[tuple[np.ndarray, Marking]] = []
    half_road = track.half_road_m
    if track.start_line_s_m is not None:
        s0 = track.start_line_s_m
        bands.append((_cross_band(track, s0 - START_LINE_WIDTH_M / 2, s0 + START_LINE_WIDTH_M / 2,
                                  -half_road, half_road), Marking.START_LINE))
    for inter in track.intersections:
        for sx in (inter.s1_m, inter.s2_m):
            bands.append((_cross_band(track, sx - half_road - STOP_LINE_WIDTH_M, sx - half_road,
                                      -half_road, 0.0), Marking.STOP_LINE))
            bands.append((_cross_band(track, sx + half_road, sx + half_road + STOP_LINE_WIDTH_M,
                                      0.0, half_road), Marking.STOP_LINE))
    for outline, mark in bands:
        if np.min(np.hypot(*(outline[:, :2] - cam_xy).T)) > TRUTH_RANGE_M:
            continue
        uv, ok = to_px(outline)
        if np.all(ok):
            cv2.fillPoly(labels, [np.rint(uv * 16).astype(np.int32)], int(mark),
                         lineType=cv2.LINE_8, shift=4)
    # What the camera cannot see: the cartons' fronts hide the road behind them.
    boxes = np.zeros((len(track.obstacles), 8, 3))
    for k, ob in enumerate(track.obstacles):
        boxes[k, :4, :2] = boxes[k, 4:, :2] = obstacle_corners(track, k)
        boxes[k, 4:, 2] = ob.height_m
    for uv, _ in obstacle_faces(camera, BoxFaces.of(boxes), pose):
        cv2.fillPoly(labels, [np.rint(uv * 16).astype(np.int32)], int(Marking.OBSTACLE),
                     lineType=cv2.LINE_8, shift=4)
    edge_row = bonnet.edge(np.arange(w), w, h)
    if bonnet.enabled:
        labels[np.arange(h)[:, None] >= edge_row[None, :]] = 0
    left, right = _ego_boundaries(track, camera, pose, edge_row, s_hint_m)
    return FrameTruth(labels, left, right)


def ego_boundaries(track: Track, camera: Camera, pose: tuple[float, float, float], *,
                   bonnet: Bonnet | None = None, s_hint_m: float | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The ego lane's left (centre line) and right (side line) boundaries in the image as
    ``(N, 2)`` pixels, without the label image (``frame_truth``'s boundaries, for
    recordings: a tenth of its cost)."""
    bonnet = bonnet or camera.bonnet
    edge_row = bonnet.edge(np.arange(camera.width), camera.width, camera.height)
    return _ego_boundaries(track, camera, pose, edge_row, s_hint_m)


def _ego_boundaries(track: Track, camera: Camera, pose: tuple[float, float, float],
                    edge_row: np.ndarray, s_hint_m: float | None) -> tuple[np.ndarray, np.ndarray]:
    x, y, yaw = pose
    cam_x = x + math.cos(yaw) * camera.mount.forward_m
    cam_y = y + math.sin(yaw) * camera.mount.forward_m
    loc = track.locate(cam_x, cam_y, s_hint_m=s_hint_m)
    s = loc.s_m + np.arange(0.05, EGO_AHEAD_M, TRUTH_STEP_M)
    if not track.closed:
        s = s[s <= track.length_m]
    result = []
    for d in (0.0, -track.lane_width_m):
        pts = np.zeros((len(s), 3))
        if len(s):
            pts[:, :2] = track.position(s, d)
        uv = camera.project_world(pts, pose)
        inside = np.all(np.isfinite(uv), axis=1)
        inside &= (uv[:, 0] >= 0) & (uv[:, 0] <= camera.width - 1) & (uv[:, 1] >= 0)
        cols = np.clip(np.rint(np.nan_to_num(uv[:, 0])).astype(int), 0, camera.width - 1)
        inside &= uv[:, 1] < edge_row[cols]
        result.append(uv[inside])
    return result[0], result[1]
