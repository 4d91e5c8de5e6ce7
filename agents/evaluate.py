"""Evaluate an agent on held-out generated tracks: laps completed without leaving the road.

    python -m agents.evaluate --agent pid --seeds 10000:10100 --laps 3 [--speeds 1.5,2,2.5] --json

Each track (its cartons removed: lane keeping does not avoid obstacles) is driven from
its start line; a run succeeds when the car completes the laps
without a departure (the drive ends at the first one). Seeds run in a process pool
(results do not depend on the worker count) with a progress bar. ``--speeds`` runs the
same tracks at several speeds (the speed sweep of docs/agents.md).
"""

from __future__ import annotations

import argparse
import json
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from tfalda_sim.cli_common import seed_range_arg
from tracks import generate

from .drive import drive, make_agent
from .train import TEST_SEEDS


def _one(job: tuple[str, str | None, int, int, float]) -> dict[str, Any]:
    kind, policy, seed, laps, speed = job
    track = replace(generate(seed), obstacles=())  # lane keeping: no cartons to avoid
    result = drive(make_agent(kind, policy), track, laps=laps, speed_m_s=speed,
                   recover=False, label=f"seed {seed}")
    return {"seed": seed, "speed_m_s": speed, "success": result.laps_completed == laps,
            **{k: v for k, v in result.summary().items() if k != "track"}}


def evaluate(kind: str, seeds: range, *, laps: int = 3, speeds: tuple[float, ...] = (1.5,),
             policy: str | None = None, workers: int | None = None, progress: bool = True
             ) -> dict[str, Any]:
    """Drive every seed at every speed; per speed the success rate and figures."""
    make_agent(kind, policy)  # fail early on a bad agent or policy
    jobs = [(kind, policy, seed, laps, speed) for speed in speeds for seed in seeds]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        runs = list(tqdm(pool.map(_one, jobs, chunksize=1), total=len(jobs), desc=kind,
                         disable=not progress))
    per_speed = []
    for speed in speeds:
        group = [r for r in runs if r["speed_m_s"] == speed]
        per_speed.append({
            "speed_m_s": speed, "tracks": len(group),
            "success_rate": float(np.mean([r["success"] for r in group])),
            "successes": int(sum(r["success"] for r in group)),
            "failed_seeds": [r["seed"] for r in group if not r["success"]],
            "mean_abs_cross_track_m": float(np.mean([r["mean_abs_cross_track_m"]
                                                     for r in group])),
            "lis_resets_per_track": float(np.mean([r["lis_resets"] for r in group])),
        })
    return {"agent": kind, "policy": policy, "laps": laps, "seeds": [seeds.start, seeds.stop],
            "speeds": per_speed, "runs": runs}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agent", choices=["pid", "ppo"], default="pid")
    parser.add_argument("--policy", help="PPO policy .zip (default: the committed one)")
    parser.add_argument("--seeds", type=seed_range_arg,
                        default=range(*TEST_SEEDS), help="held-out seeds A:B")
    parser.add_argument("--laps", type=int, default=3)
    parser.add_argument("--speeds", default="1.5", help="comma-separated speeds [m/s]")
    parser.add_argument("--workers", type=int, help="processes (default: all CPUs)")
    parser.add_argument("--out", type=Path, help="also write the JSON here")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    try:
        speeds = tuple(float(v) for v in args.speeds.split(","))
    except ValueError:
        parser.error(f"--speeds must be comma-separated numbers, got {args.speeds!r}")
    if any(not 0 < v <= 8.3 for v in speeds) or args.laps < 1:
        parser.error("speeds must be in (0, 8.3] m/s and --laps ≥ 1")
    result = evaluate(args.agent, args.seeds, laps=args.laps, speeds=speeds,
                      policy=args.policy, workers=args.workers, progress=not args.json)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(result, indent=1))
    if args.json:
        print(json.dumps(result))
        return 0
    print(f"{args.agent}: {args.laps} laps on seeds {args.seeds.start}:{args.seeds.stop}")
    print(f"{'speed':>8}{'success':>10}{'mean |e|':>10}{'resets/track':>14}")
    for r in result["speeds"]:
        print(f"{r['speed_m_s']:>6.2f} m/s{r['successes']:>5}/{r['tracks']:<4}"
              f"{r['mean_abs_cross_track_m'] * 100:>8.1f}cm{r['lis_resets_per_track']:>12.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
