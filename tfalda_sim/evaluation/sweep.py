"""Runs over ranges of generated tracks (the seed is the scenario id) in a process pool,
and the ablation of the LIS stages."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from functools import partial
from typing import Any

import numpy as np
from tqdm import tqdm

from ..perception import DetectorConfig, LisConfig
from ..rendering import Renderer
from .metrics import EPSILON_PX
from .runner import LOW_CONFIDENCE, RunResult, run_scenario
from .scenarios import generated_scenario

LIS_STAGES: tuple[str, ...] = ("lowpass", "min_max", "width_change", "vertical", "reset")
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


_RENDERER: Renderer | None = None


def _one_seed(seed: int, configs: Mapping[str, DetectorConfig], epsilon_px: float,
              scenario_kwargs: Mapping[str, Any]) -> dict[str, RunResult]:
    global _RENDERER
    if _RENDERER is None:  # one per worker process: its pixel geometry is costly
        _RENDERER = Renderer()
    scenario = generated_scenario(seed, **scenario_kwargs)
    return run_scenario(scenario, configs, renderer=_RENDERER, epsilon_px=epsilon_px)


def run_seeds(seeds: Sequence[int], configs: Mapping[str, DetectorConfig], *,
              workers: int | None = None, epsilon_px: float = EPSILON_PX,
              progress: bool = False, **scenario_kwargs: Any) -> list[dict[str, RunResult]]:
    """Every configuration on each generated track of ``seeds`` (one lap, see
    ``generated_scenario`` for ``scenario_kwargs``), in ``workers`` processes (default:
    the CPUs this process may use). Results come back in seed order and do not depend on
    the number of workers."""
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise ValueError("no seeds given")
    if workers is None:
        workers = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 1
    if workers < 1:
        raise ValueError(f"workers must be ≥ 1, got {workers}")
    job = partial(_one_seed, configs=dict(configs), epsilon_px=epsilon_px,
                  scenario_kwargs=scenario_kwargs)
    bar = tqdm(total=len(seeds), desc="tracks", unit="track", disable=not progress)
    try:
        if workers == 1 or len(seeds) == 1:
            results = []
            for seed in seeds:
                results.append(job(seed))
                bar.update()
            return results
        with ProcessPoolExecutor(max_workers=min(workers, len(seeds))) as pool:
            results = []
            for res in pool.map(job, seeds):
                results.append(res)
                bar.update()
            return results
    finally:
        bar.close()


def pooled_summary(runs: Sequence[RunResult]) -> dict[str, Any]:
    """One configuration's figures over many tracks: frames pooled, resets summed."""
    conf = np.concatenate([r.confidence for r in runs])
    means = np.array([r.confidence.mean() for r in runs])
    summaries = [r.summary() for r in runs]
    acc = np.concatenate([r.accuracy[r.truth_present] for r in runs])
    given = sum(int(np.all(np.isfinite(r.lanes), axis=2).sum()) for r in runs)
    n_truth = sum(int(r.truth_present.sum()) for r in runs)
    return {
        "tracks": len(runs), "frames": int(len(conf)),
        "mean_confidence": float(conf.mean()),
        "worst_track_mean_confidence": float(means.min()),
        "min_confidence": float(conf.min()),
        "frames_below_0_75": int((conf < LOW_CONFIDENCE).sum()),
        "share_below_0_75": float((conf < LOW_CONFIDENCE).mean()),
        "resets": int(sum(s["resets"] for s in summaries)),
        "tracks_with_reset": int(sum(s["resets"] > 0 for s in summaries)),
        "tusimple_accuracy": float(acc.mean()) if len(acc) else None,
        "false_positive_rate": float(sum(int(r.false_positive.sum()) for r in runs)
                                     / max(1, given)),
        "false_negative_rate": float(sum(int(r.false_negative.sum()) for r in runs)
                                     / max(1, n_truth)),
    }
