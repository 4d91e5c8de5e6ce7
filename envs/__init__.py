"""Gymnasium environments of tfalda-sim (registered by ``import tfalda_sim``)."""

from .observation import lane_vector, lane_vector_bounds, lane_vector_names
from .tfalda_track import ObservationMode, RewardWeights, TfaldaTrackEnv, resolve_track

__all__ = ["ObservationMode", "RewardWeights", "TfaldaTrackEnv", "lane_vector",
           "lane_vector_bounds", "lane_vector_names", "resolve_track"]
