"""Evaluate an agent on held-out generated tracks: laps completed without leaving the road.

    tfalda-sim evaluate-agent --agent pid --seeds 10000:10100 --laps 3 [--speeds 1.5,2,2.5] --json

Each track (its cartons removed: lane keeping does not avoid obstacles) is driven from
its start line; a run succeeds when the car completes the laps
without a departure (the drive ends at the first one). Seeds run in a process pool
(results do not depend on the worker count) with a progress bar. ``--speeds`` runs the
same tracks at several speeds (the speed sweep of docs/agents.md).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np

from tfalda_sim.camera import load_camera
from tfalda_sim.parallel import stream
from tfalda_sim.timing import Timing, resolve_timing
from tfalda_sim.tracks import generate, seed_name

from .drive import check_agent, drive, make_agent

Job = tuple[str, str | None, int, int, float, str, bool, str, Timing]


def run_job(job: Job) -> dict[str, Any]:
    """One run (agent, policy, seed, laps, speed, camera, trust the policy's pickles,
    vehicle, timing): the picklable top-level function every backend runs; its result is
    its JSON record. The timing travels read (a worker on another host need not have its
    file)."""
    kind, policy, seed, laps, speed, camera_spec, trust, vehicle, timing = job
    track = generate(seed).with_elements(obstacles=())  # lane keeping: no cartons to avoid
    camera = load_camera(camera_spec)
    agent = make_agent(kind, policy, camera, trust_policy=trust)
    result = drive(agent, track, laps=laps, speed_m_s=speed, recover=False,
                   label=seed_name(seed), camera=camera, vehicle=vehicle, timing=timing)
    if result.ended == "interrupted":  # drive() stops at Ctrl-C; the sweep must stop too
        raise KeyboardInterrupt
    return {"seed": seed, "speed_m_s": speed, "success": result.laps_completed == laps,
            **{k: v for k, v in result.summary().items() if k != "track"}}


def evaluation_jobs(kind: str, policy: str | None, seeds: range, laps: int,
                    speeds: tuple[float, ...], camera: str, trust_policy: bool = False,
                    vehicle: str = "kinematic", timing: str | Timing = "ideal"
                    ) -> Iterator[Job]:
    """The runs, generated as they are needed: every seed at the first speed, then at the
    next."""
    resolved = resolve_timing(timing)
    for speed in speeds:
        for seed in seeds:
            yield kind, policy, seed, laps, speed, camera, trust_policy, vehicle, resolved


def iter_evaluate(kind: str, seeds: range, *, laps: int = 3,
                  speeds: tuple[float, ...] = (1.5,), policy: str | None = None,
                  workers: int = 1, camera: str = "thesis", trust_policy: bool = False,
                  vehicle: str = "kinematic", timing: str | Timing = "ideal"
                  ) -> Iterator[dict[str, Any]]:
    """One run per (speed, seed), streamed from ``workers`` processes in that order;
    ``camera`` a profile name or file (the workers load it); ``trust_policy`` as
    ``make_agent``'s; ``vehicle`` and ``timing`` the env's."""
    repeated = [v for k, v in enumerate(speeds) if v in speeds[:k]]
    if repeated:  # its runs would be made twice and pooled with themselves
        raise ValueError(f"{repeated[0]:g} m/s is named twice in speeds {speeds}")
    # Fail early on a bad agent or camera.
    check_agent(kind, policy, load_camera(camera), trust_policy=trust_policy)
    yield from stream(run_job, evaluation_jobs(kind, policy, seeds, laps, speeds, camera,
                                               trust_policy, vehicle, timing),
                      workers=workers)


def run_record(job: Job, run: dict[str, Any]) -> dict[str, Any]:
    """A run's JSON record (a line of ``--results``): the run itself."""
    return run


def check_run_record(job: Job, rec: dict[str, Any]) -> None:
    """A stored record is ``job``'s run, else ValueError."""
    seed, speed = job[2], job[4]
    if (rec.get("seed"), rec.get("speed_m_s")) != (seed, speed):
        raise ValueError(f"it holds the run (seed, speed) {(rec.get('seed'), rec.get('speed_m_s'))}"
                         f", the sweep's next run is {(seed, speed)}")
    missing = {"success", "mean_abs_cross_track_m", "roi_resets"} - set(rec)
    if missing:
        raise ValueError(f"it lacks {', '.join(sorted(missing))}")


def result_document(kind: str, policy: str | None, camera: str, laps: int, seeds: range,
                    speeds: tuple[float, ...], runs: list[dict[str, Any]],
                    interrupted: bool, worker_died: str | None, vehicle: str = "kinematic",
                    timing: str = "ideal") -> dict[str, Any]:
    """The evaluation's result: per speed the success rate and figures, and every run
    (``timing`` as given: a name or a file)."""
    return {"agent": kind, "policy": policy, "camera": camera, "vehicle": vehicle,
            "timing": timing, "laps": laps,
            "seeds": [seeds.start, seeds.stop],
            "speeds": summarise(runs, speeds), "runs": runs, "interrupted": interrupted,
            "worker_died": worker_died}


def summarise(runs: list[dict[str, Any]], speeds: tuple[float, ...]) -> list[dict[str, Any]]:
    """Per speed: the success rate and figures of the runs finished."""
    per_speed = []
    for speed in speeds:
        group = [r for r in runs if r["speed_m_s"] == speed]
        if not group:
            continue
        per_speed.append({
            "speed_m_s": speed, "tracks": len(group),
            "success_rate": float(np.mean([r["success"] for r in group])),
            "successes": int(sum(r["success"] for r in group)),
            "failed_seeds": [r["seed"] for r in group if not r["success"]],
            "mean_abs_cross_track_m": float(np.mean([r["mean_abs_cross_track_m"]
                                                     for r in group])),
            "roi_resets_per_track": float(np.mean([r["roi_resets"] for r in group])),
        })
    return per_speed
