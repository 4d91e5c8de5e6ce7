"""TFALDA with the Lane Inference System, frame by frame (listing A.2 ``notify``).

Per frame: for every ROI, pre-process and search the candidates, then pick the lane —
the largest ``I`` in a first frame, else the smallest λ (listing 3.1) against that ROI's
lane of the last frame; then (not in a first frame) the LIS checks and corrects the lanes;
then the ROIs of the next frame are placed from the lanes and the driving state. When the
fault counter passes its limit, the ROIs go back to table 2.4 and the next frame is a first
frame again (section 2.4; reported in the frame that caused it).

Works on any 8-bit grayscale sequence: ``process(frame)`` takes whole frames,
``process_crops(crops)`` only the pixels of ``rois`` (what the simulator renders on demand).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .candidates import (
    find_lane_in_crop,
    resample_shape,
    segment_steps,
    sobel_horizontal_edges,
)
from .fused import LEFT_CURVE, RIGHT_CURVE, STRAIGHT, FusedParams, detect_frame, fused_params
from .lis import LaneInferenceSystem, LisResult, Rows
from .params import DetectorConfig, EdgeMode, RoiLayout, TfaldaConfig
from .rois import (
    LaneChangeState,
    Roi,
    StateKind,
    StraightState,
    classify,
    follow,
    initial_rois,
    row_geometry,
    row_lambda_scales,
    state_of,
    windows,
)
from .segment import LaneSegment


@dataclass(frozen=True)
class LaneObservation:
    """One frame's result. Arrays index the ROIs row by row, top row first, left before
    right: for the thesis' two rows 0 upper-left, 1 upper-right, 2 lower-left,
    3 lower-right (table 2.4's order)."""

    frame: int
    """Frames processed before this one since the detector was made (0-based)."""
    rois: np.ndarray
    """(n, 4) int32: the ROIs ``(x, y, w, h)`` [px] this frame was read through."""
    lanes: np.ndarray
    """(n, 4) float64: each lane's ends ``(x_top, y_top, x_bottom, y_bottom)`` [px]."""
    d: np.ndarray
    """(n,) float64: D = x_bottom − x_top [px]."""
    intensity: np.ndarray
    """(n,) float64: I, the summed gradient along the lane (resampled gradient units)."""
    lam: np.ndarray
    """(n,) float64: λ of the distance function; NaN where the first-frame rule chose."""
    replaced: np.ndarray
    """(n,) bool: the LIS rejected this frame's lane and kept the last frame's (its row's
    width checks, or the gap hold of an improved configuration)."""
    corrected: np.ndarray
    """(n,) bool: the vertical check moved the lane's upper end."""
    widths: np.ndarray
    """(rows, 2) float64: the low-pass filtered lane width at each row's top and bottom
    edge [px] (the measured ones in a first frame or with the filter off)."""
    fault_count: int
    roi_reset: bool
    """The fault counter passed its limit in this frame: the next frame starts afresh."""
    state: StateKind
    """The driving state the next ROIs were placed in (the topmost row's that is not
    straight; rows classify themselves unless a state is forced)."""
    first_frame: bool
    """This frame was a first frame (start or after a reset): largest I, no LIS."""
    next_rois: np.ndarray
    """(n, 4) int32: the ROIs of the next frame."""

    @property
    def n_rows(self) -> int:
        return len(self.widths)

    @property
    def accepted(self) -> np.ndarray:
        """(n,) bool: the ROIs with a lane of this frame's that the LIS kept (a lane, not
        replaced by last frame's): the detections of a replay, a recording's kept lanes."""
        return np.all(np.isfinite(self.lanes), axis=1) & ~self.replaced


_FUSED_STATES = {STRAIGHT: StateKind.STRAIGHT, LEFT_CURVE: StateKind.LEFT_CURVE,
                 RIGHT_CURVE: StateKind.RIGHT_CURVE}

_SEGMENTS: dict[tuple[tuple[int, ...], float], tuple[np.ndarray, np.ndarray]] = {}
"""``_segments_for``'s tables by crop shape and resample factor (the ROIs' few heights
and widths; bounded)."""


def _segments_for(shape: tuple[int, ...], config: TfaldaConfig
                  ) -> tuple[np.ndarray, np.ndarray]:
    """``segment_steps`` of a crop of ``shape`` resampled by ``config``, looked up (per
    ROI and frame: the shape's resampling and the table's key cost µs)."""
    key = (shape, config.resample_factor)
    found = _SEGMENTS.get(key)
    if found is None:
        if len(_SEGMENTS) >= 256:
            _SEGMENTS.clear()
        found = _SEGMENTS[key] = segment_steps(*resample_shape(*shape, config))
    return found


def _lane_of(row: list[float]) -> LaneSegment:
    """The lane of a row of ``fused.detect_frame``'s table."""
    return LaneSegment(row[0], row[4], row[5], row[1], row[3], row[6])


class _Pairs(Sequence[tuple[Any, Any]]):
    """(left, right) per ROI row, made from the rows of ``table`` (two per ROI row) by
    ``make`` when first asked for: the fused path hands the next frame its inputs as
    arrays; the objects are made only for the Python path (≈ 11 µs a frame otherwise)."""

    __slots__ = ("_make", "_pairs", "table")

    def __init__(self, table: np.ndarray, make: Callable[[Any], Any]) -> None:
        self.table = table
        self._make = make
        self._pairs: list[tuple[Any, Any]] | None = None

    def _made(self) -> list[tuple[Any, Any]]:
        if self._pairs is None:
            items = [self._make(row) for row in self.table.tolist()]
            self._pairs = [(items[k], items[k + 1]) for k in range(0, len(items), 2)]
        return self._pairs

    def __getitem__(self, index):  # type: ignore[no-untyped-def,override]
        return self._made()[index]

    def __iter__(self) -> Iterator[tuple[Any, Any]]:
        return iter(self._made())

    def __len__(self) -> int:
        return len(self.table) // 2


def _lane_table(rows: Sequence[tuple[LaneSegment, LaneSegment]]) -> np.ndarray:
    """The lanes of ``rows`` as one table (n, 7): ``x_top, y_top, x_bottom, y_bottom, d,
    i, λ`` per lane (``LaneObservation``'s arrays, ``fused.detect_frame``'s rows)."""
    return np.array([(ln.p, ln.y_top, ln.p + ln.d, ln.y_bottom, ln.d, ln.i, ln.lam)
                     for pair in rows for ln in pair], dtype=np.float64).reshape(-1, 7)


def _roi_of(row: list[int]) -> Roi:
    """The ROI of a row ``(x, y, width, height)`` [px] of ``fused.detect_frame``'s."""
    return Roi(row[0], row[1], row[2], row[3])


def check_frame(frame: object, width: int, height: int) -> np.ndarray:
    """``frame`` if it is a (height, width) uint8 array, else a ValueError/TypeError that
    names what was given and how to fix it."""
    if not isinstance(frame, np.ndarray):
        raise TypeError(f"frame must be a numpy array, got {type(frame).__name__}")
    if frame.dtype != np.uint8:
        raise ValueError(f"frame must be uint8 grayscale, got dtype {frame.dtype}; convert "
                         "with cv2.convertScaleAbs or frame.astype(np.uint8) after scaling")
    if frame.ndim == 3 and frame.shape[2] in (1, 3, 4):
        raise ValueError(f"frame must be 2-D grayscale, got shape {frame.shape}; use "
                         "frame[..., 0] for one channel or cv2.cvtColor(frame, "
                         "cv2.COLOR_BGR2GRAY) for colour")
    if frame.shape != (height, width):
        raise ValueError(f"frame must have shape ({height}, {width}), got {frame.shape}; "
                         f"resize with cv2.resize(frame, ({width}, {height}))")
    return frame


class TfaldaDetector:
    """TFALDA + LIS on a frame sequence. ``config`` selects each stage
    (``DetectorConfig.thesis()``, ``.without_lis()``, ``.improved()``).

    ``fused``: frames after a first frame go through one numba call (``fused``) where it
    applies (no forced state, no lane change); False keeps every frame on the Python
    path, the reference it equals."""

    def __init__(self, config: DetectorConfig | None = None, *, fused: bool = True) -> None:
        if not isinstance(fused, bool):
            raise TypeError(f"fused must be True or False, got {fused!r}")
        self.config = config or DetectorConfig.thesis()
        self.fused = fused
        self.lis = LaneInferenceSystem(self.config.lis, self.config.layout.rows)
        self._lambda_scale = row_lambda_scales(self.config.layout)
        self._initial_rois: tuple[RoiLayout, tuple[tuple[Roi, Roi], ...]] | None = None
        self._frames = 0
        self._forced: StateKind | None = None
        self.reset()

    # ----------------------------------------------------------------- state
    def reset(self) -> None:
        """Back to table 2.4's ROIs; the next frame is a first frame (section 2.4)."""
        # Table 2.4's ROIs of the layout, kept (immutable ROIs; ~25 µs each time computed,
        # and the env restarts its detector every episode).
        layout = self.config.layout
        kept = getattr(self, "_initial_rois", None)  # unpickled from before it: None
        if kept is None or kept[0] is not layout:
            kept = self._initial_rois = (layout, tuple(initial_rois(layout)))
        self._rois: Sequence[tuple[Roi, Roi]] = list(kept[1])
        self._previous: Sequence[tuple[LaneSegment, LaneSegment]] | None = None  # last
        # frame's final lanes (a _Pairs after a fused frame)
        self._fresh_side: list[list[bool]] | None = None  # lane change: sides to re-find
        self._state = state_of(self._forced) if self._forced else StraightState()
        self.lis.reset()

    def restart(self) -> None:
        """A new frame sequence: what a new detector of the same config would do next
        (``reset``, the frame count from 0 and no imposed state), without building one."""
        self._frames = 0
        self._forced = None
        self.reset()

    def force_state(self, kind: StateKind | None) -> None:
        """Impose a driving state from outside (section 2.3.2), e.g. a planned lane change;
        ``None`` hands the choice back to the detector."""
        if kind in (StateKind.LANE_CHANGE_LEFT, StateKind.LANE_CHANGE_RIGHT) and not (
                self.config.lis.lane_change_state):
            raise ValueError("lane-change states need LisConfig(lane_change_state=True)")
        self._forced = kind
        self._state = state_of(kind) if kind is not None else StraightState()

    @property
    def rois(self) -> list[tuple[int, int, int, int]]:
        """The ``(x, y, w, h)`` windows [px] the next frame is read through."""
        return list(self._windows()[0])

    def _windows(self) -> tuple[list[tuple[int, int, int, int]], np.ndarray]:
        """``windows`` of the current ROIs and the same as an int32 array, made once per
        set of ROIs (a frame asks for them four times). The ROI lists are replaced, never
        changed in place, so the list itself is the key (and kept alive by the cache)."""
        cached = getattr(self, "_windows_of", None)  # None: unpickled from before it
        if cached is None or cached[0] is not self._rois:
            wins = windows(self._rois)
            cached = self._windows_of = (self._rois, wins, np.array(wins, dtype=np.int32))
        return cached[1], cached[2]

    # ----------------------------------------------------------------- frames
    def process(self, frame: np.ndarray) -> LaneObservation:
        """Detect the lanes in a whole ``(480, 752)`` uint8 frame."""
        layout = self.config.layout
        check_frame(frame, layout.image_width, layout.image_height)
        return self._process([frame[y:y + h, x:x + w] for x, y, w, h in self.rois])

    def process_crops(self, crops: list[np.ndarray]) -> LaneObservation:
        """Detect the lanes from the crops of ``rois`` only (same order and sizes)."""
        wins = self._windows()[0]
        if len(crops) != len(wins):
            raise ValueError(f"expected {len(wins)} crops (one per ROI), got {len(crops)}")
        for k, (crop, (_, _, w, h)) in enumerate(zip(crops, wins, strict=True)):
            if not isinstance(crop, np.ndarray) or crop.dtype != np.uint8 or crop.shape != (h, w):
                given = (f"{crop.shape} {crop.dtype}" if isinstance(crop, np.ndarray)
                         else type(crop).__name__)
                raise ValueError(f"crop {k} must be a ({h}, {w}) uint8 array for ROI "
                                 f"{wins[k]}, got {given}")
        return self._process(crops)

    def _process(self, crops: list[np.ndarray]) -> LaneObservation:
        if (self._previous is not None and self._fresh_side is None and self._forced is None
                and not isinstance(self._state, LaneChangeState)
                and getattr(self, "fused", True)):  # unpickled from before it: fused
            return self._process_fused(crops)
        cfg = self.config
        first = self._previous is None
        rois_used = self._rois
        rois_array = self._windows()[1]
        rows: Rows = []
        held = np.zeros(2 * len(rois_used), dtype=bool)
        for r, pair in enumerate(rois_used):
            found = []
            for side, roi in enumerate(pair):
                prev = None if first else self._previous[r][side]
                if self._fresh_side is not None and self._fresh_side[r][side]:
                    prev = None
                lane = self._find(crops[2 * r + side], roi, prev, self._lambda_scale[r])
                if prev is not None and lane.i < cfg.lis.gap_hold_ratio * prev.i:
                    lane = prev  # no marking here (a gap): keep the last lane
                    held[2 * r + side] = True
                found.append(lane)
            rows.append((found[0], found[1]))
        self._fresh_side = None
        result: LisResult | None = None
        if first:
            self.lis.start(rows)
            final = rows
        else:
            result = self.lis.infer(rows, self._previous)
            final = result.rows
        widths = result.widths if result is not None else self.lis.widths.copy()
        reset = result is not None and result.roi_reset_due
        # ROIs of the next frame (listing A.2 places none after a first frame).
        base = final if (cfg.lis.roi_from_current_lanes or first) else self._previous
        if reset:
            state_kind = self._state.kind
        else:
            state_kind = self._place(base, final, first)
        # One table of the lanes' numbers (one array made, not four): x_top, y_top,
        # x_bottom, y_bottom, d, i, λ per lane.
        table = _lane_table(final)
        replaced = held
        if result is not None:
            for r, row_replaced in enumerate(result.replaced):
                if row_replaced:
                    replaced[2 * r:2 * r + 2] = True
        obs = self._observation(
            rois_array, table, replaced,
            (np.array([c for pair in result.corrected for c in pair], dtype=bool)
             if result is not None else np.zeros(2 * len(final), dtype=bool)),
            np.asarray(widths, dtype=np.float64), self.lis.fault_count, reset, state_kind,
            first)
        self._frames += 1
        if reset:
            self.reset()
        else:
            self._previous = final
        object.__setattr__(obs, "next_rois", self._windows()[1].copy())
        return obs

    def _process_fused(self, crops: list[np.ndarray]) -> LaneObservation:
        """``_process`` of a frame after a first frame in one numba call
        (``fused.detect_frame``; no forced state, no lane change, no side searched
        afresh): the same results, the same state after it."""
        rois_array = self._windows()[1]
        tcfg = self.config.tfalda
        params = self._fused_params()
        previous = self._previous_table()
        lis = self.lis
        final, marks, widths, fault_count, reset, state, placed = detect_frame(
            tuple(crops), tuple([_segments_for(c.shape, tcfg) for c in crops]),
            rois_array, previous, lis.widths, lis.fault_count, params.flags, params.reals,
            params.layout, params.rows)
        lis.widths = widths
        lis.fault_count = fault_count
        obs = self._observation(
            rois_array, final, marks[:, 0].copy(), marks[:, 1].copy(), widths.copy(),
            fault_count, reset, self._state.kind if state < 0 else _FUSED_STATES[state], False)
        self._frames += 1
        if reset:
            self.reset()
        else:
            self._previous = _Pairs(final, _lane_of)
            if placed is not rois_array:
                self._rois = _Pairs(placed, _roi_of)
                self._windows_of = (self._rois, [tuple(w) for w in placed.tolist()], placed)
        object.__setattr__(obs, "next_rois", self._windows()[1].copy())
        return obs

    def _observation(self, rois: np.ndarray, table: np.ndarray, replaced: np.ndarray,
                     corrected: np.ndarray, widths: np.ndarray, fault_count: int, reset: bool,
                     state: StateKind, first: bool) -> LaneObservation:
        """The frame's observation from its lanes' ``table`` (n, 7) (``x_top, y_top,
        x_bottom, y_bottom, d, i, λ``); ``next_rois`` is set once the ROIs are placed."""
        return LaneObservation(
            frame=self._frames, rois=rois.copy(), lanes=table[:, :4].copy(),
            d=table[:, 4].copy(), intensity=table[:, 5].copy(), lam=table[:, 6].copy(),
            replaced=replaced, corrected=corrected, widths=widths, fault_count=fault_count,
            roi_reset=reset, state=state, first_frame=first,
            next_rois=np.empty((0, 4), np.int32))

    def _previous_table(self) -> np.ndarray:
        """The last frame's final lanes as ``fused.detect_frame`` reads them (n, 7): the
        table of the last fused frame, else made from the lanes."""
        previous = self._previous
        if isinstance(previous, _Pairs):
            return previous.table
        kept = getattr(self, "_previous_of", None)
        if kept is not None and kept[0] is previous:
            return kept[1]
        assert previous is not None
        table = _lane_table(previous)
        self._previous_of = (previous, table)
        return table

    def _fused_params(self) -> FusedParams:
        """``fused_params`` of this detector's configuration, made once (the ROI rows keep
        the layout's heights, ``row_geometry``: ROIs move sideways only)."""
        kept = getattr(self, "_fused_of", None)
        if kept is None or kept[0] is not self.config:
            kept = self._fused_of = (self.config, fused_params(
                self.config, self.lis, row_geometry(self.config.layout), self._lambda_scale))
        return kept[1]

    def _find(self, crop: np.ndarray, roi: Roi, prev: LaneSegment | None,
              lambda_scale: float) -> LaneSegment:
        """TFALDA on one ROI: the lane chosen among its candidates (λ's pixel weights
        divided by the row's ``lambda_scale``)."""
        tcfg = self.config.tfalda
        height = roi.height - 1
        horizontal = (tcfg.sobel_manager and prev is not None
                      and sobel_horizontal_edges(prev.d, prev.y_bottom - prev.y_top,
                                                 tcfg.sobel_switch_angle_deg))
        small_h, small_w = resample_shape(*crop.shape, tcfg)
        # Back to image coordinates (listing A.6 normalize_vector: × resample factor + ROI
        # offset), pixel centre to pixel centre and with the crop's exact factor [px]; the
        # first frame takes the largest I, later ones the smallest λ (first of equals).
        kp, kd = tcfg.kp, tcfg.kd
        if lambda_scale != 1.0:
            kp, kd = kp / lambda_scale, kd / lambda_scale
        p, d, i, lam = find_lane_in_crop(
            crop, small_h, small_w, segment_steps(small_h, small_w), horizontal,
            tcfg.edge_mode is EdgeMode.RISING, float(roi.x), roi.width / small_w,
            prev is None,
            *((prev.p, prev.d, prev.i) if prev is not None else (0.0, 0.0, 0.0)),
            kp, kd, tcfg.ki)
        return LaneSegment(p, d, i, float(roi.y), float(roi.y + height), lam)

    def _place(self, base: Rows, final: Rows, first: bool) -> StateKind:
        """Place the next frame's ROIs from ``base`` lanes; returns the driving state."""
        lis = self.config.lis
        layout = self.config.layout
        width = layout.image_width
        if first or not lis.roi_placement:
            return self._state.kind
        state = self._state
        if isinstance(state, LaneChangeState):
            lowest_left, lowest_right = final[-1]
            if state.crossed(lowest_left.x_bottom, lowest_right.x_bottom, width):
                self._hand_over(state.to_left)
                self._forced = None
                self._state = StraightState()
                return StateKind.STRAIGHT
        new, kinds = [], []
        for (left, right), (lroi, rroi) in zip(base, self._rois, strict=True):
            lnext, rnext = follow(left, lroi, layout), follow(right, rroi, layout)
            row_state = state
            if self._forced is None and not isinstance(state, LaneChangeState):
                row_state = (classify(lnext, rnext, layout) if lis.curve_states
                             else StraightState())
            lnext, rnext = row_state.correct(lnext, rnext, layout)
            new.append((lnext, rnext))
            kinds.append(row_state.kind)
        self._rois = new
        # The frame's state: the first row (from the top) that is not driving straight.
        return next((k for k in kinds if k is not StateKind.STRAIGHT), StateKind.STRAIGHT)

    def _hand_over(self, to_left: bool) -> None:
        """Lane change done: the line crossed becomes the far side's line of the new lane,
        and the near side searches afresh one lane width further over."""
        layout = self.config.layout
        assert self._previous is not None
        new_rois, new_prev, fresh = [], [], []
        for (left, right), (lroi, rroi) in zip(self._previous, self._rois, strict=True):
            lane_w = right.x_bottom - left.x_bottom
            if to_left:  # old left line → new right line; new left line further left
                moved = LaneSegment(left.p - lane_w, left.d, left.i, left.y_top, left.y_bottom)
                new_prev.append((moved, left))
                new_rois.append((follow(moved, lroi, layout), follow(left, rroi, layout)))
                fresh.append([True, False])
            else:
                moved = LaneSegment(right.p + lane_w, right.d, right.i, right.y_top, right.y_bottom)
                new_prev.append((right, moved))
                new_rois.append((follow(right, lroi, layout), follow(moved, rroi, layout)))
                fresh.append([False, True])
        self._previous = new_prev
        self._rois = new_rois
        self._fresh_side = fresh
        self.lis.start(new_prev)
