"""The lens models (fisheye, pinhole): OpenCV agreement, inversion, mounting, the checks of
impossible values, calibration to the thesis."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from tfalda_sim.camera import Bonnet, CameraMount, FisheyeCamera, PinholeCamera

THESIS_ROIS = {  # table 2.4: (x, y, width, height) [px]
    "upper_left": (195, 260, 150, 75), "upper_right": (365, 260, 150, 75),
    "lower_left": (80, 340, 180, 85), "lower_right": (429, 340, 180, 85),
}


def points_in_view(rng: np.random.Generator, n: int) -> np.ndarray:
    """Random camera-frame points within 75° of the optical axis, 0.05–20 m away."""
    theta = rng.uniform(0.0, math.radians(75.0), n)
    phi = rng.uniform(-math.pi, math.pi, n)
    dist = rng.uniform(0.05, 20.0, n)
    return np.column_stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi),
                            np.cos(theta)]) * dist[:, None]


@pytest.mark.parametrize("D", [np.zeros(4), np.array([0.05, -0.02, 0.01, -0.003])])
def test_project_agrees_with_opencv(D: np.ndarray) -> None:
    cam = FisheyeCamera(FisheyeCamera.default().K, D)
    pts = points_in_view(np.random.default_rng(0), 10_000)
    ref, _ = cv2.fisheye.projectPoints(pts.reshape(-1, 1, 3), np.zeros((3, 1)), np.zeros((3, 1)),
                                       cam.K, cam.D.reshape(4, 1))
    assert np.max(np.abs(cam.project(pts) - ref.reshape(-1, 2))) < 0.01


def test_behind_the_lens_is_nan_and_unproject_inverts() -> None:
    cam = FisheyeCamera.default()
    uv = cam.project(np.array([[0.1, 0.0, -1.0], [0.0, 0.0, 0.0], [0.2, 0.1, 1.0]]))
    assert np.isnan(uv[:2]).all() and np.isfinite(uv[2]).all()
    pix = np.random.default_rng(1).uniform([0, 0], [751, 479], (4000, 2))
    rays = cam.unproject(pix)
    assert np.allclose(np.linalg.norm(rays, axis=1), 1.0)
    # The image corners look more than 90° off-axis (diagonal field of view ≈ 187°):
    # their rays point backwards, which ``project`` marks as behind the lens.
    front = rays[:, 2] > math.cos(math.radians(85.0))
    assert front.sum() > 3000 and (rays[:, 2] < 0).any()
    assert np.allclose(cam.project(rays[front]), pix[front], atol=1e-6)


def test_real_calibration_plugs_in_unchanged() -> None:
    """K and D exactly as cv2.fisheye.calibrate returns them (K with skew, D of shape
    (4, 1)) make a camera that projects as cv2.fisheye.projectPoints does."""
    truth = FisheyeCamera(FisheyeCamera.default().K, np.array([0.03, -0.01, 0.004, -0.001]))
    grid = np.array([[x, y, 0.0] for y in range(6) for x in range(9)], np.float64) * 0.04
    rng = np.random.default_rng(2)
    obj, img = [], []
    for _ in range(12):
        R, _ = cv2.Rodrigues(rng.uniform(-0.5, 0.5, 3))
        t = np.array([rng.uniform(-0.25, 0.05), rng.uniform(-0.2, 0.0), rng.uniform(0.3, 0.6)])
        obj.append(grid.reshape(1, -1, 3).astype(np.float32))
        img.append(truth.project(grid @ R.T + t).reshape(1, -1, 2).astype(np.float32))
    # Recompute extrinsics, fix skew. OpenCV 5.1 exports the names again, with the unified
    # cv::CALIB_* values it now requires; 5.0 exported none and took its fisheye enum's
    # own values (2 and 8).
    if hasattr(cv2.fisheye, "CALIB_RECOMPUTE_EXTRINSIC"):
        flags = cv2.fisheye.CALIB_RECOMPUTE_EXTRINSIC | cv2.fisheye.CALIB_FIX_SKEW
    else:
        flags = 2 | 8
    _, K, D, _, _ = cv2.fisheye.calibrate(obj, img, (752, 480), np.zeros((3, 3)),
                                          np.zeros((4, 1)), flags=flags)
    assert K.shape == (3, 3) and D.shape == (4, 1)
    cam = FisheyeCamera(K, D)
    pts = points_in_view(rng, 2000)
    # projectPoints takes the skew separately (alpha); calibrate puts α·fx into K[0, 1].
    ref, _ = cv2.fisheye.projectPoints(pts.reshape(-1, 1, 3), np.zeros((3, 1)), np.zeros((3, 1)),
                                       K, D, alpha=K[0, 1] / K[0, 0])
    assert np.nanmax(np.abs(cam.project(pts) - ref.reshape(-1, 2))) < 0.01


def test_bad_inputs() -> None:
    cam = FisheyeCamera.default()
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        cam.project(np.zeros((4, 2)))
    with pytest.raises(ValueError, match="K must have shape"):
        FisheyeCamera(np.eye(2), np.zeros(4))
    with pytest.raises(ValueError, match="D must be finite"):
        FisheyeCamera(np.eye(3), np.array([0.0, np.nan, 0.0, 0.0]))


def test_default_field_of_view_is_the_thesis_lens() -> None:
    cam = FisheyeCamera.default()
    edge = cam.unproject(np.array([[0.0, cam.K[1, 2]], [751.0, cam.K[1, 2]]]))
    hfov = math.degrees(math.acos(edge[0, 2]) + math.acos(edge[1, 2]))
    assert 155.0 <= hfov <= 160.0
    assert (cam.width, cam.height) == (752, 480)


def lines_at_row(cam: FisheyeCamera, row: float) -> tuple[float, float]:
    """Columns [px] where the centre line (0.2 m left) and the right line (0.2 m right)
    cross image row ``row``, for a car centred in the right lane of a straight."""
    xs = cam.mount.forward_m + np.geomspace(0.01, 40.0, 20_000)
    out = []
    for lateral in (0.2, -0.2):
        pts = np.column_stack([xs, np.full_like(xs, lateral), np.zeros_like(xs)])
        uv = cam.project(cam.car_to_camera(pts))
        out.append(float(np.interp(row, uv[::-1, 1], uv[::-1, 0])))
    return out[0], out[1]


def test_lane_width_at_row_270_is_the_thesis_112_px() -> None:
    left, right = lines_at_row(FisheyeCamera.default(), 270)
    assert right - left == pytest.approx(112, abs=15)


@pytest.mark.parametrize(("row", "lo", "hi"), [(260, 45, 220), (335, 200, 272),
                                                (340, 200, 272), (425, 320, 520)])
def test_widths_at_roi_rows_lie_in_table_2_3(row: int, lo: int, hi: int) -> None:
    left, right = lines_at_row(FisheyeCamera.default(), row)
    assert lo <= right - left <= hi


@pytest.mark.parametrize("name", THESIS_ROIS)
def test_initial_rois_hold_the_ego_lane_markings(name: str) -> None:
    x, y, w, h = THESIS_ROIS[name]
    for row in (y, y + h):
        left, right = lines_at_row(FisheyeCamera.default(), row)
        col = left if name.endswith("left") else right
        assert x <= col <= x + w, f"{name}: line at column {col:.0f} on row {row}"


def test_mount_pitch_moves_the_horizon() -> None:
    cam = FisheyeCamera.default()
    far = np.array([[1000.0, 0.0, cam.mount.height_m]])
    level = cam.with_mount(pitch_rad=0.0)
    assert level.project(level.car_to_camera(far))[0, 1] == pytest.approx(cam.K[1, 2], abs=0.5)
    assert cam.project(cam.car_to_camera(far))[0, 1] < cam.K[1, 2] - 20  # tilted down


# ----------------------------------------------------------------------------- pinhole
PINHOLE_K = np.array([[420.0, 0.0, 371.2], [0.0, 418.5, 243.9], [0.0, 0.0, 1.0]])


@pytest.mark.parametrize("D", [np.zeros(5), np.array([-0.28, 0.09, 0.0012, -0.0008, -0.012])])
def test_pinhole_project_agrees_with_opencv(D: np.ndarray) -> None:
    cam = PinholeCamera(PINHOLE_K, D)
    rng = np.random.default_rng(3)
    theta = rng.uniform(0.0, math.radians(45.0), 10_000)  # a 90° lens's view
    phi = rng.uniform(-math.pi, math.pi, 10_000)
    pts = np.column_stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi),
                           np.cos(theta)]) * rng.uniform(0.05, 20.0, 10_000)[:, None]
    ref, _ = cv2.projectPoints(pts.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K, cam.D)
    assert np.max(np.abs(cam.project(pts) - ref.reshape(-1, 2))) < 0.01


def test_pinhole_behind_is_nan_and_unproject_inverts() -> None:
    cam = PinholeCamera(PINHOLE_K, np.array([-0.28, 0.09, 0.0012, -0.0008, -0.012]))
    uv = cam.project(np.array([[0.1, 0.0, -1.0], [0.0, 0.0, 0.0], [0.2, 0.1, 1.0]]))
    assert np.isnan(uv[:2]).all() and np.isfinite(uv[2]).all()
    pix = np.random.default_rng(4).uniform([0, 0], [751, 479], (4000, 2))
    rays = cam.unproject(pix)
    assert np.allclose(np.linalg.norm(rays, axis=1), 1.0) and (rays[:, 2] > 0).all()
    assert np.max(np.abs(cam.project(rays) - pix)) < 1e-6


def test_pinhole_refuses_skew_and_wrong_distortion() -> None:
    skewed = PINHOLE_K.copy()
    skewed[0, 1] = 0.5
    with pytest.raises(ValueError, match="skew"):
        PinholeCamera(skewed, np.zeros(5))
    with pytest.raises(ValueError, match=r"D must have shape \(5,\)"):
        PinholeCamera(PINHOLE_K, np.zeros(4))


@pytest.mark.parametrize("lens", [FisheyeCamera, PinholeCamera])
def test_pixels_to_ground_inverts_project_world(lens: type) -> None:
    """Both models: a ground point projected and taken back lands where it was."""
    if lens is FisheyeCamera:
        cam = FisheyeCamera.default()
    else:
        cam = PinholeCamera(PINHOLE_K, np.array([-0.2, 0.05, 0.001, 0.0, 0.0]),
                            mount=CameraMount(height_m=0.12, pitch_rad=math.radians(12.0),
                                              roll_rad=0.02, yaw_rad=-0.03, lateral_m=0.01))
    rng = np.random.default_rng(5)
    ground = np.column_stack([rng.uniform(0.6, 3.0, 200), rng.uniform(-0.4, 0.4, 200),
                              np.zeros(200)])
    uv = cam.project(cam.car_to_camera(ground))
    ok = np.all(np.isfinite(uv), axis=1)
    assert ok.sum() > 150
    assert np.allclose(cam.pixels_to_ground(uv[ok]), ground[ok, :2], atol=1e-6)


@pytest.mark.parametrize("field,value,match", [
    ("height_m", -0.1, "height_m must be in"), ("height_m", 5.0, "height_m must be in"),
    ("pitch_rad", math.radians(95.0), "pitch_rad must lie within"),
    ("roll_rad", float("nan"), "roll_rad must be finite"),
    ("yaw_rad", "0.1", "yaw_rad must be a number"),
])
def test_impossible_mounts_are_refused(field: str, value: object, match: str) -> None:
    with pytest.raises((ValueError, TypeError), match=match):
        CameraMount(**{field: value})


def test_camera_refuses_impossible_intrinsics() -> None:
    K = FisheyeCamera.default().K
    with pytest.raises(ValueError, match="positive focal"):
        FisheyeCamera(np.diag([-1.0, 1.0, 1.0]), np.zeros(4))
    with pytest.raises(ValueError, match="image width must be in"):
        FisheyeCamera(K, np.zeros(4), width=0)
    with pytest.raises(ValueError, match="principal point"):
        FisheyeCamera(K, np.zeros(4), width=128, height=96)
    with pytest.raises(ValueError, match="frame_rate_hz"):
        FisheyeCamera(K, np.zeros(4), frame_rate_hz=0.0)
    with pytest.raises(ValueError, match="outside the 752×480 image"):
        FisheyeCamera(K, np.zeros(4), bonnet=Bonnet.polygon([[0, 400], [800, 400], [0, 479]]))


def test_pinhole_unproject_is_nan_past_the_distortion_turning_point() -> None:
    """Strong barrel distortion folds back at the image corners: no ray reaches them."""
    cam = PinholeCamera(PINHOLE_K, np.array([-0.45, 0.0, 0.0, 0.0, 0.0]))
    rays = cam.unproject(np.array([[751.0, 0.0], [371.2, 243.9]]))
    assert np.isnan(rays[0]).all() and np.isfinite(rays[1]).all()
