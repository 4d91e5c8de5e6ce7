"""Speed limits: per generated track, the highest constant cruise speed at which an agent
still drives the laps without leaving the road.

    tfalda-sim limits --agent pid --seeds 10000:10050 --laps 2 --vehicle dynamic --json

Each track (its cartons removed, as in ``evaluate-agent``) is driven from its start line at
one constant speed; a drive passes when it completes the laps without a departure (the
drive ends at the first one). The limit is found by bisection on the speeds
``LOWEST_SPEED_M_S``, + ``STEP_M_S``, …, up to the car's top speed: the lowest speed is
tried first (a track failed there has no limit: ``below_min_speed``, ``limit_m_s`` None),
then the top speed (passed: the limit is the top speed, ``at_top_speed``), then the
bisection keeps a passed speed below a failed one until they are one step apart. It
assumes a car that passes at a speed passes at every lower one; each drive is
deterministic, so a track's limit is the same on every run. A track's whole bisection is
one job of the sweep (``tfalda_sim.sweep_runner``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tfalda_sim.camera import load_camera
from tfalda_sim.timing import Timing, resolve_timing
from tfalda_sim.tracks import generate, seed_name
from tfalda_sim.vehicle import MAX_SPEED_M_S

from .drive import drive, make_agent

LOWEST_SPEED_M_S: float = 0.5
"""The lowest speed tried by default [m/s] (``--lowest-speed``): a limit below it is
reported as such, not sought (the car crawls there; below it no lane keeper is of
interest)."""

STEP_M_S: float = 0.1
"""The bisection's resolution [m/s]: a limit is a multiple of it above the lowest speed."""

TOP_SPEED_M_S: float = MAX_SPEED_M_S
"""The highest speed tried: the car's top speed [m/s]."""

QUANTILES: dict[str, float] = {"min_m_s": 0.0, "q1_m_s": 0.25, "median_m_s": 0.5,
                               "q3_m_s": 0.75, "max_m_s": 1.0}
"""The summary's order statistics of the limits (numpy's default, linear, quantiles)."""


def speed_grid(low: float = LOWEST_SPEED_M_S, high: float = TOP_SPEED_M_S,
               step: float = STEP_M_S) -> list[float]:
    """The speeds a bisection may try: ``low``, ``low + step``, … and ``high`` [m/s],
    rounded to the step's decimals (so 0.1-steps read 2.3, not 2.3000000000000003)."""
    if not (math.isfinite(low) and math.isfinite(high) and math.isfinite(step)
            and 0 < low < high and step > 0):
        raise ValueError(f"a speed grid needs 0 < low < high and step > 0, got {low}, "
                         f"{high}, {step}")
    decimals = max(0, -math.floor(math.log10(step)) + 1)
    n = math.floor((high - low) / step + 1e-9)
    grid = [round(low + k * step, decimals) for k in range(n + 1)]
    if high - grid[-1] > 1e-9:
        grid.append(high)
    return grid


def bisect_limit(passes: Callable[[float], Mapping[str, Any]],
                 grid: Sequence[float] | None = None) -> dict[str, Any]:
    """The highest speed of ``grid`` (default ``speed_grid()``) at which ``passes(speed)``
    succeeds (its ``"success"``), by bisection: the lowest speed first, then the highest,
    then between a passed and a failed one until they are neighbours. Returns
    ``limit_m_s`` (None when the lowest speed fails), ``below_min_speed``,
    ``at_top_speed`` and ``drives``, every call's result in the order made."""
    grid = list(speed_grid() if grid is None else grid)
    drives: list[dict[str, Any]] = []

    def ok(k: int) -> bool:
        result = dict(passes(grid[k]))
        drives.append({"speed_m_s": grid[k], **result})
        return bool(result["success"])

    def outcome(limit: float | None) -> dict[str, Any]:
        return {"limit_m_s": limit, "below_min_speed": limit is None,
                "at_top_speed": limit == grid[-1], "drives": drives}

    if not ok(0):
        return outcome(None)
    if len(grid) == 1 or ok(len(grid) - 1):
        return outcome(grid[-1])
    lo, hi = 0, len(grid) - 1  # grid[lo] passed, grid[hi] failed
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if ok(mid):
            lo = mid
        else:
            hi = mid
    return outcome(grid[lo])


Job = tuple[str, str | None, int, int, str, bool, str, Timing, float]
"""(agent, policy, seed, laps, camera, trust the policy's pickles, vehicle, timing, lowest
speed): one track's bisection."""


def run_job(job: Job) -> dict[str, Any]:
    """One track's limit: the picklable top-level function every backend runs; its
    result is its JSON record. The timing travels read (a worker on another host need
    not have its file)."""
    kind, policy, seed, laps, camera_spec, trust, vehicle, timing, lowest = job
    track = generate(seed).with_elements(obstacles=())  # lane keeping: no cartons to avoid
    camera = load_camera(camera_spec)
    agent = make_agent(kind, policy, camera, trust_policy=trust)

    def passes(speed: float) -> dict[str, Any]:
        # A new env per drive: a drive depends on its track, speed and seeds only, never on
        # the drives before it (same seed, same limit).
        result = drive(agent, track, laps=laps, speed_m_s=speed, recover=False,
                       label=seed_name(seed), camera=camera, vehicle=vehicle, timing=timing)
        if result.ended == "interrupted":  # drive() stops at Ctrl-C; the sweep must too
            raise KeyboardInterrupt
        return {"success": result.laps_completed == laps, "ended": result.ended,
                "laps_completed": result.laps_completed,
                "distance_m": round(result.distance_m, 3)}

    return {"seed": seed, **bisect_limit(passes, speed_grid(lowest))}


def limit_jobs(kind: str, policy: str | None, seeds: range, laps: int, camera: str,
               trust_policy: bool = False, vehicle: str = "kinematic",
               timing: str | Timing = "ideal", lowest_speed_m_s: float = LOWEST_SPEED_M_S
               ) -> Iterator[Job]:
    """One job per seed, generated as needed."""
    resolved = resolve_timing(timing)
    for seed in seeds:
        yield (kind, policy, seed, laps, camera, trust_policy, vehicle, resolved,
               lowest_speed_m_s)


def run_record(job: Job, result: dict[str, Any]) -> dict[str, Any]:
    """A track's JSON record (a line of ``--results``): the result itself."""
    return result


RECORD_KEYS: frozenset[str] = frozenset({"seed", "limit_m_s", "below_min_speed",
                                         "at_top_speed", "drives"})


def check_run_record(job: Job, rec: dict[str, Any]) -> None:
    """A stored record is ``job``'s track's limit, else ValueError."""
    if rec.get("seed") != job[2]:
        raise ValueError(f"it holds seed {rec.get('seed')}, the sweep's next track is seed "
                         f"{job[2]}")
    if set(rec) != RECORD_KEYS:
        raise ValueError(f"its fields are {sorted(rec)}, a track's limit has "
                         f"{sorted(RECORD_KEYS)}")
    limit = rec["limit_m_s"]
    if limit is not None and not (isinstance(limit, int | float) and math.isfinite(limit)):
        raise ValueError(f"its limit_m_s is {limit!r}, not a speed")


def summarise(per_seed: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """The distribution of the limits: ``count`` tracks, how many fell below the lowest
    speed and how many reached the top speed, and the order statistics ``QUANTILES``. A
    track below the lowest speed counts as slower than every other; an order statistic
    that depends on such a track is None (below ``LOWEST_SPEED_M_S``)."""
    limits = sorted(-math.inf if r["limit_m_s"] is None else float(r["limit_m_s"])
                    for r in per_seed)
    out: dict[str, Any] = {
        "count": len(limits),
        "below_min_speed": sum(1 for r in per_seed if r["limit_m_s"] is None),
        "at_top_speed": sum(1 for r in per_seed if r["at_top_speed"]),
    }
    for key, q in QUANTILES.items():
        out[key] = _quantile(limits, q)
    return out


def _quantile(values: Sequence[float], q: float) -> float | None:
    """numpy's linear quantile of sorted ``values``; None when it needs a -inf (a track
    below the lowest speed) or there are none."""
    if not values:
        return None
    pos = q * (len(values) - 1)
    lo, hi = math.floor(pos), math.ceil(pos)
    a, b = values[lo], values[hi]
    if not (math.isfinite(a) and math.isfinite(b)):
        return None
    return round(a + (pos - lo) * (b - a), 6)


def result_document(kind: str, policy: str | None, camera: str, vehicle: str, timing: str,
                    laps: int, seeds: range, per_seed: list[dict[str, Any]],
                    interrupted: bool, worker_died: str | None,
                    lowest_speed_m_s: float = LOWEST_SPEED_M_S) -> dict[str, Any]:
    """The limits' result: the search's set-up, the summary and every track's limit."""
    return {"agent": kind, "policy": policy, "camera": camera, "vehicle": vehicle,
            "timing": timing, "laps": laps, "seeds": [seeds.start, seeds.stop],
            "lowest_speed_m_s": lowest_speed_m_s, "top_speed_m_s": TOP_SPEED_M_S,
            "step_m_s": STEP_M_S, "summary": summarise(per_seed), "per_seed": per_seed,
            "interrupted": interrupted, "worker_died": worker_died}


def show_limit(limit: float | None, lowest: float = LOWEST_SPEED_M_S) -> str:
    """A limit in the table: "<0.5" below the lowest speed."""
    return f"<{lowest:g}" if limit is None else f"{limit:.1f}"


def table(doc: Mapping[str, Any]) -> str:
    """The limits as a table: one line per track, then the distribution."""
    lowest = doc["lowest_speed_m_s"]

    def show(limit: float | None) -> str:
        return show_limit(limit, lowest)

    lines = [f"{doc['agent']} ({doc['vehicle']} car, {doc['timing']} timing): speed limit "
             f"for {doc['laps']} lap{'s' if doc['laps'] != 1 else ''} without a departure, "
             f"seeds {doc['seeds'][0]}:{doc['seeds'][1]}",
             f"{'seed':>8}  {'limit [m/s]':>11}  drives"]
    for r in doc["per_seed"]:
        note = " (top speed)" if r["at_top_speed"] else (
            " (failed at the lowest speed)" if r["below_min_speed"] else "")
        lines.append(f"{r['seed']:>8}  {show(r['limit_m_s']):>11}  "
                     f"{len(r['drives']):>6}{note}")
    s = doc["summary"]
    lines.append(f"{s['count']} tracks: min {show(s['min_m_s'])}, q1 "
                 f"{show(s['q1_m_s'])}, median {show(s['median_m_s'])}, q3 "
                 f"{show(s['q3_m_s'])}, max {show(s['max_m_s'])} m/s; "
                 f"{s['below_min_speed']} below {lowest:g} m/s, "
                 f"{s['at_top_speed']} at the top speed")
    return "\n".join(lines)


def plot(doc: Mapping[str, Any], path: Path) -> None:
    """A histogram of the limits in ``STEP_M_S``·5 wide bins; the tracks below the lowest
    speed as a bar of their own left of it, the median as a line."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    limits = [r["limit_m_s"] for r in doc["per_seed"] if r["limit_m_s"] is not None]
    below = doc["summary"]["below_min_speed"]
    width = 5 * STEP_M_S
    lowest = doc["lowest_speed_m_s"]
    edges = np.arange(lowest, TOP_SPEED_M_S + width, width)
    edges[-1] = max(edges[-1], TOP_SPEED_M_S + 1e-6)  # the top speed falls in the last bin
    fig, ax = plt.subplots(figsize=(8.0, 4.0))
    ax.hist(limits, bins=edges, color="tab:blue", edgecolor="white",
            label="tracks by speed limit")
    if below:
        ax.bar(lowest - width / 2, below, width, color="tab:red", edgecolor="white",
               label=f"failed at {lowest:g} m/s")
    median = doc["summary"]["median_m_s"]
    if median is not None:
        ax.axvline(median, color="black", linestyle="--", label=f"median {median:.1f} m/s")
    ax.set_xlim(lowest - width, TOP_SPEED_M_S + width)
    ax.set_xlabel("speed limit [m/s]")
    ax.set_ylabel("tracks")
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_title(f"{doc['agent']}, {doc['vehicle']} car, {doc['timing']} timing: "
                 f"{doc['laps']} lap(s), seeds {doc['seeds'][0]}:{doc['seeds'][1]}")
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110, format="png")  # the file is a temporary name until commit
    plt.close(fig)
