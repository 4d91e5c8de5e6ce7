"""The thesis' test system (chapter 4): scenarios, the scenario runner, the black-box hit
rate and TuSimple-style scores, exports (XML of listing 4.1, JSON Lines), charts."""

from .metrics import (
    EPSILON_PX,
    FrameScore,
    dda_pixels,
    lane_hit_rates,
    score_frame,
    truth_distance,
)
from .runner import LOW_CONFIDENCE, WITH_LIS, WITHOUT_LIS, RunResult, run_scenario
from .scenarios import Scenario, ScenarioKind, generated_scenario, thesis_scenario
from .sweep import ablation_configs, pooled_summary, run_seeds
from .trajectory import Trajectory

__all__ = ["EPSILON_PX", "LOW_CONFIDENCE", "WITHOUT_LIS", "WITH_LIS", "FrameScore",
           "RunResult", "Scenario", "ScenarioKind", "Trajectory", "ablation_configs",
           "dda_pixels", "generated_scenario", "lane_hit_rates", "pooled_summary",
           "run_scenario", "run_seeds", "score_frame", "thesis_scenario", "truth_distance"]
