"""The detector's fused frame (``fused.detect_frame``) against its reference, the Python
path (``TfaldaDetector(fused=False)``): the same observations and the same state, frame
for frame, on every preset and camera, through curves, gaps, blackouts and forced states."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from tfalda_sim.camera import load_camera
from tfalda_sim.perception import DetectorConfig, StateKind, TfaldaDetector
from tfalda_sim.perception.fused import _round
from tfalda_sim.perception.rois import Roi
from tfalda_sim.perception.segment import LaneSegment
from tfalda_sim.rendering import Effects, Renderer, build_scene
from tfalda_sim.tracks import generate, load_named

FIELDS = ("frame", "rois", "lanes", "d", "intensity", "lam", "replaced", "corrected",
          "widths", "fault_count", "roi_reset", "state", "first_frame", "next_rois")


def assert_same(a: object, b: object, k: int) -> None:
    for name in FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and x.shape == y.shape, (k, name)
            assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), (k, name, x, y)
        else:
            assert type(x) is type(y) and x == y, (k, name, x, y)


class Spy:
    """Counts the frames that took the fused path."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.frames = 0
        original = TfaldaDetector._process_fused

        def counted(det: TfaldaDetector, crops: list[np.ndarray]):  # type: ignore[no-untyped-def]
            self.frames += 1
            return original(det, crops)

        monkeypatch.setattr(TfaldaDetector, "_process_fused", counted)


def weaving_poses(track, n: int, seed: int) -> list[tuple[float, float, float]]:  # type: ignore[no-untyped-def]
    """Poses along the right lane, weaving across it (curve states, rejected rows)."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        s = (0.3 + 0.06 * k) % track.length_m
        lateral = -0.5 * track.lane_width_m + 0.12 * np.sin(0.15 * k) + rng.normal(0, 0.01)
        x, y, h = track.pose(s, lateral)
        out.append((float(x), float(y), float(h) + 0.15 * np.sin(0.11 * k)))
    return out


@pytest.mark.parametrize("camera", ["thesis", "reference-car"])
@pytest.mark.parametrize("preset", ["thesis", "improved", "without_lis", "improved-3-rows"])
def test_fused_frames_equal_the_python_path(monkeypatch: pytest.MonkeyPatch, camera: str,
                                            preset: str) -> None:
    """Frames rendered on demand through the ROIs (crops of one buffer) and whole frames
    (crops that are views of a frame), with blackouts that reset the ROIs."""
    cam = load_camera(camera)
    renderer = Renderer(cam)
    config = (DetectorConfig.improved(rows=3) if preset == "improved-3-rows"
              else getattr(DetectorConfig, preset)()).on_camera(cam)
    assert config.layout.rows == (3 if preset == "improved-3-rows" else 2)
    track = generate(3)
    scene = build_scene(track, Effects(), np.random.default_rng(0))
    spy = Spy(monkeypatch)
    fused, reference = TfaldaDetector(config), TfaldaDetector(config, fused=False)
    resets = replaced = 0
    for k, pose in enumerate(weaving_poses(track, 160, seed=1)):
        blackout = 60 <= k < 80  # rejected rows, then a reset
        if k % 2:
            frame = renderer.render(scene, pose, frame_seed=k)
            frame[:] *= not blackout
            a, b = fused.process(frame), reference.process(frame)
        else:
            assert fused.rois == reference.rois
            crops = renderer.render_windows(scene, pose, fused.rois, frame_seed=k)
            for crop in crops:
                crop[:] *= not blackout
            a, b = fused.process_crops(crops), reference.process_crops(crops)
        assert_same(a, b, k)
        resets += a.roi_reset
        replaced += int(a.replaced.sum())
    assert spy.frames >= 100  # most frames took the fused path
    # the LIS's paths ran: rejected rows (or held lanes, improved) and, in the thesis'
    # configuration, resets
    assert (replaced > 0) == (preset != "without_lis")
    if preset in ("thesis", "without_lis"):  # (the gap hold rides out blackouts, or not)
        assert (resets > 0) == (preset == "thesis")


def test_forced_states_take_the_python_path_and_agree(monkeypatch: pytest.MonkeyPatch
                                                       ) -> None:
    """A forced state (and the frames after it is lifted) on a curve: the fused path
    stands aside while the state is forced, and both detectors agree throughout."""
    renderer = Renderer()
    track = load_named("left-curve")
    scene = build_scene(track, Effects(), np.random.default_rng(0))
    fused, reference = TfaldaDetector(), TfaldaDetector(fused=False)
    spy = Spy(monkeypatch)
    for k, pose in enumerate(weaving_poses(track, 60, seed=2)):
        if k in (20, 40):
            kind = StateKind.RIGHT_CURVE if k == 20 else None
            fused.force_state(kind)
            reference.force_state(kind)
        before = spy.frames
        frame = renderer.render(scene, pose, frame_seed=k)
        assert_same(fused.process(frame), reference.process(frame), k)
        if 20 <= k < 40:
            assert spy.frames == before
    assert spy.frames >= 30


def test_a_pickled_detector_goes_on_the_same() -> None:
    """Mid-drive pickles, with the fused path's caches and without them (a pickle from
    before it), continue as the detector itself."""
    renderer = Renderer()
    track = load_named("left-curve")
    scene = build_scene(track, Effects(), np.random.default_rng(0))
    frames = [renderer.render(scene, pose, frame_seed=k)
              for k, pose in enumerate(weaving_poses(track, 24, seed=3))]
    det = TfaldaDetector()
    for frame in frames[:12]:
        det.process(frame)
    copy = pickle.loads(pickle.dumps(det))
    old = pickle.loads(pickle.dumps(det))
    for name in ("fused", "_previous_of", "_fused_of"):
        old.__dict__.pop(name, None)
    old._previous = [tuple(pair) for pair in old._previous]  # lists of objects, as then
    old._rois = [tuple(pair) for pair in old._rois]
    assert isinstance(copy._previous[0][0], LaneSegment) and isinstance(copy._rois[1][0], Roi)
    for k, frame in enumerate(frames[12:]):
        a = det.process(frame)
        assert_same(a, copy.process(frame), k)
        assert_same(a, old.process(frame), k)


def test_fused_must_be_a_bool() -> None:
    with pytest.raises(TypeError, match="fused must be True or False"):
        TfaldaDetector(fused="no")  # type: ignore[arg-type]


@pytest.mark.parametrize("value", [-3.5, -2.5, -1.5, -0.5, 0.5, 1.5, 2.5, 3.5, 0.49999999999999994,
                                   -0.49999999999999994, 2.5000000000000004, 123.5, 124.5,
                                   1e15 + 0.5, 7.25, -7.75])
def test_round_is_pythons(value: float) -> None:
    assert _round(value) == round(value)
