"""The renderer: geometry to within a pixel, windows equal crops, effects do their job."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace

import numpy as np
import pytest

from tests.conftest import generated
from tfalda_sim.rendering import (
    Bonnet,
    DomainRandomization,
    Effects,
    Renderer,
    build_scene,
    frame_truth,
)
from tfalda_sim.rendering.obstacles import BoxFaces, obstacle_faces
from tfalda_sim.tracks import Marking, Track, load_named

ROIS = [(195, 260, 150, 75), (365, 260, 150, 75), (80, 340, 180, 85), (429, 340, 180, 85)]


@pytest.fixture(scope="module")
def renderer() -> Renderer:
    return Renderer()


def lane_pose(track: Track, s: float, lateral: float | None = None) -> tuple[float, float, float]:
    """The car's reference point at arc length ``s`` [m], in the middle of the right lane
    (or at ``lateral`` [m]), heading along the road."""
    lat = -0.5 * track.lane_width_m if lateral is None else lateral
    x, y, h = track.pose(s, lat)
    return float(x), float(y), float(h)


def test_marking_appears_within_a_pixel_of_its_projection(renderer: Renderer) -> None:
    track = load_named("straight")
    scene = build_scene(track, Effects.off())
    pose = lane_pose(track, 1.0)
    frame = renderer.render(scene, pose).astype(np.float64)
    cam = renderer.camera
    for line_lateral in (-0.4, 0.0):  # right side line, centre line (dashes)
        s = 1.0 + np.linspace(0.25, 3.0, 6000)
        pts = np.zeros((len(s), 3))
        pts[:, :2] = track.position(s, line_lateral)
        uv = cam.project_world(pts, pose)
        checked = 0
        for row in range(250, 440, 10):
            if not uv[:, 1].min() < row < uv[:, 1].max():
                continue
            u = float(np.interp(row, uv[::-1, 1], uv[::-1, 0]))
            lo, hi = int(u) - 8, int(u) + 9
            profile = frame[row, lo:hi] - frame[row, lo:hi].min()
            if profile.max() < 40:  # a gap between two dashes
                continue
            centroid = lo + float((profile * np.arange(hi - lo)).sum() / profile.sum())
            assert abs(centroid - u) < 1.0, (line_lateral, row, centroid, u)
            checked += 1
        assert checked >= 8


def random_windows(rng: np.random.Generator, n: int) -> list[tuple[int, int, int, int]]:
    wins = []
    for _ in range(n):
        w, h = int(rng.integers(1, 300)), int(rng.integers(1, 200))
        wins.append((int(rng.integers(0, 752 - w + 1)), int(rng.integers(0, 480 - h + 1)), w, h))
    return wins


@pytest.mark.parametrize("variant", ["off", "default", "randomized"])
def test_windows_equal_crops_of_the_full_frame(renderer: Renderer, variant: str) -> None:
    rng = np.random.default_rng(7)
    track = generated(3)  # has obstacles and an intersection
    fx = {"off": Effects.off(), "default": Effects(),
          "randomized": replace(DomainRandomization().sample(rng), motion_blur_s=0.004,
                                shadows=2, glare_spots=2)}[variant]
    scene = build_scene(track, fx, rng)
    poses = [lane_pose(track, ob.s_m - 0.9) for ob in track.obstacles]
    poses += [lane_pose(track, track.intersections[0].s1_m - 1.5), lane_pose(track, 2.0)]
    for k, pose in enumerate(poses):
        full = renderer.render(scene, pose, speed_m_s=3.0, frame_seed=k)
        # The top rows switch between walls and ceiling (not sampled): windows across,
        # inside and beside those switches.
        top = [(100, 0, 600, 40), (360, 0, 30, 12), (0, 8, 90, 30), (370, 25, 3, 3)]
        wins = [*ROIS, *random_windows(rng, 6), *top, (0, 0, 752, 480)]
        parts = renderer.render_windows(scene, pose, wins, speed_m_s=3.0, frame_seed=k)
        for (x, y, w, h), part in zip(wins, parts, strict=True):
            assert part.shape == (h, w) and part.dtype == np.uint8
            assert np.array_equal(part, full[y:y + h, x:x + w]), (variant, k, (x, y, w, h))


def test_small_windows_at_an_obstacle_outline_equal_crops(renderer: Renderer) -> None:
    """Tiny windows rendered one by one along a carton's image: the window pre-test must
    never drop a box whose (fisheye-curved) edges reach into the window."""
    track = generated(3)
    scene = build_scene(track, Effects.off(), np.random.default_rng(1))
    checked = 0
    for ob in track.obstacles[:2]:
        for back in (0.6, 1.2):
            pose = lane_pose(track, ob.s_m - back)
            full = renderer.render(scene, pose)
            faces = obstacle_faces(renderer.camera, BoxFaces.of(scene.boxes), pose)
            if not faces:
                continue
            pts = np.concatenate([uv for uv, _ in faces])
            x0, y0 = np.clip(np.floor(pts.min(axis=0)).astype(int) - 8, 0, None)
            x1, y1 = np.minimum(np.ceil(pts.max(axis=0)).astype(int) + 8, (752, 480))
            for y in range(int(y0), int(y1) - 4, 4):
                for x in range(int(x0), int(x1) - 6, 6):
                    (part,) = renderer.render_windows(scene, pose, [(x, y, 6, 4)])
                    assert np.array_equal(part, full[y:y + 4, x:x + 6]), (pose, x, y)
                    checked += 1
    assert checked > 200


def test_obstacle_outlines_are_the_camera_projection_of_the_box_faces(
        renderer: Renderer) -> None:
    """The per-frame face kernel uses the camera model's formulas: its outlines equal
    ``FisheyeCamera.project_world`` of the faces, here with a camera mounted off-centre
    and yawed, and only faces turned towards the camera are drawn."""
    camera = renderer.camera
    mount = replace(camera.mount, lateral_m=0.03, yaw_rad=0.1, roll_rad=0.02)
    camera = replace(camera, mount=mount)
    track = generated(3)
    faces = BoxFaces.of(build_scene(track, Effects.off()).boxes)
    seen = 0
    for ob in track.obstacles:
        pose = lane_pose(track, ob.s_m - 0.8)
        for uv, shade in obstacle_faces(camera, faces, pose):
            # Find the face this outline belongs to by projecting every face (faces
            # behind the lens project to NaN).
            errors = np.nan_to_num([np.abs(camera.project_world(outline, pose) - uv).max()
                                    for outline in faces.outlines.reshape(
                                        -1, *faces.outlines.shape[2:])], nan=np.inf)
            assert errors.min() < 1e-6
            box, face = divmod(int(np.argmin(errors)), faces.outlines.shape[1])
            cam_world = np.array([*pose[:2], 0.0]) + np.array([
                [math.cos(pose[2]), -math.sin(pose[2]), 0.0],
                [math.sin(pose[2]), math.cos(pose[2]), 0.0], [0.0, 0.0, 1.0]]) @ mount.position()
            assert np.dot(faces.normals[box, face], cam_world - faces.mids[box, face]) > 0
            assert 0.72 * 255 <= shade <= 255
            seen += 1
    assert seen >= 2


def test_same_seed_same_frame_and_noise_differs_by_seed(renderer: Renderer) -> None:
    track = load_named("oval")
    scene = build_scene(track, Effects(noise_dn=4.0))
    pose = lane_pose(track, 1.0)
    a = renderer.render(scene, pose, frame_seed=3)
    assert np.array_equal(a, renderer.render(scene, pose, frame_seed=3))
    b = renderer.render(scene, pose, frame_seed=4)
    diff = a.astype(int) - b.astype(int)
    assert 3.0 < diff.std() < 8.0  # two independent N(0, 4) draws differ by σ·√2


def test_sensor_noise_has_the_requested_spread(renderer: Renderer) -> None:
    track = load_named("straight")
    pose = lane_pose(track, 1.0)
    clean = renderer.render(build_scene(track, Effects.off()), pose).astype(float)
    noisy = renderer.render(build_scene(track, replace(Effects.off(), noise_dn=5.0)), pose,
                            frame_seed=1).astype(float)
    inside = (clean > 10) & (clean < 245)
    assert (noisy - clean)[inside].std() == pytest.approx(5.0, rel=0.1)


def test_gain_and_vignetting(renderer: Renderer) -> None:
    track = load_named("straight")
    pose = lane_pose(track, 1.0)
    base = renderer.render(build_scene(track, Effects.off()), pose).astype(float)
    bright = renderer.render(build_scene(track, replace(Effects.off(), gain=1.5)), pose)
    mat = (base > 20) & (base < 60)
    assert np.median(bright[mat] / base[mat]) == pytest.approx(1.5, abs=0.05)
    vig = renderer.render(build_scene(track, replace(Effects.off(), vignetting=0.5)), pose)
    ratio = vig.astype(float) / np.maximum(base, 1)
    assert ratio[470, 5] < 0.6 < 0.95 < ratio[240, 376]


def test_far_dashes_fade_but_do_not_vanish(renderer: Renderer) -> None:
    """Mip-mapping keeps distant centre-line dashes visible as a faint band."""
    track = load_named("straight")
    scene = build_scene(track, Effects.off())
    pose = lane_pose(track, 0.3)
    frame = renderer.render(scene, pose).astype(float)
    pts = np.zeros((1, 3))
    pts[0, :2] = track.position(0.3 + 6.0, 0.0)  # centre line 6 m ahead
    u, v = renderer.camera.project_world(pts, pose)[0]
    patch = frame[int(v) - 1:int(v) + 2, int(u) - 3:int(u) + 4]
    assert patch.max() > Effects.off().mat_dn + 8


def test_far_dashes_do_not_shimmer(renderer: Renderer) -> None:
    """Driving 2 cm per frame, a far patch's brightness changes smoothly."""
    track = load_named("straight")
    scene = build_scene(track, Effects.off())
    means = []
    for k in range(40):
        pose = lane_pose(track, 0.3 + 0.02 * k)
        means.append(renderer.render_windows(scene, pose, [(340, 222, 60, 6)])[0].mean())
    steps = np.abs(np.diff(means))
    assert steps.max() < 2.0  # DN per 2 cm of travel


def test_bonnet_is_dark_and_reflects_the_lines(renderer: Renderer) -> None:
    track = load_named("straight")
    pose = lane_pose(track, 1.0)
    plain = renderer.render(build_scene(track, replace(Effects.off(), bonnet_dn=20.0)), pose)
    shiny = renderer.render(build_scene(track, replace(Effects.off(), bonnet_dn=20.0,
                                                       bonnet_reflectivity=0.3)), pose)
    bonnet = renderer.geometry.bonnet.astype(bool)
    assert np.all(plain[bonnet] == 20)
    assert shiny[bonnet].max() > 20 + 0.3 * 150  # a mirrored white line
    assert np.all(renderer.geometry.bonnet[:430] == 0) and np.all(renderer.geometry.bonnet[470:])
    flat = Renderer(bonnet=Bonnet(enabled=False))
    assert not flat.geometry.bonnet.any()


def test_obstacle_hides_the_road_behind_it(renderer: Renderer) -> None:
    track = generated(3)
    ob = track.obstacles[0]
    scene = build_scene(track, Effects.off())
    pose = lane_pose(track, ob.s_m - 1.0, -0.5 * track.lane_width_m + ob.offset_m
                     if ob.lane.value == "right" else None)
    frame = renderer.render(scene, pose)
    truth = frame_truth(track, renderer.camera, pose)
    carton = truth.labels == Marking.OBSTACLE
    assert carton.sum() > 200
    assert np.median(frame[carton]) > 0.7 * Effects.off().line_dn  # white carton


@pytest.mark.parametrize("window", [(-1, 0, 10, 10), (700, 0, 60, 10), (0, 0, 0, 5)])
def test_windows_outside_the_image_are_refused(renderer: Renderer, window: tuple) -> None:
    scene = build_scene(load_named("oval"), Effects.off())
    with pytest.raises(ValueError, match="not inside"):
        renderer.render_windows(scene, lane_pose(load_named("oval"), 1.0), [window])


def test_nan_pose_is_refused(renderer: Renderer) -> None:
    scene = build_scene(load_named("oval"), Effects.off())
    with pytest.raises(ValueError, match="finite"):
        renderer.render(scene, (math.nan, 0.0, 0.0))


def test_walls_turn_with_the_car(renderer: Renderer) -> None:
    track = load_named("oval")
    scene = build_scene(track, Effects.off())
    x, y, h = lane_pose(track, 1.0)
    a = renderer.render_windows(scene, (x, y, h), [(0, 0, 752, 120)])[0]
    b = renderer.render_windows(scene, (x, y, h + 0.3), [(0, 0, 752, 120)])[0]
    assert not np.array_equal(a, b)


def test_renderer_does_not_keep_old_scenes_alive(renderer: Renderer) -> None:
    """A new scene per episode (domain randomisation) must not pile up atlases."""
    import gc
    import weakref

    track = load_named("oval")
    first = build_scene(track, Effects.off())
    ref = weakref.ref(first)
    renderer.render(first, lane_pose(track, 1.0))
    renderer.render(build_scene(track, Effects()), lane_pose(track, 1.0))
    del first
    gc.collect()
    assert ref() is None


def test_numpy_frame_seeds_and_hashable_camera(renderer: Renderer) -> None:
    track = load_named("straight")
    scene = build_scene(track, Effects(noise_dn=4.0))
    pose = lane_pose(track, 1.0)
    big = np.int64(2**62 + 12345)  # the splitmix hash must not wrap in int64
    assert np.array_equal(renderer.render(scene, pose, frame_seed=big),
                          renderer.render(scene, pose, frame_seed=int(big)))
    assert len({renderer.camera, renderer.camera, scene}) == 2


def _blended_combine(tex: np.ndarray, flags: np.ndarray, gain: np.ndarray, sheen: np.ndarray,
                     noise: np.ndarray, params: np.ndarray) -> np.ndarray:
    """The combine pass as it was per pixel: every formula computed, the pixel's own
    selected by 0/1 factors of its flags (float32 throughout)."""
    from tfalda_sim.rendering.renderer import _combine_params

    mat, k_line, wall_k, bonnet_dn, refl, sigma, ceiling = _combine_params(params)
    f32 = np.float32
    one = f32(1.0)
    is_g, is_b, is_c = ((flags >> k) & 1 for k in range(3))
    is_g, is_b, is_c = (x.astype(f32) for x in (is_g, is_b, is_c))
    value = tex.astype(f32)
    w = is_c * ceiling + (one - is_c) * (wall_k * value)
    v = is_g * (mat + k_line * value + sheen.astype(f32)) + (one - is_g) * w
    v = is_b * (bonnet_dn + refl * v) + (one - is_b) * v
    v = v * gain + sigma * noise.astype(f32)
    return (np.minimum(np.maximum(v, f32(0.0)), f32(255.0)) + f32(0.5)).astype(np.uint8)


def test_combine_per_piece_equals_the_per_pixel_blend() -> None:
    """The combine pass picks one formula per piece (its pixels share their flags); it
    must give the per-pixel blend's grey levels bit for bit, for every combination of
    ground, bonnet and ceiling, at clipping levels too."""
    from tfalda_sim.rendering.renderer import _combine

    rng = np.random.default_rng(5)
    width, rows = 64, 8
    flags_of_row = np.array([0, 1, 2, 3, 4, 6, 1, 0], np.uint8)  # every case the layout has
    flags = np.repeat(flags_of_row[:, None], width, axis=1)
    gain = rng.uniform(0.2, 3.0, (rows, width)).astype(np.float32)
    sheen = rng.integers(0, 60, (rows, width), dtype=np.uint8)
    noise = rng.integers(-127, 128, rows * width + 16, dtype=np.int8)
    tex = rng.integers(0, 256, rows * width, dtype=np.uint8)
    params = np.array([40.0, 230.0, 90.0, 12.0, 0.15, 3.0, 1.25 * 90.0])
    # One piece per row, in a shuffled order of the output.
    order = rng.permutation(rows)
    r = np.arange(rows, dtype=np.int64)[order]
    out = np.empty(rows * width, np.uint8)
    offsets = np.arange(rows, dtype=np.int64) * width
    _combine(out, offsets, r, np.zeros(rows, np.int64), np.full(rows, width, np.int64),
             r * width, flags_of_row[r].astype(np.int64), tex, gain, sheen, noise, 7, width,
             params)
    want = _blended_combine(tex.reshape(rows, width), flags, gain, sheen,
                            noise[7:7 + rows * width].reshape(rows, width), params)
    got = out.reshape(rows, width)[np.argsort(order)]
    assert (got == want).all()
    assert (got == 255).any() and (got == 0).any()  # both clips are exercised


def _fma_sensitive_samples(rng: np.random.Generator, want: int
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Taps (4, n) and fractions of samples whose bilinear value rounds differently with
    fused and with separate multiply-adds (about one in a million)."""
    f32 = np.float32

    def lerp(p: np.ndarray, sx: np.ndarray, sy: np.ndarray, fused: bool) -> np.ndarray:
        def mad(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
            return (a.astype(np.float64) * b + c).astype(f32) if fused else a * b + c
        v0, v1 = mad(sx, p[1] - p[0], p[0]), mad(sx, p[3] - p[2], p[2])
        return np.rint(mad(sy, v1 - v0, v0))

    taps, fx, fy = [], [], []
    while sum(map(len, fx)) < want:
        p = rng.integers(0, 256, (4, 1 << 21)).astype(f32)
        sx = (rng.integers(0, 4096, 1 << 21) / 4096).astype(f32)  # exact beside x < 2048
        sy = rng.random(1 << 21).astype(f32)
        hit = lerp(p, sx, sy, True) != lerp(p, sx, sy, False)
        taps.append(p[:, hit])
        fx.append(sx[hit])
        fy.append(sy[hit])
    return np.concatenate(taps, axis=1), np.concatenate(fx), np.concatenate(fy)


def test_atlas_sampling_equals_opencv_remap() -> None:
    """The renderer samples the atlas itself (``_bilinear``); it must give what
    ``cv2.remap`` (bilinear, constant 0 border, float maps in rows of 1024, as the
    renderer called it) gives: inside, across every border, far outside (the padding
    coordinate), at exact texels, and where only fused multiply-adds round right."""
    import cv2

    from tfalda_sim.rendering.renderer import _bilinear

    if int(cv2.__version__.split(".")[0]) < 5:
        pytest.skip(f"OpenCV {cv2.__version__}'s remap uses fixed-point weights (OpenCV 5 "
                    "float32 ones, which the renderer reproduces)")
    rng = np.random.default_rng(11)
    f32 = np.float32
    rows, width = 24, 1024
    image = rng.integers(0, 256, (61, 83), dtype=np.uint8)
    mx = rng.uniform(-3.0, 86.0, (rows, width)).astype(f32)
    my = rng.uniform(-3.0, 64.0, (rows, width)).astype(f32)
    mx[:4] = np.round(mx[:4] * 2) / 2  # texel centres and halfway points
    my[:4] = np.round(my[:4] * 2) / 2
    mx[4, ::3] = -8.0  # the renderer's padding coordinate
    cases: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = [
        (image, mx, my, cv2.remap(image, mx, my, cv2.INTER_LINEAR,
                                  borderMode=cv2.BORDER_CONSTANT, borderValue=0))]
    # Samples that tell fused from separate multiply-adds, one 2×2 block each.
    taps, fx, fy = _fma_sensitive_samples(rng, 40)
    n = taps.shape[1]
    blocks = np.zeros((2, 2 * width), np.uint8)
    sx = np.full((1, width), 0.25, f32)
    sy = np.full((1, width), 0.25, f32)
    for k in range(n):
        col = 7 * k  # spread over the row
        blocks[:, 2 * col:2 * col + 2] = taps[:, k].reshape(2, 2)
        sx[0, col] = f32(2 * col) + fx[k]
        sy[0, col] = fy[k]
    want = cv2.remap(blocks, sx, sy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                     borderValue=0)
    cases.append((blocks, sx, sy, want))
    for img, xs, ys, expected in cases:
        h, w = img.shape
        got = np.empty(xs.shape, np.uint8)
        scratch = (np.empty(width, f32), np.empty(width, f32), np.empty(width, np.int32),
                   np.empty(width, np.uint16), np.empty(width, np.uint16))
        for r in range(xs.shape[0]):
            _bilinear(got[r], img.reshape(-1), np.int32(h), np.int32(w), xs[r], ys[r],
                      *scratch)
        assert (got == expected).all(), f"{np.count_nonzero(got != expected)} samples differ"
    assert n >= 40


def test_windows_take_one_kernel_call_where_they_can(renderer: Renderer, monkeypatch) -> None:
    """The ROIs of a frame without blur, light maps or obstacles in view are rendered in
    one kernel call: ``_render_lean``, or on a lazy scene ``_render_lazy``, which checks
    that the view's tiles are filled (if not, it lists them and ``_fill_render`` fills
    and renders: two calls); the rest kernel by kernel. Either way the crops of the eager
    scene's full frame."""
    import tfalda_sim.rendering.renderer as module

    statuses: list[str] = []

    def counted(name: str) -> Callable[..., int]:
        real = getattr(module, name)

        def call(*args: object) -> int:
            status = real(*args)
            statuses.append({"_render_lean": "lean", "_fill_render": "filled"}.get(name) or (
                "walls" if status < 0 else "listed" if status > 0 else "rendered"))
            return status
        return call

    for name in ("_render_lean", "_render_lazy", "_fill_render"):
        monkeypatch.setattr(module, name, counted(name))
    track = generated(3)  # obstacles: views with and without one
    fx = replace(Effects(), motion_blur_s=0.004)  # blurs at speed only
    assert fx.shadows == 0 and fx.glare_spots == 0
    eager = build_scene(track, fx, np.random.default_rng(5), lazy=False)
    lazy = build_scene(track, fx, np.random.default_rng(5))
    clear = lane_pose(track, 2.0)
    cases = [  # (pose, speed, windows, kernels on the lazy scene, on the eager one)
        (clear, 0.0, ROIS, "listed, filled", "lean"),
        (clear, 0.0, ROIS, "rendered", "lean"),  # filled now: nothing to fill
        (clear, 2.0, ROIS, "", ""),  # motion blur
        (lane_pose(track, track.obstacles[0].s_m - 0.9), 0.0, ROIS, "", ""),  # a carton
        (clear, 0.0, [(100, 0, 600, 40)], "walls", "lean"),  # wall rows not copied yet
    ]
    for k, (pose, speed, wins, on_lazy, on_eager) in enumerate(cases):
        full = renderer.render(eager, pose, speed_m_s=speed, frame_seed=k)
        for scene, expected in ((lazy, on_lazy), (eager, on_eager)):
            statuses.clear()
            parts = renderer.render_windows(scene, pose, wins, speed_m_s=speed, frame_seed=k)
            assert ", ".join(statuses) == expected, (k, scene is lazy)
            for (x, y, w, h), part in zip(wins, parts, strict=True):
                assert np.array_equal(part, full[y:y + h, x:x + w]), (k, scene is lazy)
    # light maps (shadows): kernel by kernel
    shaded = build_scene(track, replace(fx, shadows=2), np.random.default_rng(5))
    statuses.clear()
    renderer.render_windows(shaded, clear, ROIS)
    assert statuses == []
