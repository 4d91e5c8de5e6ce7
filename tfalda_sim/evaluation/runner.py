"""The scenario runner: render each frame of a scenario, run detectors on it, score them
against that frame's ground truth (the thesis' test frame, section 4.1.6)."""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from tqdm import tqdm

from ..interrupts import INTERRUPTS, ignoring_stops, is_interrupt
from ..perception import DetectorConfig, LaneObservation, TfaldaDetector
from ..rendering import FrameTruth, Renderer, build_scene, frame_truth
from .metrics import EPSILON_PX, LANE_FAILURE_HIT_RATE, score_frame, truth_distance
from .scenarios import Scenario

LOW_CONFIDENCE: float = 0.75
"""A frame below this confidence has at least one of four lanes off its marking: the
thesis' 75 % line (sections 4.2.2–4.2.3)."""

WITH_LIS = "with LIS"
WITHOUT_LIS = "without LIS"


@dataclass(eq=False)
class RunResult:
    """One detector's run over one scenario, frame by frame (index = frame of the run)."""

    label: str
    scenario: str
    seed: int | None
    config: DetectorConfig
    epsilon_px: float
    seq: np.ndarray  # (n,) int: the thesis' sequence numbers
    time_s: np.ndarray  # (n,) [s]
    lanes: np.ndarray  # (n, k, 4) [px]: x_top, y_top, x_bottom, y_bottom
    d: np.ndarray  # (n, k) [px]
    lam: np.ndarray  # (n, k)
    rois: np.ndarray  # (n, k, 4) [px]: x, y, w, h
    hit_rates: np.ndarray  # (n, k) [0, 1]
    accuracy: np.ndarray  # (n, k) TuSimple point accuracy, NaN without truth
    false_positive: np.ndarray  # (n, k) bool
    false_negative: np.ndarray  # (n, k) bool
    truth_present: np.ndarray  # (n, k) bool
    replaced: np.ndarray  # (n, k) bool
    corrected: np.ndarray  # (n, k) bool
    roi_reset: np.ndarray  # (n,) bool
    fault_count: np.ndarray  # (n,) int
    state: list[str]  # (n,) driving state names
    detector_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """(n,) wall-clock time of the detector per frame [s] (not part of equality checks)."""

    @property
    def confidence(self) -> np.ndarray:
        """(n,) the thesis' per-frame figure: mean hit rate of the lanes."""
        return self.hit_rates.mean(axis=1)

    def summary(self) -> dict[str, Any]:
        """The scenario figures: confidence mean/min, frames below 0.75, resets,
        TuSimple accuracy/FP/FN, per-ROI failures, detector time."""
        conf = self.confidence
        given = np.all(np.isfinite(self.lanes), axis=2)
        n_truth = int(self.truth_present.sum())
        acc = self.accuracy[self.truth_present]
        return {
            "scenario": self.scenario, "seed": self.seed, "run": self.label,
            "frames": int(len(conf)), "epsilon_px": self.epsilon_px,
            "mean_confidence": float(conf.mean()), "min_confidence": float(conf.min()),
            "frames_below_0_75": int((conf < LOW_CONFIDENCE).sum()),
            "roi_resets": int(self.roi_reset.sum()),
            "tusimple_accuracy": float(acc.mean()) if n_truth else None,
            "false_positive_rate": float(self.false_positive.sum() / max(1, given.sum())),
            "false_negative_rate": float(self.false_negative.sum() / max(1, n_truth)),
            "per_roi_failures": [int(v) for v in
                                 (self.hit_rates < LANE_FAILURE_HIT_RATE).sum(axis=0)],
            "per_roi_mean_hit_rate": [float(v) for v in self.hit_rates.mean(axis=0)],
            "per_roi_false_positives": [int(v) for v in self.false_positive.sum(axis=0)],
            "per_roi_false_negatives": [int(v) for v in self.false_negative.sum(axis=0)],
            "detector_ms_median": (float(np.median(self.detector_s)) * 1e3
                                   if len(self.detector_s) else None),
        }


class ScenarioInterrupted(KeyboardInterrupt):
    """A Ctrl-C during ``run_scenario``: carries the runs over the frames finished so far
    (``results``; None if not even one frame was), so that a command can keep them."""

    def __init__(self, results: dict[str, RunResult] | None) -> None:
        super().__init__("interrupted")
        self.results = results


FrameHook = Callable[[int, np.ndarray, FrameTruth, Mapping[str, LaneObservation]], None]
"""Called per frame with (seq, frame, truth, observation per run label): e.g. a video."""


def run_scenario(scenario: Scenario, configs: Mapping[str, DetectorConfig], *,
                 renderer: Renderer | None = None, epsilon_px: float = EPSILON_PX,
                 progress: bool = False, on_frame: FrameHook | None = None
                 ) -> dict[str, RunResult]:
    """Run every detector configuration over the same rendered frames of ``scenario``.

    Each frame is rendered and its truth computed once, then given to each detector, so
    runs differ only by their configuration (as the thesis ran its two software states
    over the same recorded sequence)."""
    if not configs:
        raise ValueError("configs is empty: give at least one {label: DetectorConfig}")
    if not (np.isfinite(epsilon_px) and epsilon_px >= 0):
        raise ValueError(f"epsilon_px must be finite and ≥ 0, got {epsilon_px}")
    renderer = renderer or Renderer()
    scene = build_scene(scenario.track, scenario.effects,
                        np.random.default_rng(scenario.scene_seed))
    traj = scenario.trajectory
    detectors = {label: TfaldaDetector(cfg) for label, cfg in configs.items()}
    records: dict[str, list[tuple[LaneObservation, Any, float]]] = {k: [] for k in detectors}
    frames = tqdm(range(len(traj)), desc=scenario.name, unit="frame", disable=not progress,
                  leave=False)
    try:
        for k in frames:
            _run_frame(k, scenario, renderer, scene, detectors, records, epsilon_px, on_frame)
    except INTERRUPTS as exc:
        if not is_interrupt(exc):
            raise
        with ignoring_stops():  # a second Ctrl-C must not lose the frames run so far
            done = min(len(r) for r in records.values())
            partial = None
            if done:
                partial = {label: _collect(label, scenario, configs[label], epsilon_px,
                                           recs[:done], frames=done)
                           for label, recs in records.items()}
        raise ScenarioInterrupted(partial) from None
    finally:
        frames.close()
    return {label: _collect(label, scenario, configs[label], epsilon_px, recs)
            for label, recs in records.items()}


def _run_frame(k: int, scenario: Scenario, renderer: Renderer, scene: Any,
               detectors: Mapping[str, TfaldaDetector],
               records: dict[str, list[tuple[LaneObservation, Any, float]]],
               epsilon_px: float, on_frame: FrameHook | None) -> None:
    """Frame ``k``: render, truth, every detector, the hook."""
    seq = scenario.first_seq + k
    traj = scenario.trajectory
    pose = traj.pose(k)
    s_hint = float(traj.s_m[k]) if np.isfinite(traj.s_m[k]) else None
    frame = renderer.render(scene, pose, speed_m_s=float(traj.speeds_m_s[k]),
                            frame_seed=seq + 1_000_003 * scenario.scene_seed)
    truth = frame_truth(scenario.track, renderer.camera, pose, bonnet=renderer.bonnet,
                        s_hint_m=s_hint)
    distance = truth_distance(truth.labels)
    observations = {}
    for label, det in detectors.items():
        t0 = time.perf_counter()
        obs = det.process(frame)
        dt = time.perf_counter() - t0
        score = score_frame(obs.lanes, obs.rois, truth, distance, epsilon_px=epsilon_px)
        records[label].append((obs, score, dt))
        observations[label] = obs
    if on_frame is not None:
        on_frame(seq, frame, truth, observations)


def _collect(label: str, scenario: Scenario, config: DetectorConfig, epsilon_px: float,
             recs: list[tuple[LaneObservation, Any, float]], frames: int | None = None
             ) -> RunResult:
    """The run of ``recs``; ``frames``: only the first frames of the scenario were run."""
    obs = [r[0] for r in recs]
    sc = [r[1] for r in recs]
    n = len(scenario.trajectory) if frames is None else frames
    return RunResult(
        label=label, scenario=scenario.name, seed=scenario.seed, config=config,
        epsilon_px=epsilon_px,
        seq=np.arange(scenario.first_seq, scenario.first_seq + n),
        time_s=scenario.trajectory.times_s[:n].copy(),
        lanes=np.stack([o.lanes for o in obs]), d=np.stack([o.d for o in obs]),
        lam=np.stack([o.lam for o in obs]), rois=np.stack([o.rois for o in obs]),
        hit_rates=np.stack([s.hit_rates for s in sc]),
        accuracy=np.stack([s.accuracy for s in sc]),
        false_positive=np.stack([s.false_positive for s in sc]),
        false_negative=np.stack([s.false_negative for s in sc]),
        truth_present=np.stack([s.truth_present for s in sc]),
        replaced=np.stack([o.replaced for o in obs]),
        corrected=np.stack([o.corrected for o in obs]),
        roi_reset=np.array([o.roi_reset for o in obs]),
        fault_count=np.array([o.fault_count for o in obs]),
        state=[o.state.name.lower() for o in obs],
        detector_s=np.array([r[2] for r in recs]))
