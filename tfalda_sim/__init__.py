"""tfalda-sim: a Gymnasium lane-keeping simulator for 1:10 Carolo-Cup model cars.

``import tfalda_sim`` registers ``TfaldaTrack-v0`` with Gymnasium (also reachable as
``gymnasium.make("tfalda_sim:TfaldaTrack-v0")``). The env module is imported only when an
env is made, so importing the package stays light.
"""

from __future__ import annotations

__version__ = "0.1.0"

ENV_ID = "TfaldaTrack-v0"
"""The Gymnasium id of the lane-keeping env."""

MAX_EPISODE_STEPS = 3000
"""Default step limit of ``TfaldaTrack-v0`` (60 s of camera frames)."""


def register_envs() -> None:
    """Register the envs with Gymnasium; calling it again changes nothing."""
    import gymnasium

    if ENV_ID not in gymnasium.registry:
        # vector_entry_point: make_vec without a vectorization_mode steps the envs in this
        # process and a worker process per further core (tfalda_sim.envs.vector).
        gymnasium.register(id=ENV_ID, entry_point="tfalda_sim.envs.tfalda_track:TfaldaTrackEnv",
                           vector_entry_point="tfalda_sim.envs.vector:make_vector_env",
                           max_episode_steps=MAX_EPISODE_STEPS)


register_envs()
