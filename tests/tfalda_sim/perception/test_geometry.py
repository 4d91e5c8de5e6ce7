"""The thesis' layout from ground-plane definitions: agreement with tables 2.3/2.4 on the
thesis camera, derived ROIs inside the image and above the bonnet for other cameras, and
clear errors for cameras that cannot see the lane."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tfalda_sim.camera import Bonnet, CameraMount, FisheyeCamera, PinholeCamera
from tfalda_sim.perception import TfaldaDetector
from tfalda_sim.perception.geometry import (
    LAMBDA_DISTANCES_M,
    LAMBDA_REFERENCE_PX_PER_M,
    PLACEMENT_DISTANCE_M,
    THESIS_AGREEMENT_PX,
    CameraGeometryError,
    ground_pixels,
    px_per_m,
)
from tfalda_sim.perception.params import (
    INITIAL_ROIS,
    LEFT_CURVE_RIGHT_ROI_X_PX,
    RIGHT_CURVE_LEFT_ROI_END_PX,
    ROI_EXTRA_WIDTH_PX,
    ROI_MARGIN_LEFT_PX,
    ROI_MAX_WIDTH_PX,
    ROI_MIN_WIDTH_PX,
    WIDTH_LIMIT_ROWS_PX,
    WIDTH_LIMITS_PX,
    DetectorConfig,
    is_thesis_camera,
)
from tfalda_sim.perception.rois import initial_rois

PINHOLE_K = np.array([[300.0, 0.0, 375.5], [0.0, 300.0, 239.5], [0.0, 0.0, 1.0]])


def test_thesis_camera_agrees_with_tables_2_3_and_2_4() -> None:
    cfg = DetectorConfig.for_camera(FisheyeCamera.default())
    lay, lis = cfg.layout, cfg.lis
    got = np.array(lay.table_px, float)
    assert np.max(np.abs(got - np.array(INITIAL_ROIS, float))) <= THESIS_AGREEMENT_PX
    sizes = (lay.margin_left_px, lay.extra_width_px, lay.min_width_px, lay.max_width_px,
             lay.left_curve_right_roi_x_px, lay.right_curve_left_roi_end_px)
    thesis = (ROI_MARGIN_LEFT_PX, ROI_EXTRA_WIDTH_PX, ROI_MIN_WIDTH_PX, ROI_MAX_WIDTH_PX,
              LEFT_CURVE_RIGHT_ROI_X_PX, RIGHT_CURVE_LEFT_ROI_END_PX)
    assert np.max(np.abs(np.subtract(sizes, thesis))) <= THESIS_AGREEMENT_PX
    assert np.max(np.abs(np.subtract(lis.width_limits_px, WIDTH_LIMITS_PX))) <= THESIS_AGREEMENT_PX
    assert np.max(np.abs(np.subtract(lis.width_limit_rows_px, WIDTH_LIMIT_ROWS_PX))) \
        <= THESIS_AGREEMENT_PX
    assert np.allclose(lis.tolerance_scale, 1.0, atol=0.01)
    assert np.allclose(lay.lambda_scale, 1.0, atol=0.01)
    # the literal preset is untouched
    assert DetectorConfig.thesis().layout.table_px == INITIAL_ROIS
    assert is_thesis_camera(FisheyeCamera.default())
    assert not is_thesis_camera(FisheyeCamera.default().with_mount(height_m=0.15))


def test_lambda_reference_is_the_thesis_camera() -> None:
    cam = FisheyeCamera.default()
    for d, k in zip(LAMBDA_DISTANCES_M, LAMBDA_REFERENCE_PX_PER_M, strict=True):
        assert px_per_m(cam, d) == pytest.approx(k, rel=1e-3)


def random_camera(rng: np.random.Generator) -> FisheyeCamera | PinholeCamera:
    mount = CameraMount(height_m=rng.uniform(0.10, 0.30), forward_m=rng.uniform(0.1, 0.35),
                        lateral_m=rng.uniform(-0.03, 0.03),
                        pitch_rad=math.radians(rng.uniform(2.0, 25.0)),
                        roll_rad=math.radians(rng.uniform(-3.0, 3.0)),
                        yaw_rad=math.radians(rng.uniform(-4.0, 4.0)))
    bonnet = Bonnet(top_row=rng.uniform(430.0, 470.0), edge_drop_px=rng.uniform(0.0, 9.0))
    if rng.random() < 0.5:
        f = rng.uniform(230.0, 300.0)
        K = np.array([[f, 0.0, 375.5], [0.0, f, 239.5], [0.0, 0.0, 1.0]])
        return FisheyeCamera(K, rng.uniform(-0.02, 0.02, 4), mount=mount, bonnet=bonnet)
    f = rng.uniform(170.0, 240.0)
    K = np.array([[f, 0.0, 375.5], [0.0, f, 239.5], [0.0, 0.0, 1.0]])
    return PinholeCamera(K, np.array([rng.uniform(-0.1, 0.0), 0.0, 0.0, 0.0, 0.0]),
                         mount=mount, bonnet=bonnet)


def test_derived_rois_lie_inside_the_image_and_above_the_bonnet() -> None:
    rng = np.random.default_rng(7)
    made = 0
    for _ in range(60):
        cam = random_camera(rng)
        try:
            cfg = DetectorConfig.for_camera(cam)
        except CameraGeometryError:
            continue
        made += 1
        for rows in (2, 4):
            layout = cfg.layout.__class__(**{**cfg.layout.__dict__, "rows": rows})
            for pair in initial_rois(layout):
                for roi in pair:
                    assert 0 <= roi.x and roi.end <= cam.width and 0 <= roi.y
                    edge = cam.bonnet.edge(np.arange(roi.x, roi.end), cam.width, cam.height)
                    assert roi.y + roi.height - 1 < edge.min()
        # the ROIs hold the ego lane's lines at their rows' middle distance
        lay = cfg.layout
        ul, ur, ll, lr = lay.table_px
        for roi, line in ((ul, 0.2), (ur, -0.2), (ll, 0.2), (lr, -0.2)):
            v_mid = roi[1] + roi[3] / 2
            ahead = np.linspace(0.1, 3.0, 600)
            uv = ground_pixels(cam, ahead, np.full(600, line))
            k = int(np.nanargmin(np.abs(uv[:, 1] - v_mid)))
            assert roi[0] <= uv[k, 0] <= roi[0] + roi[2]
        TfaldaDetector(cfg).process(np.zeros((cam.height, cam.width), np.uint8))
    assert made >= 40


@pytest.mark.parametrize("mount,match", [
    (CameraMount(pitch_rad=math.radians(-30.0)), "does not see the road .* ahead"),
    (CameraMount(pitch_rad=math.radians(70.0)), "does not see the road"),
    (CameraMount(yaw_rad=math.radians(60.0)), "lines? .*ego lane.* field of view"),
])
def test_blind_cameras_are_refused_naming_what_is_missing(mount: CameraMount,
                                                          match: str) -> None:
    cam = FisheyeCamera.default(mount=mount)
    with pytest.raises(CameraGeometryError, match=match):
        DetectorConfig.for_camera(cam)


def test_a_narrow_lens_and_a_big_bonnet_are_refused() -> None:
    narrow = PinholeCamera(np.array([[2500.0, 0, 375.5], [0, 2500.0, 239.5], [0, 0, 1]]),
                           np.zeros(5))
    with pytest.raises(CameraGeometryError, match="does not see"):
        DetectorConfig.for_camera(narrow)
    big = FisheyeCamera.default().replace(bonnet=Bonnet(top_row=300.0, edge_drop_px=0.0))
    with pytest.raises(CameraGeometryError, match="body hides the lower ROI row"):
        DetectorConfig.for_camera(big)


def test_bonnet_moves_the_lower_row_up() -> None:
    cam = FisheyeCamera.default().replace(bonnet=Bonnet(top_row=405.0, edge_drop_px=0.0))
    cfg = DetectorConfig.for_camera(cam)
    ll = cfg.layout.table_px[2]
    assert ll[1] + ll[3] - 1 <= 404 and ll[3] < 85
    assert cfg.lis.width_limit_rows_px[3] == ll[1] + ll[3] - 1


def test_pixel_numbers_scale_with_the_ground_resolution() -> None:
    """A camera with twice the focal length sees the ground at twice the pixels: the ROI
    sizes, the tolerance and λ scales follow."""
    base = PinholeCamera(PINHOLE_K, np.zeros(5),
                         mount=CameraMount(height_m=0.2, pitch_rad=math.radians(20.0)))
    cfg = DetectorConfig.for_camera(base)
    k = px_per_m(base, PLACEMENT_DISTANCE_M)
    assert cfg.layout.max_width_px == min(round(0.682 * k), 752 // 2 - 1)
    assert cfg.layout.lambda_scale[0] == pytest.approx(
        px_per_m(base, LAMBDA_DISTANCES_M[0]) / LAMBDA_REFERENCE_PX_PER_M[0])
    assert cfg.lis.tolerance_scale[0] != pytest.approx(1.0, abs=0.05)


def test_a_camera_without_a_bonnet_and_hough_for_it() -> None:
    from tfalda_sim.perception import HoughConfig

    cam = FisheyeCamera.default().replace(bonnet=Bonnet.none())
    cfg = DetectorConfig.for_camera(cam)
    assert cfg.layout.table_px == INITIAL_ROIS  # nothing to clip
    hough = HoughConfig.for_camera(cam)
    assert hough.car_mask == () and hough.crop_top_px + hough.crop_height_px == 480
