"""The clip fit: known mounts recovered from rendered clips of a weaving car (both lens
models, 320×240 to 1920×1200), lines on the car's body never fitted, the cables car's real
frames, and what it refuses."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest

from tfalda_sim.camera import Bonnet, CameraMount, FisheyeCamera, PinholeCamera
from tfalda_sim.camera.clip import (
    ClipFitError,
    ClipFrame,
    clip_focal,
    fit_clip,
    sample_frames,
    time_weights,
)
from tfalda_sim.camera.fit import MountFitError, SearchScale, body_search_mask, fit_mount
from tfalda_sim.camera.models import Camera
from tfalda_sim.camera.static_body import static_body
from tfalda_sim.rendering.renderer import Renderer
from tfalda_sim.rendering.scene import build_scene
from tfalda_sim.tracks import MarkingMap, rasterize
from tfalda_sim.tracks.named import load_named

REFERENCE = Path(__file__).parents[2] / "data" / "reference"  # ../shared/reference/, copied

FRAMES_PER_CLIP = 8
"""Frames of one clip: one weave of the car, evenly over it."""

WEAVE_AMPLITUDE_M = 0.05
"""The car's lateral swing about the right lane's centre [m]."""

WEAVE_LENGTH_M = 1.8
"""One weave's length along the road [m]: with the amplitude, headings up to
atan(2π · 0.05 / 1.8) = ±9.9°."""

SPEED_M_S = 1.5
"""The clip's speed [m/s] (its time stamps)."""

# (width, height, lens) of the 20 clips: both lens models from 320×240 to 1920×1200.
CLIPS = [(320, 240, "fisheye"), (320, 240, "pinhole"), (454, 284, "fisheye"),
         (454, 284, "pinhole"), (640, 480, "fisheye"), (640, 480, "pinhole"),
         (752, 480, "fisheye"), (752, 480, "pinhole"), (800, 600, "fisheye"),
         (800, 600, "pinhole"), (960, 600, "fisheye"), (960, 600, "pinhole"),
         (1024, 640, "fisheye"), (1024, 768, "pinhole"), (1280, 800, "fisheye"),
         (1120, 700, "pinhole"), (1440, 900, "fisheye"), (1280, 720, "pinhole"),
         (1920, 1200, "fisheye"), (1920, 1200, "pinhole")]


@dataclass(frozen=True)
class Clip:
    camera: Camera
    frames: list[ClipFrame]
    headings_rad: list[float]


def _camera(rng: np.random.Generator, width: int, height: int, lens: str) -> Camera:
    """A random known mount (as test_fit's) on a lens of the image's size: the thesis
    camera's fields of view scaled to the width."""
    mount = CameraMount(height_m=rng.uniform(0.10, 0.28), forward_m=0.2,
                        lateral_m=rng.uniform(-0.04, 0.04),
                        pitch_rad=math.radians(rng.uniform(3.0, 25.0)),
                        roll_rad=math.radians(rng.uniform(-4.0, 4.0)),
                        yaw_rad=math.radians(rng.uniform(-5.0, 5.0)))
    s = width / 752
    centre = [width / 2 + rng.uniform(-10, 10) * s, height / 2 + rng.uniform(-8, 8) * s]
    if lens == "fisheye":
        f = rng.uniform(240.0, 320.0) * s
        K = np.array([[f, 0.0, centre[0]], [0.0, f, centre[1]], [0.0, 0.0, 1.0]])
        D = np.array([rng.uniform(-0.004, 0.004), 0.0, 0.0, 0.0])
        return FisheyeCamera(K, D, width=width, height=height, mount=mount,
                             bonnet=Bonnet.none())
    f = rng.uniform(200.0, 260.0) * s
    K = np.array([[f, 0.0, centre[0]], [0.0, f, centre[1]], [0.0, 0.0, 1.0]])
    D = np.array([rng.uniform(-0.05, 0.0), 0.0, 0.0, 0.0, 0.0])
    return PinholeCamera(K, D, width=width, height=height, mount=mount, bonnet=Bonnet.none())


def weave(rng: np.random.Generator, n: int = FRAMES_PER_CLIP
          ) -> list[tuple[float, float, float, float]]:
    """(s [m], lateral offset [m], heading [rad], t [s]) of a car weaving about the right
    lane's centre: one weave, evenly, its heading the path's own (atan of the offset's
    slope), so the heading averages out over the clip."""
    s0, phase = rng.uniform(1.0, 2.5), rng.uniform(0.0, 2 * math.pi)
    out = []
    for i in range(n):
        s = s0 + i * WEAVE_LENGTH_M / n
        a = 2 * math.pi * (s - s0) / WEAVE_LENGTH_M + phase
        offset = -0.2 + WEAVE_AMPLITUDE_M * math.sin(a)
        heading = math.atan(WEAVE_AMPLITUDE_M * 2 * math.pi / WEAVE_LENGTH_M * math.cos(a))
        out.append((s, offset, heading, (s - s0) / SPEED_M_S))
    return out


@functools.cache
def _straight() -> tuple:
    track = load_named("straight")
    return track, build_scene(track)


def render_clip(camera: Camera, rng: np.random.Generator, *, scene: object | None = None,
                n: int = FRAMES_PER_CLIP) -> Clip:
    """The straight track seen through ``camera`` by a weaving car."""
    track, straight = _straight()
    renderer = Renderer(camera)
    frames, headings = [], []
    for i, (s, offset, heading, t) in enumerate(weave(rng, n)):
        x, y = track.position(np.array([s]), offset)[0]
        image = renderer.render(scene or straight, (x, y, heading), frame_seed=i)
        frames.append(ClipFrame(i, t, image))
        headings.append(heading)
    return Clip(camera, frames, headings)


@functools.cache
def clips() -> list[Clip]:
    """The 20 rendered clips (seeded), made once for the tests that use them."""
    rng = np.random.default_rng(2024)
    return [render_clip(_camera(rng, w, h, lens), rng) for w, h, lens in CLIPS]


def test_clip_fit_recovers_the_mounts_of_weaving_cars() -> None:
    """20 clips, the car weaving ±10°: pitch, roll and yaw within 0.5°, height within
    5 mm on every one (the heading is not taken for the yaw)."""
    errors = []
    for clip in clips():
        truth = clip.camera.mount
        fit = fit_clip(clip.frames, clip.camera.replace(mount=CameraMount()))
        m = fit.camera.mount
        err = (math.degrees(m.pitch_rad - truth.pitch_rad),
               math.degrees(m.roll_rad - truth.roll_rad),
               math.degrees(m.yaw_rad - truth.yaw_rad), m.height_m - truth.height_m)
        errors.append(err)
        what = f"{clip.camera.width}×{clip.camera.height} {clip.camera.lens.value}: {err}"
        assert abs(err[0]) < 0.5 and abs(err[1]) < 0.5, what
        assert abs(err[2]) < 0.5 and abs(err[3]) < 0.005, what
        assert fit.roll_fitted and fit.used >= FRAMES_PER_CLIP // 2, what
        # the car's heading was ±10°: reported as the heading's spread, not as the yaw
        assert fit.spreads["heading_deg"].q75 - fit.spreads["heading_deg"].q25 > 5.0, what
        assert m.lateral_m == 0.0  # a clip keeps the mount's lateral offset
    worst = np.max(np.abs(errors), axis=0)
    print(f"\nworst of {len(errors)} clips: pitch {worst[0]:.3f}°, roll {worst[1]:.3f}°, "
          f"yaw {worst[2]:.3f}°, height {worst[3] * 1000:.2f} mm")
    assert len({c.camera.lens for c in clips()}) == 2


def test_a_frame_s_yaw_holds_the_car_s_heading() -> None:
    """Why a clip is needed: one frame's yaw is the mount's plus the car's heading."""
    clip = clips()[6]
    k = int(np.argmax(np.abs(clip.headings_rad)))
    fit = fit_mount(clip.frames[k].image, clip.camera.replace(mount=CameraMount()))
    own = fit.camera.mount.yaw_rad - clip.camera.mount.yaw_rad
    assert abs(math.degrees(own)) > 5.0
    assert abs(abs(own) - abs(clip.headings_rad[k])) < math.radians(0.5)


def _empty_scene() -> object:
    """The straight track's hall and mat without a single marking."""
    track, _ = _straight()
    full = rasterize(track)
    empty = MarkingMap(np.zeros_like(full.intensity), np.zeros_like(full.labels),
                       full.origin_m, full.resolution_m)
    return build_scene(track, marking_map=empty, lazy=False)


def _body_lines(frames: list[ClipFrame], camera: Camera) -> list[ClipFrame]:
    """``frames`` with bright lines drawn on the car's body: three converging like a
    road's, the middle one dashed, as cables or a print might (the same in every frame)."""
    h, w = frames[0].image.shape
    top = camera.bonnet.top_px(w, h)
    out = []
    for f in frames:
        img = f.image.copy()
        vp = (w / 2, top + 0.2 * (h - top))
        for k, du in enumerate((-0.45, 0.0, 0.45)):
            a = (vp[0] + 0.15 * du * w, vp[1])
            b = (w / 2 + du * w, h - 1)
            steps = 6 if k == 1 else 1
            for j in range(steps):
                if k == 1 and j % 2:
                    continue
                p = [a[i] + (b[i] - a[i]) * j / steps for i in range(2)]
                q = [a[i] + (b[i] - a[i]) * (j + 1) / steps for i in range(2)]
                cv2.line(img, (int(p[0]), int(p[1])), (int(q[0]), int(q[1])), 230,
                         max(2, w // 200), cv2.LINE_AA)
        out.append(ClipFrame(f.index, f.t_s, img))
    return out


def _body_camera(width: int, height: int) -> FisheyeCamera:
    f = 0.4 * width
    K = np.array([[f, 0.0, width / 2], [0.0, f, height / 2], [0.0, 0.0, 1.0]])
    body = Bonnet.polygon([[0, height - 1], [0, 0.72 * height], [width / 2, 0.68 * height],
                           [width - 1, 0.72 * height], [width - 1, height - 1]])
    return FisheyeCamera(K, np.zeros(4), width=width, height=height, bonnet=body,
                         mount=CameraMount(height_m=0.16, pitch_rad=math.radians(14.0)))


def _auto_mask(frames: list[ClipFrame], camera: Camera) -> np.ndarray | None:
    """``--bonnet auto`` on a clip: what stays put while the road moves."""
    h, w = frames[0].image.shape
    f_px = float(camera.K[0, 0])
    poly, _ = static_body([f.image for f in frames],
                          SearchScale.for_image(w, h, f_px).marking_width_px)
    return None if poly is None else body_search_mask(Bonnet.polygon(poly).mask(w, h))


def test_lines_on_the_car_s_body_alone_are_refused() -> None:
    """An empty road (no markings) with line-like things only on the car's body: the
    clip's static body is found and kept out of the search; the fit is refused."""
    rng = np.random.default_rng(7)
    camera = _body_camera(640, 400)
    clip = render_clip(camera, rng, scene=_empty_scene())
    frames = _body_lines(clip.frames, camera)
    mask = _auto_mask(frames, camera)
    assert mask is not None
    drawn = np.zeros_like(mask)
    for f, g in zip(frames, clip.frames, strict=True):
        drawn |= f.image.astype(int) - g.image.astype(int) > 40
    assert mask[drawn].mean() > 0.99  # the body's lines are all masked
    with pytest.raises(ClipFitError, match="no frame of a straight road"):
        fit_clip(frames, camera.replace(mount=CameraMount()), mask=mask)


def test_a_road_beside_lines_on_the_car_is_fitted_from_the_road_alone() -> None:
    """The same lines on the body over a marked road: the fit uses the road's lines only
    (none of its pixels on the drawn body lines) and recovers the mount."""
    rng = np.random.default_rng(8)
    camera = _body_camera(640, 400)
    clip = render_clip(camera, rng)
    frames = _body_lines(clip.frames, camera)
    drawn = np.zeros(frames[0].image.shape, bool)
    for f, g in zip(frames, clip.frames, strict=True):
        drawn |= f.image.astype(int) - g.image.astype(int) > 40
    mask = _auto_mask(frames, camera)
    fit = fit_clip(frames, camera.replace(mount=CameraMount()), mask=mask)
    for r in fit.frames:
        if r.fit is None:
            continue
        for line in r.fit.lines:
            p = np.rint(line.pixels).astype(int)
            assert not drawn[p[:, 1], p[:, 0]].any(), line.role
    assert abs(fit.camera.mount.height_m - 0.16) < 0.005
    assert abs(math.degrees(fit.camera.mount.pitch_rad) - 14.0) < 0.5


def _cables_frames() -> list[ClipFrame]:
    files = sorted((REFERENCE / "cables-car").glob("frame*.jpg"))
    assert len(files) == 3
    return [ClipFrame(k, float(k), cv2.imread(str(p), cv2.IMREAD_GRAYSCALE))
            for k, p in enumerate(files)]


CABLES_BODY = [[0, 1199], [0, 1010], [170, 740], [230, 680], [620, 680], [1000, 740],
               [1230, 760], [1290, 900], [1390, 1110], [1599, 1160], [1599, 1199]]
"""The cables car's electronics and cables, drawn by hand on its frames [px]: its lower
40 % (the right line, a road marking, passes to its right)."""


def test_the_cables_car_is_fitted_on_the_road_or_refused_never_on_its_cables() -> None:
    """The real 1600×1200 frames with cables in the lower 40 %: the clip's static body
    covers the cables; the fit (focal length unknown) uses no line on them, and either
    gives a plausible mount or is refused naming why."""
    frames = _cables_frames()
    h, w = frames[0].image.shape
    cables = Bonnet.polygon(CABLES_BODY).mask(w, h)
    poly, _ = static_body([f.image for f in frames],
                          SearchScale.for_image(w, h).marking_width_px)
    assert poly is not None
    found = Bonnet.polygon(poly).mask(w, h)
    cable_pixels = (cables & (np.median([f.image for f in frames], axis=0) > 120))
    assert found[cable_pixels].mean() > 0.9  # the bright cables are inside the body found
    mask = body_search_mask(found)
    try:
        camera, _ = clip_focal(frames, mask=mask)
        fit = fit_clip(frames, camera, mask=mask)
    except MountFitError as exc:
        assert str(exc)  # refused, saying why
        lines = exc.lines
    else:
        m = fit.camera.mount
        assert 0.03 <= m.height_m <= 1.0 and -5 <= math.degrees(m.pitch_rad) <= 60
        lines = tuple(ln for r in fit.frames if r.fit is not None for ln in r.fit.lines)
    for line in lines:
        p = np.rint(line.pixels).astype(int)
        assert cables[p[:, 1], p[:, 0]].mean() < 0.02, line.role


def test_frames_that_disagree_are_refused_naming_the_parameter() -> None:
    """Frames of two cars (mounts 6 cm apart in height) in one clip: refused, naming the
    height."""
    a, b = clips()[6], clips()[8]
    assert abs(a.camera.mount.height_m - b.camera.mount.height_m) > 0.02
    other = [ClipFrame(f.index + 100, f.t_s + 10, f.image) for f in render_clip(
        a.camera.with_mount(height_m=a.camera.mount.height_m + 0.06),
        np.random.default_rng(3)).frames]
    with pytest.raises(ClipFitError, match=r"disagree on the (height|pitch)") as err:
        fit_clip(a.frames + other, a.camera.replace(mount=CameraMount()))
    assert err.value.parameter in ("height", "pitch") and err.value.lines


def test_a_lane_width_scales_the_height() -> None:
    """The same clip read with 0.35 m lanes: the height scales by 0.35 / 0.4."""
    clip = clips()[6]
    base = clip.camera.replace(mount=CameraMount())
    wide = fit_clip(clip.frames, base).camera.mount
    narrow = fit_clip(clip.frames, base, lane_width_m=0.35).camera.mount
    assert narrow.height_m == pytest.approx(wide.height_m * 0.35 / 0.4, rel=1e-3)
    assert narrow.pitch_rad == pytest.approx(wide.pitch_rad, abs=1e-3)


def test_sampling_spreads_over_the_clip_with_bounded_memory() -> None:
    frames = (ClipFrame(i, i / 30, np.zeros((2, 2), np.uint8)) for i in range(1000))
    picked = sample_frames(frames, budget=40)
    idx = [f.index for f in picked]
    assert len(idx) <= 40 and idx == sorted(idx) and idx[0] < 50 and idx[-1] > 900
    assert [f.index for f in sample_frames(iter([]), budget=3)] == []
    short = [ClipFrame(i, i, np.zeros((2, 2), np.uint8)) for i in range(5)]
    assert [f.index for f in sample_frames(short, budget=40)] == [0, 1, 2, 3, 4]


def test_time_weights_bridge_a_gap() -> None:
    assert np.allclose(time_weights([0, 1, 2, 3]), 0.25)
    w = time_weights([0.0, 1.0, 3.0, 4.0])  # a frame at 2 s left out
    assert w[1] > w[0] and w[2] > w[3] and w.sum() == pytest.approx(1.0)
    assert np.allclose(time_weights([0.0, 0.0, 0.0]), 1 / 3)  # no time stamps
