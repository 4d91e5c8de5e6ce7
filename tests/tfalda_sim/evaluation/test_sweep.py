"""Seed ranges in a process pool and the LIS ablation configurations."""

from __future__ import annotations

import numpy as np
import pytest

from tfalda_sim.evaluation import WITH_LIS, WITHOUT_LIS, ablation_configs, pooled_summary, run_seeds
from tfalda_sim.evaluation.sweep import LIS_STAGES
from tfalda_sim.perception import DetectorConfig, LisConfig

CONFIGS = {WITH_LIS: DetectorConfig.thesis(), WITHOUT_LIS: DetectorConfig.without_lis()}


def test_ablation_switches_one_stage_at_a_time() -> None:
    configs = ablation_configs()
    assert configs["all stages"] == DetectorConfig.thesis()
    assert configs["no LIS"].lis == LisConfig.off()
    assert len(configs) == 2 + 2 * len(LIS_STAGES)
    for stage in LIS_STAGES:
        (without,) = [c for name, c in configs.items() if name.startswith(f"without {stage}")]
        (only,) = [c for name, c in configs.items() if name.startswith(f"only {stage}")]
        assert getattr(without.lis, stage) is False and getattr(only.lis, stage) is True
        others = [s for s in LIS_STAGES if s != stage]
        # the width-change check needs the low-pass filter: they go together
        assert sum(getattr(without.lis, s) for s in others) == len(others) - (
            stage == "lowpass")
        assert sum(getattr(only.lis, s) for s in others) == (stage == "width_change")
        assert only.layout == without.layout == DetectorConfig.thesis().layout


def test_results_do_not_depend_on_the_worker_count() -> None:
    one = run_seeds([3, 8], CONFIGS, workers=1, max_frames=15)
    two = run_seeds([3, 8], CONFIGS, workers=2, max_frames=15)
    assert [r[WITH_LIS].seed for r in two] == [3, 8]
    for a, b in zip(one, two, strict=True):
        for label in CONFIGS:
            assert np.array_equal(a[label].lanes, b[label].lanes)
            assert np.array_equal(a[label].hit_rates, b[label].hit_rates)


def test_pooled_summary_pools_frames_and_sums_resets() -> None:
    runs = [r[WITHOUT_LIS] for r in run_seeds([1, 2], CONFIGS, workers=1, max_frames=10)]
    pooled = pooled_summary(runs)
    conf = np.concatenate([r.confidence for r in runs])
    assert pooled["tracks"] == 2 and pooled["frames"] == 20
    assert pooled["mean_confidence"] == pytest.approx(conf.mean())
    assert pooled["frames_below_0_75"] == int((conf < 0.75).sum())
    assert pooled["roi_resets"] == sum(int(r.roi_reset.sum()) for r in runs)


def test_bad_sweep_arguments_are_named() -> None:
    with pytest.raises(ValueError, match="no seeds"):
        run_seeds([], CONFIGS)
    with pytest.raises(ValueError, match="workers"):
        run_seeds([1], CONFIGS, workers=0)
