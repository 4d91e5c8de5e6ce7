"""The thesis' test system: ground truth, black-box hit rate, scenario runs."""

from .metrics import EPSILON_PX, lane_hit_rates, segment_pixels, truth_distance

__all__ = ["EPSILON_PX", "lane_hit_rates", "segment_pixels", "truth_distance"]
