"""Runs over ranges of generated tracks (the seed is the scenario id) in a process pool,
and the ablation of the LIS stages."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import replace
from functools import partial
from typing import Any

import numpy as np
from tqdm import tqdm

from ..camera import load_camera
from ..parallel import resolve_workers, stream
from ..perception import DetectorConfig, LisConfig
from ..rendering import Renderer
from .metrics import EPSILON_PX
from .runner import LOW_CONFIDENCE, RunResult, run_scenario
from .scenarios import generated_scenario

LIS_STAGES: tuple[str, ...] = ("lowpass", "min_max", "width_change", "vertical", "roi_reset")
"""The LIS stages of the ablation (``LisConfig`` switches, thesis sections 2.1.2–2.4)."""

_STAGE_NEEDS = {"width_change": ("lowpass",)}
_STAGE_DROPS = {"lowpass": ("width_change",)}
# the width-change check compares low-pass filtered widths: it cannot run without them


def ablation_configs(base: DetectorConfig | None = None) -> dict[str, DetectorConfig]:
    """The base configuration (default: the thesis' "with LIS"), no LIS, and each LIS
    stage switched off alone ("without X") and on alone ("only X")."""
    base = base or DetectorConfig.thesis()
    out = {"all stages": base, "no LIS": replace(base, lis=LisConfig.off())}
    for stage in LIS_STAGES:
        off = {stage: False, **{s: False for s in _STAGE_DROPS.get(stage, ())}}
        name = stage + "".join(f" (+{s})" for s in _STAGE_DROPS.get(stage, ()))
        out[f"without {name}"] = replace(base, lis=replace(base.lis, **off))
    for stage in LIS_STAGES:
        on = {stage: True, **{s: True for s in _STAGE_NEEDS.get(stage, ())}}
        name = stage + "".join(f" (+{s})" for s in _STAGE_NEEDS.get(stage, ()))
        out[f"only {name}"] = replace(base, lis=replace(LisConfig.off(), **on))
    return out


_RENDERERS: dict[str, Renderer] = {}


def _one_seed(seed: int, configs: Mapping[str, DetectorConfig], epsilon_px: float,
              scenario_kwargs: Mapping[str, Any], camera: str = "thesis"
              ) -> dict[str, RunResult]:
    renderer = _RENDERERS.get(camera)
    if renderer is None:  # one per camera and worker process: its pixel geometry is costly
        renderer = _RENDERERS[camera] = Renderer(load_camera(camera))
    configs = {k: c.on_camera(renderer.camera) for k, c in configs.items()}
    scenario = generated_scenario(seed, **scenario_kwargs)
    return run_scenario(scenario, configs, renderer=renderer, epsilon_px=epsilon_px)


def iter_seeds(seeds: Iterable[int], configs: Mapping[str, DetectorConfig], *,
               workers: int = 1, epsilon_px: float = EPSILON_PX, camera: str = "thesis",
               **scenario_kwargs: Any) -> Iterator[dict[str, RunResult]]:
    """Every configuration on each generated track of ``seeds`` (one lap, see
    ``generated_scenario`` for ``scenario_kwargs``) seen by ``camera`` (a profile name or
    file; the configurations' pixel layout derived for it), streamed from ``workers`` processes
    (``tfalda_sim.parallel.stream``: bounded memory for any range). Results come in seed
    order and do not depend on the number of workers."""
    if workers < 1:
        raise ValueError(f"workers must be ≥ 1, got {workers}")
    job = seed_job(configs, epsilon_px=epsilon_px, camera=camera, **scenario_kwargs)
    yield from stream(job, (int(s) for s in seeds), workers=workers)


def run_seeds(seeds: Sequence[int], configs: Mapping[str, DetectorConfig], *,
              workers: int | None = None, epsilon_px: float = EPSILON_PX,
              progress: bool = False, **scenario_kwargs: Any) -> list[dict[str, RunResult]]:
    """``iter_seeds`` collected into a list (for short ranges), with a progress bar;
    ``workers`` defaults to the CPUs available (capped at the seeds)."""
    if not len(seeds):
        raise ValueError("no seeds given")
    if workers is not None and workers < 1:
        raise ValueError(f"workers must be ≥ 1, got {workers}")
    workers, _ = resolve_workers(workers, len(seeds))
    results = iter_seeds(seeds, configs, workers=workers, epsilon_px=epsilon_px,
                         **scenario_kwargs)
    return list(tqdm(results, total=len(seeds), desc="tracks", unit="track",
                     disable=not progress))


class PooledTally:
    """One configuration's figures over many tracks, updated track by track (memory
    independent of the number of tracks): frames pooled, resets summed."""

    def __init__(self) -> None:
        self.tracks = self.frames = self.below = self.roi_resets = self.tracks_with_reset = 0
        self.conf_sum = 0.0
        self.min_conf = self.worst_track_mean = math.inf
        self.acc_sum, self.acc_n = 0.0, 0
        self.given = self.n_truth = self.fp = self.fn = 0

    def add(self, run: RunResult) -> None:
        self.add_counts(run_counts(run))

    def add_counts(self, c: Mapping[str, Any]) -> None:
        """Add one track's ``run_counts`` (read back from a results file: the same sums)."""
        self.tracks += 1
        self.frames += int(c["frames"])
        self.conf_sum += float(c["conf_sum"])
        self.min_conf = min(self.min_conf, float(c["min_conf"]))
        self.worst_track_mean = min(self.worst_track_mean, float(c["mean_conf"]))
        self.below += int(c["below"])
        resets = int(c["roi_resets"])
        self.roi_resets += resets
        self.tracks_with_reset += resets > 0
        self.acc_sum += float(c["acc_sum"])
        self.acc_n += int(c["acc_n"])
        self.given += int(c["given"])
        self.n_truth += int(c["n_truth"])
        self.fp += int(c["fp"])
        self.fn += int(c["fn"])

    def summary(self) -> dict[str, Any]:
        if not self.frames:
            raise ValueError("no track added yet")
        return {
            "tracks": self.tracks, "frames": self.frames,
            "mean_confidence": self.conf_sum / self.frames,
            "worst_track_mean_confidence": self.worst_track_mean,
            "min_confidence": self.min_conf,
            "frames_below_0_75": self.below,
            "share_below_0_75": self.below / self.frames,
            "roi_resets": self.roi_resets,
            "tracks_with_roi_reset": self.tracks_with_reset,
            "tusimple_accuracy": self.acc_sum / self.acc_n if self.acc_n else None,
            "false_positive_rate": self.fp / max(1, self.given),
            "false_negative_rate": self.fn / max(1, self.n_truth),
        }


def run_counts(run: RunResult) -> dict[str, Any]:
    """What ``PooledTally`` needs of one track's run, as JSON values."""
    conf = run.confidence
    acc = run.accuracy[run.truth_present]
    return {"frames": len(conf), "conf_sum": float(conf.sum()), "min_conf": float(conf.min()),
            "mean_conf": float(conf.mean()), "below": int((conf < LOW_CONFIDENCE).sum()),
            "roi_resets": int(run.roi_reset.sum()), "acc_sum": float(acc.sum()),
            "acc_n": len(acc), "given": int(np.all(np.isfinite(run.lanes), axis=2).sum()),
            "n_truth": int(run.truth_present.sum()), "fp": int(run.false_positive.sum()),
            "fn": int(run.false_negative.sum())}


def seed_job(configs: Mapping[str, DetectorConfig], *, epsilon_px: float = EPSILON_PX,
             camera: str = "thesis", **scenario_kwargs: Any
             ) -> Callable[[int], dict[str, RunResult]]:
    """The per-seed job of ``iter_seeds``: picklable (a partial of a top-level function),
    so every backend runs the same one."""
    return partial(_one_seed, configs=dict(configs), epsilon_px=epsilon_px,
                   scenario_kwargs=scenario_kwargs, camera=camera)


def seed_record(seed: int, runs: Mapping[str, RunResult]) -> dict[str, Any]:
    """A track's JSON record (a line of ``--results``): per run its summary and counts."""
    return {"seed": seed, "runs": {label: {"summary": run.summary(), "counts": run_counts(run)}
                                   for label, run in runs.items()}}


def check_seed_record(seed: int, rec: dict[str, Any]) -> None:
    """A stored record is ``seed``'s track, else ValueError."""
    if rec.get("seed") != seed:
        raise ValueError(f"it holds seed {rec.get('seed')!r}, the sweep's next one is {seed}")
    runs = rec.get("runs")
    if not isinstance(runs, dict) or not runs:
        raise ValueError("it lacks the track's runs")
    for run in runs.values():
        if not isinstance(run, dict) or not {"summary", "counts"} <= set(run):
            raise ValueError("a run lacks its summary or counts")
        PooledTally().add_counts(run["counts"])  # raises on missing or bad counts


def pooled_summary(runs: Iterable[RunResult]) -> dict[str, Any]:
    """One configuration's figures over many tracks (``PooledTally``)."""
    tally = PooledTally()
    for run in runs:
        tally.add(run)
    return tally.summary()
