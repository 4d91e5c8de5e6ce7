"""Steering agents of tfalda-sim: the PID lane keeper (``pid``), the ground-truth oracle
(``oracle``), PPO training (``train``), closed-loop drives (``drive``), the held-out
evaluation (``evaluate``) and the stress test of the ROI reset logic (``stress``)."""

if __name__ != "tfalda_sim.agents":  # pragma: no cover - a set-up error, checked in tests
    # The repository root on sys.path makes this folder importable as a top-level
    # `agents` too; two names for one package would split its state and its numba cache.
    raise ImportError("tfalda-sim's agents package is tfalda_sim.agents; import it under that "
                      "name (the repository root is on sys.path ahead of the installed "
                      "package)")

