"""Fit a camera's mount from a clip: many frames of a car driving a straight road.

Each frame is fitted by itself (``fit.fit_mount``); frames that show no straight road
(curves, crossings, no markings) or give no plausible mount are left out. The mount is
what stays the same across the frames that remain:

- **pitch, roll, height**: the medians over the frames that agree (a frame more than
  ``plausible.CLIP_OUTLIER_SPREADS`` tolerances from the median is left out); a spread
  beyond ``plausible.CLIP_TOLERANCES``, or fewer than ``MIN_CLIP_AGREEMENT`` of the
  frames agreeing, is refused naming the parameter.
- **yaw**: a frame's fitted yaw is the mount's yaw plus the car's heading on the road at
  that moment (both turn the camera about the same vertical axis). Every fitted frame's
  road direction (two lines suffice) gives its yaw under the clip's pitch and roll; the
  mount's yaw is their mean over the clip's time (``time_weights``: a frame left out
  does not tilt it) without the quarter of the time at each end (``YAW_TRIM``). The
  assumption is that the car's heading averages out — a car that stays in its lane
  cannot head off to one side for long (its lateral position would drift by
  ∫ v·sin(heading) dt); the cut keeps a curve's entry and exit, where the car is still
  turning, from pulling it. The heading's spread is reported.
- **lateral offset**: a frame's fitted offset is where the camera is in the lane: the
  car's position plus the mount's offset, which no clip of a driving car can tell
  apart. The mount's lateral offset is not fitted from a clip: it is ``lateral_m``
  (default 0, a camera on the car's centre line, or the ``--intrinsics`` profile's);
  the car's position in the lane (median and spread) is reported.

One frame is fitted as before (``fit_mount`` alone: the car parked parallel to the lane
and centred in it, so its heading is taken as 0 and its position as the mount's offset).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

import cv2
import numpy as np

from ..tracks.dimensions import LANE_WIDTH_M
from .bonnet import Bonnet
from .fit import (
    LineFit,
    MountFit,
    MountFitError,
    SearchScale,
    fit_focal,
    fit_mount,
    residual_px,
    road_direction,
)
from .models import Camera, FisheyeCamera
from .mount import CameraMount
from .plausible import (
    CLIP_NOISE_FLOORS,
    CLIP_OUTLIER_SPREADS,
    CLIP_TOLERANCES,
    MIN_CLIP_AGREEMENT,
    ImplausibleMount,
    check_fitted_mount,
)

MAX_CLIP_FRAMES: int = 40
"""Most frames of a clip that are fitted [1], spread over it: enough for robust medians,
few enough for a fit in tens of seconds (each frame is fitted by itself)."""

FOCAL_FRAMES: int = 5
"""Frames whose focal length is fitted by itself with ``--fit-focal`` [1]; their median
is the clip's focal length."""

FOCAL_TRIES: int = 15
"""Frames tried at most to find ``FOCAL_FRAMES`` of straight road [1]."""

MAD_TO_SIGMA: float = 1.4826
"""The median absolute deviation × this is a normal distribution's σ [1]."""


@dataclass(frozen=True)
class ClipFrame:
    """One frame of a clip: its index in the source, its time stamp [s] and the grey
    image (uint8)."""

    index: int
    t_s: float
    image: np.ndarray


@dataclass(frozen=True)
class Spread:
    """One parameter across the frames used: median, robust σ (1.4826 × the median
    absolute deviation), quartiles and the count; in the parameter's own unit."""

    median: float
    sigma: float
    q25: float
    q75: float
    n: int

    @classmethod
    def of(cls, values: Iterable[float]) -> Spread:
        """The spread of ``values`` (at least one)."""
        v = np.asarray(list(values), dtype=np.float64)
        med = float(np.median(v))
        return cls(med, MAD_TO_SIGMA * float(np.median(np.abs(v - med))),
                   float(np.percentile(v, 25)), float(np.percentile(v, 75)), len(v))


@dataclass(frozen=True)
class FrameResult:
    """A frame's own fit (``fit``) or why it has none (``error``); ``agrees``: used for
    the mount."""

    index: int
    t_s: float
    fit: MountFit | None = None
    error: MountFitError | None = None
    agrees: bool = False


@dataclass(frozen=True)
class ClipFit:
    """The mount of a clip: ``camera`` (the profile's), the residual of the agreeing
    frames' line pixels from the model lines (each frame with its own heading and
    position in the lane) [px], the spreads per parameter (``pitch_deg``, ``roll_deg``,
    ``height_m``, ``heading_deg``, ``car_offset_m``, ``residual_px`` and with a fitted
    focal length ``focal_px``), every frame's result, and the frame shown in the overlay
    (``shown``, its fit under the clip's mount)."""

    camera: Camera
    roll_fitted: bool
    residual_px: float
    spreads: dict[str, Spread]
    frames: tuple[FrameResult, ...]
    shown: FrameResult
    shown_fit: MountFit
    lane_width_m: float = LANE_WIDTH_M
    notes: tuple[str, ...] = field(default=())

    @property
    def used(self) -> int:
        """Frames the mount is the median of."""
        return sum(1 for f in self.frames if f.agrees)

    @property
    def fitted(self) -> int:
        """Frames that gave a plausible mount by themselves."""
        return sum(1 for f in self.frames if f.fit is not None)


class ClipFitError(MountFitError):
    """A clip whose frames give no mount; ``frame`` (a ``FrameResult``) is the frame to
    show in an overlay (None: none had lines)."""

    def __init__(self, message: str, *, frame: FrameResult | None = None,
                 fit: MountFit | None = None, **kwargs: object) -> None:
        super().__init__(message, **kwargs)  # type: ignore[arg-type]
        self.frame = frame
        self.fit = fit


def sample_frames(frames: Iterable[ClipFrame], budget: int = MAX_CLIP_FRAMES,
                  seed: int = 0) -> list[ClipFrame]:
    """At most ``budget`` of ``frames`` spread over the whole clip, in order: every
    ``stride``-th frame is kept, the stride doubled whenever twice the budget is held
    (memory stays bounded, the length need not be known), then ``budget`` of them picked
    evenly with a seeded jitter (no aliasing with the dashes' period)."""
    if budget < 1:
        raise ValueError(f"budget must be ≥ 1, got {budget}")
    kept: list[ClipFrame] = []
    stride = 1
    for k, frame in enumerate(frames):
        if k % stride:
            continue
        kept.append(frame)
        if len(kept) >= 2 * budget:
            kept = kept[::2]
            stride *= 2
    if len(kept) <= budget:
        return kept
    rng = np.random.default_rng(seed)
    step = len(kept) / budget
    picks = np.floor((np.arange(budget) + rng.uniform(0.0, 1.0, budget)) * step)
    return [kept[int(i)] for i in np.unique(np.clip(picks, 0, len(kept) - 1))]


def _values(fit: MountFit) -> dict[str, float]:
    m = fit.camera.mount
    return {"pitch": m.pitch_rad, "roll": m.roll_rad, "height": m.height_m,
            "yaw": m.yaw_rad, "offset": fit.camera_offset_m}


def _why_none(results: list[FrameResult]) -> str:
    """The frames' reasons, the most common first: "12 frames: no markings found …"."""
    reasons = Counter(_reason_key(r.error) for r in results if r.error is not None)
    parts = [f"{n}× {why}" for why, n in reasons.most_common(3)]
    return "; ".join(parts)


def _reason_key(error: MountFitError | None) -> str:
    text = str(error)
    return text.split(":")[0] if error is not None and error.parameter is None else text


def frame_fits(frames: Iterable[ClipFrame], camera: Camera, *, mask: np.ndarray | None,
               lane_width_m: float, seed: int = 0) -> Iterator[FrameResult]:
    """Each frame's own fit through ``camera``'s intrinsics (or why it has none)."""
    for frame in frames:
        try:
            fit = fit_mount(frame.image, camera, lane_width_m=lane_width_m, mask=mask,
                            seed=seed)
        except MountFitError as exc:
            yield FrameResult(frame.index, frame.t_s, error=exc)
        else:
            yield FrameResult(frame.index, frame.t_s, fit=fit)


def combine(results: list[FrameResult], camera: Camera, *, lateral_m: float = 0.0,
            lane_width_m: float = LANE_WIDTH_M, focal: Spread | None = None,
            headings: list[tuple[float, np.ndarray]] | None = None) -> ClipFit:
    """The clip's mount from its frames' own fits (see the module's docstring);
    ``camera`` gives the intrinsics, forward offset, body and frame rate; ``headings``
    (time [s], road direction in the camera frame) of more frames give the yaw instead
    of the fitted frames' own directions. Raises ``ClipFitError`` naming the parameter the
    frames disagree on, or why no frame fits."""
    fitted = [r for r in results if r.fit is not None]
    if not fitted:
        shown = next((r for r in results if r.error is not None and r.error.lines), None)
        raise ClipFitError(f"no frame of a straight road with the lane's markings among "
                           f"{len(results)} frame(s): {_why_none(results)}", frame=shown,
                           lines=shown.error.lines if shown and shown.error else (),
                           camera=shown.error.camera if shown and shown.error else None,
                           parameter=shown.error.parameter if shown and shown.error else None,
                           lane_width_m=lane_width_m)
    three = [r for r in fitted if r.fit is not None and r.fit.roll_fitted]
    roll_fitted = len(three) >= 2 or len(three) == len(fitted)
    use = three if roll_fitted else [r for r in fitted if r.fit is not None
                                     and not r.fit.roll_fitted]
    values = [_values(r.fit) for r in use if r.fit is not None]
    checked = ("pitch", "roll", "height") if roll_fitted else ("pitch", "height")
    agree = np.ones(len(use), bool)
    limits: dict[str, float] = {}
    for name in checked:
        v = np.array([x[name] for x in values])
        spread = Spread.of(v)
        tol = CLIP_TOLERANCES[name]
        limits[name] = max(tol.absolute, tol.relative * abs(spread.median))
        band = CLIP_OUTLIER_SPREADS * max(CLIP_NOISE_FLOORS[name], spread.sigma)
        agree &= np.abs(v - spread.median) <= band
    if agree.sum() < MIN_CLIP_AGREEMENT * len(use):  # name the worst parameter
        raise _disagreement(use, values, checked, limits, "agree")
    kept = [x for x, a in zip(values, agree, strict=True) if a]
    for name in checked:
        s = Spread.of(x[name] for x in kept)
        if s.sigma > limits[name]:
            raise _disagreement([r for r, a in zip(use, agree, strict=True) if a], kept,
                                (name,), limits, "spread")
    med = {name: float(np.median([x[name] for x in kept])) for name in
           ("pitch", "roll", "height")}
    if not roll_fitted:
        med["roll"] = 0.0
    # Every fitted frame's road direction (two lines suffice) under the clip's pitch and
    # roll: its yaw, if the direction lies on the clip's horizon.
    band = CLIP_OUTLIER_SPREADS * limits["pitch"]
    directions = headings if headings else [
        (r.t_s, r.fit.camera.mount.rotation()[:, 0]) for r in fitted if r.fit is not None]
    timed: list[tuple[float, float]] = []  # (time, yaw)
    for t_s, direction in directions:
        yaw, off_horizon = yaw_on_horizon(direction, med["pitch"], med["roll"])
        if abs(off_horizon) <= band:
            timed.append((t_s, yaw))
    if not timed:  # the fitted frames' own, then
        timed = [(r.t_s, _values(r.fit)["yaw"]) for r in use if r.fit is not None]
    timed.sort(key=lambda x: x[0])
    yaw_values = np.array([y for _, y in timed])
    med["yaw"] = trimmed_mean(yaw_values, time_weights([t for t, _ in timed]))
    try:
        check_fitted_mount(med["height"], med["pitch"], med["roll"], med["yaw"])
        mount = CameraMount(height_m=med["height"], forward_m=camera.mount.forward_m,
                            lateral_m=lateral_m, pitch_rad=med["pitch"],
                            roll_rad=med["roll"], yaw_rad=med["yaw"])
    except ImplausibleMount as exc:  # the medians of plausible frames: hardly ever
        raise ClipFitError(f"the frames' median mount: {exc}", parameter=exc.parameter,
                           lane_width_m=lane_width_m) from None
    result_camera = camera.replace(mount=mount)
    frames_out = []
    used_iter = iter(agree)
    use_ids = {id(r) for r in use}
    for r in results:
        a = bool(next(used_iter)) if id(r) in use_ids else False
        frames_out.append(FrameResult(r.index, r.t_s, r.fit, r.error, a))
    agreeing = [r for r in frames_out if r.agrees]
    # Each agreeing frame under the clip's pitch, roll and height, with its own heading
    # (yaw) and position in the lane: the residual of the clip's mount.
    sq, count, best = 0.0, 0, None
    for r in agreeing:
        assert r.fit is not None
        own = r.fit.camera.mount
        virtual = camera.replace(mount=CameraMount(
            height_m=med["height"], forward_m=own.forward_m, lateral_m=own.lateral_m,
            pitch_rad=med["pitch"], roll_rad=med["roll"], yaw_rad=own.yaw_rad))
        centre_y = lane_width_m / 2  # the virtual camera is at the frame's own offset
        res = residual_px(virtual, [ln for ln in r.fit.lines if ln.role != "other"],
                          centre_y, lane_width_m, _inlier_px(camera))
        n = sum(len(ln.pixels) for ln in r.fit.lines if ln.role != "other")
        if math.isfinite(res):
            sq += res * res * n
            count += n
        if best is None or res < best[0]:
            best = (res, r, MountFit(virtual, r.fit.lines, res, roll_fitted, r.fit.focal_px,
                                     lane_width_m))
    assert best is not None
    residual = math.sqrt(sq / count) if count else math.inf
    spreads = {
        "pitch_deg": Spread.of(math.degrees(x["pitch"]) for x in kept),
        "roll_deg": Spread.of(math.degrees(x["roll"]) for x in kept),
        "height_m": Spread.of(x["height"] for x in kept),
        "heading_deg": Spread.of(np.degrees(yaw_values - med["yaw"])),
        "car_offset_m": Spread.of(x["offset"] - lateral_m for x in kept),
        "residual_px": Spread.of(r.fit.residual_px for r in agreeing if r.fit is not None),
    }
    if focal is not None:
        spreads["focal_px"] = focal
    notes = []
    if not roll_fitted:
        notes.append("roll not fitted: too few frames show three lines; taken as 0")
    return ClipFit(result_camera, roll_fitted, residual, spreads, tuple(frames_out),
                   best[1], best[2], lane_width_m, tuple(notes))


def yaw_on_horizon(direction: np.ndarray, pitch_rad: float, roll_rad: float
                   ) -> tuple[float, float]:
    """(yaw, elevation) [rad] of a road ``direction`` (camera frame) for a camera pitched
    ``pitch_rad`` and rolled ``roll_rad``: the yaw that turns the camera's view onto it
    (the mount's yaw plus the car's heading), and how far above the camera's horizon it
    lies (0 for a road on the ground the camera's pitch and roll describe)."""
    cp, sp = math.cos(pitch_rad), math.sin(pitch_rad)
    cr, sr = math.cos(roll_rad), math.sin(roll_rad)
    pitch = np.array([[1.0, 0.0, 0.0], [0.0, cp, -sp], [0.0, sp, cp]])
    roll = np.array([[cr, -sr, 0.0], [sr, cr, 0.0], [0.0, 0.0, 1.0]])
    u = pitch.T @ roll.T @ (direction / np.linalg.norm(direction))
    return math.atan2(u[0], u[2]), -math.asin(max(-1.0, min(1.0, float(u[1]))))


YAW_TRIM: float = 0.25
"""The yaw is the mean of the frames' yaws with this share of the weight cut off at each
end [1] (the interquartile mean): the mean is what a car that stays in its lane averages
out to, and a weaving car's headings gather at both ends of its swing (a median falls
into one of them); the cut keeps a curve's entry and exit, where the car is still
turning, and a wrong fit from pulling it."""


def trimmed_mean(values: np.ndarray, weights: np.ndarray, trim: float = YAW_TRIM) -> float:
    """The weighted mean of ``values`` without the lowest and highest ``trim`` of the
    weight (a value at a cut counts with the part of its weight inside)."""
    order = np.argsort(values)
    v, w = values[order], weights[order] / np.sum(weights)
    hi = np.cumsum(w)
    lo = hi - w
    inside = np.clip(np.minimum(hi, 1.0 - trim) - np.maximum(lo, trim), 0.0, None)
    if inside.sum() <= 0:  # one value
        return float(np.sum(v * w))
    return float(np.sum(v * inside) / inside.sum())


GAP_BRIDGE_INTERVALS: float = 2.0
"""``time_weights`` bridges a gap between frames up to this many median intervals [1]:
a frame or two left out (a wrong fit) is bridged, a curve's time is not."""


def time_weights(times_s: list[float]) -> np.ndarray:
    """Weights (sum 1) of frames at ``times_s`` [s] for a mean over the clip's time: each
    frame stands for the time from halfway to its previous frame to halfway to its next
    (the end frames for as long as their one neighbour's half interval, twice; a gap no
    longer than ``GAP_BRIDGE_INTERVALS`` intervals), so a frame or two left out does not
    tilt the mean toward their neighbours' side; equal weights when the times do not
    increase (no time stamps)."""
    t = np.asarray(times_s, dtype=np.float64)
    n = len(t)
    if n < 3 or not np.all(np.isfinite(t)) or not np.all(np.diff(t) > 0):
        return np.full(n, 1.0 / max(n, 1))
    # A long gap is time off the straight (a curve): bridged no further than twice the
    # usual interval, or the frames at a curve's ends, still turning, would weigh most.
    gaps = np.diff(t)
    gaps = np.minimum(gaps, GAP_BRIDGE_INTERVALS * float(np.median(gaps)))
    w = np.empty(n)
    w[1:-1] = 0.5 * (gaps[:-1] + gaps[1:])
    w[0], w[-1] = gaps[0], gaps[-1]
    return w / w.sum()


def _inlier_px(camera: Camera) -> float:
    f_px = float(np.sqrt(camera.K[0, 0] * camera.K[1, 1]))
    return SearchScale.for_image(camera.width, camera.height, f_px).inlier_px


_SHOWN = {"pitch": (math.degrees(1.0), "°", "{:.1f}"), "roll": (math.degrees(1.0), "°", "{:.1f}"),
          "height": (1000.0, " mm", "{:.0f}"), "focal": (1.0, " px", "{:.0f}")}


def _disagreement(use: list[FrameResult], values: list[dict[str, float]],
                  names: tuple[str, ...], limits: dict[str, float], kind: str) -> ClipFitError:
    """The refusal of frames that disagree: the parameter whose values spread most
    beyond its tolerance, its range and the tolerance."""
    def excess(name: str) -> float:
        return Spread.of(x[name] for x in values).sigma / limits[name]

    name = max(names, key=excess)
    v = np.array([x[name] for x in values])
    scale, unit, fmt = _SHOWN[name]
    sigma = Spread.of(v).sigma
    tol = CLIP_TOLERANCES[name]
    what = (f"{len(values)} frames of straight road disagree on the {name}: "
            f"{fmt.format(v.min() * scale)}–{fmt.format(v.max() * scale)}{unit} (spread "
            f"{fmt.format(sigma * scale)}{unit}, more than the "
            f"{fmt.format(limits[name] * scale)}{unit} allowed: {tol.why})")
    if kind == "agree":
        what += (f"; fewer than {MIN_CLIP_AGREEMENT:.0%} agree: the lines found are not one "
                 "camera's view of the road's markings")
    else:
        what += ": the lines found are not the road's markings in every frame"
    shown = use[int(np.argmax(np.abs(v - np.median(v))))]
    fit = shown.fit
    return ClipFitError(what, frame=shown, fit=fit, parameter=name,
                        lines=fit.lines if fit else (), camera=fit.camera if fit else None,
                        lane_width_m=fit.lane_width_m if fit else LANE_WIDTH_M)


def fit_clip(frames: list[ClipFrame], camera: Camera, *, mask: np.ndarray | None = None,
             lane_width_m: float = LANE_WIDTH_M, lateral_m: float = 0.0, seed: int = 0,
             heading_frames: list[ClipFrame] | None = None) -> ClipFit:
    """The mount of ``camera`` (its intrinsics, forward offset, body and frame rate kept)
    from the clip's grey ``frames``; ``mask`` (``(H, W)`` bool) the car's body, kept out
    of the marking search; ``heading_frames`` (more frames, any one size, e.g. smaller:
    ``HeadingSample``) give the yaw from their road directions. See the module's
    docstring."""
    if not frames:
        raise ClipFitError("the clip has no frames")
    results = list(frame_fits(frames, camera, mask=mask, lane_width_m=lane_width_m,
                              seed=seed))
    headings = None
    if heading_frames:
        small = scaled_camera(camera, *heading_frames[0].image.shape[::-1])
        small_mask = None
        if mask is not None:
            small_mask = cv2.resize(mask.astype(np.uint8), (small.width, small.height),
                                    interpolation=cv2.INTER_AREA) > 0
        headings = []
        for f in heading_frames:
            direction = road_direction(f.image, small, mask=small_mask, seed=seed)
            if direction is not None:
                headings.append((f.t_s, direction))
    return combine(results, camera, lateral_m=lateral_m, lane_width_m=lane_width_m,
                   headings=headings)


HEADING_FRAMES: int = 240
"""Most frames whose road direction gives the yaw [1]: a weaving car's heading swings
by ±10° and more, its mean over a few frames is off by degrees; the directions alone
are cheap (no mount fitted, smaller frames)."""

HEADING_WIDTH_PX: int = 480
"""The heading frames are scaled down to at most this width [px]: the vanishing point
needs no more."""


def scaled_camera(camera: Camera, width: int, height: int) -> Camera:
    """``camera``'s lens for its image scaled to ``width``×``height`` [px] (pixel centres
    kept: u' + ½ = (u + ½) · width / camera.width); no body."""
    sx, sy = width / camera.width, height / camera.height
    K = camera.K.copy()
    K[0, :] *= sx
    K[1, :] *= sy
    K[0, 2] = (camera.K[0, 2] + 0.5) * sx - 0.5
    K[1, 2] = (camera.K[1, 2] + 0.5) * sy - 0.5
    return camera.replace(K=K, width=width, height=height, bonnet=Bonnet.none())


class HeadingSample:
    """Every ``stride``-th frame of a clip, scaled to at most ``HEADING_WIDTH_PX`` wide,
    the stride doubled whenever ``HEADING_FRAMES`` are held (memory bounded, regular in
    time: no aliasing with a weave slower than a few strides)."""

    def __init__(self, budget: int = HEADING_FRAMES, width_px: int = HEADING_WIDTH_PX
                 ) -> None:
        self.budget, self.width_px = budget, width_px
        self.frames: list[ClipFrame] = []
        self._stride, self._count = 1, 0

    def add(self, frame: ClipFrame) -> None:
        """Offer the clip's next frame."""
        k = self._count
        self._count += 1
        if k % self._stride:
            return
        h, w = frame.image.shape
        if w > self.width_px:
            size = (self.width_px, max(1, int(round(h * self.width_px / w))))
            frame = ClipFrame(frame.index, frame.t_s,
                              cv2.resize(frame.image, size, interpolation=cv2.INTER_AREA))
        self.frames.append(frame)
        if len(self.frames) >= self.budget:
            self.frames = self.frames[::2]
            self._stride *= 2


def clip_focal(frames: list[ClipFrame], *, mask: np.ndarray | None = None,
               lane_width_m: float = LANE_WIDTH_M, seed: int = 0
               ) -> tuple[FisheyeCamera, Spread]:
    """An equidistant fisheye's focal length for the clip (``--fit-focal``): each of up to
    ``FOCAL_FRAMES`` frames of straight road (of ``FOCAL_TRIES`` tried, spread over the
    clip) fitted by itself (``fit_focal``), the median of those that agree; frames that
    disagree beyond ``CLIP_TOLERANCES["focal"]`` are refused (calibrate the lens)."""
    h, w = frames[0].image.shape
    order = _spread_order(len(frames))[:FOCAL_TRIES]
    focals: list[float] = []
    errors: list[FrameResult] = []
    for k in order:
        fr = frames[k]
        try:
            fit = fit_focal(fr.image, w, h, seed=seed, lane_width_m=lane_width_m, mask=mask)
        except MountFitError as exc:
            errors.append(FrameResult(fr.index, fr.t_s, error=exc))
            continue
        focals.append(fit.focal_px)
        if len(focals) >= FOCAL_FRAMES:
            break
    if not focals:
        raise ClipFitError(f"no focal length fits any of {len(order)} frames tried: "
                           f"{_why_none(errors)}")
    spread = Spread.of(focals)
    tol = CLIP_TOLERANCES["focal"]
    limit = max(tol.absolute, tol.relative * spread.median)
    v = np.array(focals)
    agree = v[np.abs(v - spread.median) <= CLIP_OUTLIER_SPREADS * max(limit, spread.sigma)]
    kept = Spread.of(agree)
    if kept.sigma > limit or len(agree) < MIN_CLIP_AGREEMENT * len(v):
        raise ClipFitError(f"{len(v)} frames fit focal lengths {v.min():.0f}–{v.max():.0f} px "
                           f"(spread {Spread.of(v).sigma:.0f} px, more than the "
                           f"{limit:.0f} px of one lens): the lens cannot be fitted from "
                           "these frames; calibrate it (--intrinsics)", parameter="focal")
    f = kept.median
    K = np.array([[f, 0.0, (w - 1) / 2], [0.0, f, (h - 1) / 2], [0.0, 0.0, 1.0]])
    return FisheyeCamera(K, np.zeros(4), width=w, height=h), kept


def _spread_order(n: int) -> list[int]:
    """0..n−1 in an order that spreads over the range early: the middle, the quarters,
    the eighths, … (a clip's straight frames may be anywhere)."""
    order: list[int] = []
    seen: set[int] = set()
    parts = 1
    while len(order) < n:
        for k in range(parts):
            i = min(n - 1, int((k + 0.5) * n / parts))
            if i not in seen:
                seen.add(i)
                order.append(i)
        parts *= 2
        if parts > 2 * n:
            order += [i for i in range(n) if i not in seen]
            break
    return order


__all__ = [
    "ClipFit",
    "ClipFitError",
    "ClipFrame",
    "FrameResult",
    "HeadingSample",
    "LineFit",
    "Spread",
    "clip_focal",
    "combine",
    "fit_clip",
    "frame_fits",
    "sample_frames",
    "scaled_camera",
    "time_weights",
    "trimmed_mean",
]
