"""Gymnasium environments of tfalda-sim (registered by ``import tfalda_sim``)."""

if __name__ != "tfalda_sim.envs":  # pragma: no cover - a set-up error, checked in tests
    # The repository root on sys.path makes this folder importable as a top-level
    # `envs` too; two names for one package would split its state and its numba cache.
    raise ImportError("tfalda-sim's envs package is tfalda_sim.envs; import it under that "
                      "name (the repository root is on sys.path ahead of the installed "
                      "package)")


from .observation import lane_vector, lane_vector_bounds, lane_vector_names
from .tfalda_track import (
    ObservationMode,
    RewardWeights,
    StartInCarton,
    TfaldaTrackEnv,
    resolve_track,
)

__all__ = ["ObservationMode", "RewardWeights", "StartInCarton", "TfaldaTrackEnv",
           "lane_vector", "lane_vector_bounds", "lane_vector_names", "resolve_track"]
