"""Obstacle cartons in the image: their box faces, projected through the fisheye, culled
(behind the lens, facing away, beyond the hall, outside the requested windows) and drawn
into an index buffer — used by the renderer and the ground truth."""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numba import njit

from ..camera import Camera, LensModel
from .scene import Hall

OBSTACLE_EDGE_STEPS: int = 12
"""Points per box edge when projecting an obstacle's faces (fisheye bends straight edges)."""


@dataclass(frozen=True)
class BoxFaces:
    """The five visible-capable faces (no bottom) of obstacle boxes, precomputed once:
    outlines ``(n, 5, 4·OBSTACLE_EDGE_STEPS, 3)``, outward normals and face centres
    ``(n, 5, 3)``, box centres ``(n, 3)`` [m] and each face's brightness under the hall's
    light relative to white ``(n, 5)`` [-]."""

    outlines: np.ndarray
    normals: np.ndarray
    mids: np.ndarray
    centres: np.ndarray
    shading: np.ndarray

    @classmethod
    def of(cls, boxes: np.ndarray) -> BoxFaces:
        """Faces of boxes ``(n, 8, 3)``: corners 0–3 on the ground, 4–7 above them."""
        boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 8, 3)
        if not len(boxes):  # no cartons (the env's default): the same empty arrays, at once
            return cls(np.zeros((0, 5, 4 * OBSTACLE_EDGE_STEPS, 3)), np.zeros((0, 5, 3)),
                       np.zeros((0, 5, 3)), np.zeros((0, 3)), np.zeros((0, 5)))
        quads = np.array([(4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)])
        pts = boxes[:, quads]  # (n, 5, 4, 3)
        t = np.linspace(0.0, 1.0, OBSTACLE_EDGE_STEPS, endpoint=False)[None, None, None, :, None]
        nxt = np.roll(pts, -1, axis=2)
        outlines = (pts[:, :, :, None] + t * (nxt - pts)[:, :, :, None]).reshape(
            len(boxes), 5, 4 * OBSTACLE_EDGE_STEPS, 3)
        normals = np.cross(pts[:, :, 1] - pts[:, :, 0], pts[:, :, 3] - pts[:, :, 0])
        normals /= np.maximum(np.linalg.norm(normals, axis=-1, keepdims=True), 1e-12)
        mids = pts.mean(axis=2)
        centres = boxes.mean(axis=1)
        flip = np.einsum("nfk,nfk->nf", normals, mids - centres[:, None]) < 0
        normals[flip] *= -1.0
        shading = 0.72 + 0.28 * np.maximum(0.0, normals @ _LIGHT_DIR)
        return cls(np.ascontiguousarray(outlines), normals, mids, centres, shading)


_LIGHT_DIR = np.array([0.3, -0.5, 0.81]) / np.linalg.norm([0.3, -0.5, 0.81])


@njit(cache=True, error_model="numpy")
def _project_faces(outlines: np.ndarray, normals: np.ndarray, mids: np.ndarray,
                   centres: np.ndarray, pose_x: float, pose_y: float, yaw: float,
                   mount_rot: np.ndarray, mount_pos: np.ndarray, K: np.ndarray,
                   D: np.ndarray, pinhole: bool, max_distance_m: float, windows: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Image outlines ``(n, 5, P, 2)`` [px] of the box faces seen from a car at ``(pose_x,
    pose_y)`` [m] heading ``yaw`` [rad] by a camera with the mount's car → camera
    rotation and position [m] (as ``FisheyeCamera.world_to_camera``), their bounding boxes
    ``(n, 5, 4)`` (u_min, v_min, u_max, v_max) [px], whether each face is drawn ``(n, 5)``
    and each box's distance from the camera [m]. A face is drawn when its box
    is within ``max_distance_m``, it faces the camera, all its outline lies in front of
    the lens, and (if ``windows`` ``(k, 4)`` is not empty) its image bounding box, ±2 px
    for the fill's rounding, touches a window. Same formulas as ``FisheyeCamera.project``
    (one loop instead of a dozen temporary arrays: this runs every frame)."""
    n, n_faces, n_pts = outlines.shape[0], outlines.shape[1], outlines.shape[2]
    c, s = math.cos(yaw), math.sin(yaw)
    world_to_car = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    rot = np.zeros((3, 3))  # mount_rot @ world_to_car (no BLAS in numba without SciPy)
    origin = np.array([pose_x, pose_y, 0.0])  # + world_to_car.T @ mount_pos: camera [m]
    for i in range(3):
        for j in range(3):
            for k in range(3):
                rot[i, j] += mount_rot[i, k] * world_to_car[k, j]
            origin[i] += world_to_car[j, i] * mount_pos[j]
    uv = np.full((n, n_faces, n_pts, 2), np.nan)
    bbox = np.zeros((n, n_faces, 4))
    keep = np.zeros((n, n_faces), np.bool_)
    dist = np.empty(n)
    k1, k2, k3, k4 = D[0], D[1], D[2], D[3]  # pinhole: k1, k2, p1, p2 (and k3 = D[4])
    pk3 = D[4] if pinhole else 0.0
    for b in range(n):
        d0 = centres[b, 0] - origin[0]
        d1 = centres[b, 1] - origin[1]
        d2 = centres[b, 2] - origin[2]
        dist[b] = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        if dist[b] > max_distance_m:
            continue
        for f in range(n_faces):
            facing = 0.0
            for k in range(3):
                facing += normals[b, f, k] * (origin[k] - mids[b, f, k])
            if facing <= 0.0:
                continue
            ok = True
            u_lo, v_lo, u_hi, v_hi = np.inf, np.inf, -np.inf, -np.inf
            for p in range(n_pts):
                q0 = outlines[b, f, p, 0] - origin[0]
                q1 = outlines[b, f, p, 1] - origin[1]
                q2 = outlines[b, f, p, 2] - origin[2]
                x = rot[0, 0] * q0 + rot[0, 1] * q1 + rot[0, 2] * q2
                y = rot[1, 0] * q0 + rot[1, 1] * q1 + rot[1, 2] * q2
                z = rot[2, 0] * q0 + rot[2, 1] * q1 + rot[2, 2] * q2
                if z <= 0.02:
                    ok = False
                    break
                if pinhole:
                    xp, yp = x / z, y / z
                    r2 = xp * xp + yp * yp
                    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * pk3))
                    xd = xp * radial + 2 * k3 * xp * yp + k4 * (r2 + 2 * xp * xp)
                    yd = yp * radial + k3 * (r2 + 2 * yp * yp) + 2 * k4 * xp * yp
                else:
                    r = math.hypot(x, y)
                    theta = math.atan2(r, z)
                    t2 = theta * theta
                    theta_d = theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
                    scale = theta_d / r if r > 1e-12 else 1.0 / z
                    xd, yd = x * scale, y * scale
                u = K[0, 0] * (xd + K[0, 1] / K[0, 0] * yd) + K[0, 2]
                v = K[1, 1] * yd + K[1, 2]
                uv[b, f, p, 0] = u
                uv[b, f, p, 1] = v
                u_lo, u_hi = min(u_lo, u), max(u_hi, u)
                v_lo, v_hi = min(v_lo, v), max(v_hi, v)
            if not ok:
                continue
            touches = windows.shape[0] == 0
            for w in range(windows.shape[0]):
                if (u_hi + 2.0 >= windows[w, 0] and u_lo - 2.0 < windows[w, 0] + windows[w, 2]
                        and v_hi + 2.0 >= windows[w, 1]
                        and v_lo - 2.0 < windows[w, 1] + windows[w, 3]):
                    touches = True
                    break
            keep[b, f] = touches
            bbox[b, f, 0], bbox[b, f, 1], bbox[b, f, 2], bbox[b, f, 3] = u_lo, v_lo, u_hi, v_hi
    return uv, bbox, keep, dist


_NO_WINDOWS = np.zeros((0, 4))
_NO_FACES = (np.zeros((0, 4 * OBSTACLE_EDGE_STEPS, 2)), np.zeros((0, 4)), np.zeros(0))


def visible_faces(camera: Camera, faces: BoxFaces, pose: tuple[float, float, float],
                  max_distance_m: float = Hall().distance_m,
                  windows: tuple[tuple[int, int, int, int], ...] | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The obstacle faces a camera on a car at ``pose`` sees, farthest box first (painter's
    order): image outlines ``(m, P, 2)`` [px], their bounding boxes ``(m, 4)`` and their
    brightness relative to white ``(m,)``. Boxes beyond ``max_distance_m`` stand behind
    the hall's walls; faces reaching behind the lens are left out. With ``windows``
    [(x, y, w, h) px], faces whose image bounding box touches none of them are left out
    too (they cannot change a requested pixel)."""
    if len(faces.centres) == 0:
        return _NO_FACES
    win = _NO_WINDOWS if windows is None else np.asarray(windows, dtype=np.float64)
    uv, bbox, keep, dist = _project_faces(faces.outlines, faces.normals, faces.mids,
                                          faces.centres, float(pose[0]), float(pose[1]),
                                          float(pose[2]), camera.mount._rotation,
                                          camera.mount._position, camera.K, camera.D,
                                          camera.lens is LensModel.PINHOLE,
                                          float(max_distance_m), win)
    if not keep.any():
        return _NO_FACES
    box_i, face_i = np.nonzero(keep)
    order = np.argsort(-dist[box_i], kind="stable")
    box_i, face_i = box_i[order], face_i[order]
    return uv[box_i, face_i], bbox[box_i, face_i], faces.shading[box_i, face_i]


def obstacle_faces(camera: Camera, faces: BoxFaces, pose: tuple[float, float, float],
                   white_dn: float = 255.0, max_distance_m: float = Hall().distance_m
                   ) -> list[tuple[np.ndarray, float]]:
    """``visible_faces`` as a list of image polygons [px] with their grey level [DN] for a
    white carton of ``white_dn`` lit from above."""
    uv, _, shading = visible_faces(camera, faces, pose, max_distance_m)
    return [(outline, float(white_dn * shade)) for outline, shade in zip(uv, shading,
                                                                          strict=True)]


def draw_faces(uv: np.ndarray, bbox: np.ndarray, shades: np.ndarray, width: int,
                height: int) -> tuple[tuple[int, int], np.ndarray, np.ndarray] | None:
    """Draw the faces (``visible_faces``' outlines and bounding boxes, grey levels [DN])
    once per frame into a buffer covering their bounding box in image coordinates (the
    same whatever window is asked for, so windows equal crops). Returns its top-left
    corner, the index of the face seen at each pixel (0: none; later faces paint over
    earlier ones) and the grey levels by index, or None if off-image."""
    if not len(uv):
        return None
    (u_lo, v_lo), (u_hi, v_hi) = bbox[:, :2].min(axis=0), bbox[:, 2:].max(axis=0)
    x0, y0 = max(0, math.floor(u_lo) - 1), max(0, math.floor(v_lo) - 1)
    x1, y1 = min(width, math.ceil(u_hi) + 2), min(height, math.ceil(v_hi) + 2)
    if x1 <= x0 or y1 <= y0:
        return None
    ids = np.zeros((y1 - y0, x1 - x0), np.uint16)
    shift = 4  # sub-pixel vertices: 1/16 px
    pts = np.rint((uv - np.array([x0, y0])) * (1 << shift)).astype(np.int32)
    for k in range(len(pts)):
        cv2.fillPoly(ids, [pts[k]], k + 1, lineType=cv2.LINE_8, shift=shift)
    return (x0, y0), ids, np.concatenate(([0.0], shades)).astype(np.float32)
