"""The figures of docs/dynamics.md from the runs of the speed-limit study: a chart of the
speed-limit distributions and their table (Markdown on stdout).

    python tools/make_dynamics_docs.py RUNS_DIR [--chart docs/dynamics/limits.png]

RUNS_DIR holds the ``tfalda-sim limits --out`` files of the study, named
``pid-{kinematic,dynamic}-latency-{0..3}.json`` and ``ppo-dynamic-real-car.json``
(docs/dynamics.md gives the commands).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

RUNS: tuple[tuple[str, str], ...] = (
    *((f"pid-{v}-latency-{k}.json", f"PID, {v}, {k} frame{'s' if k != 1 else ''} late")
      for v in ("kinematic", "dynamic") for k in range(4)),
    ("ppo-dynamic-real-car.json", "PPO (dynamic, randomised timing), dynamic, real-car"),
)


def _cell(value: float | None) -> str:
    return "–" if value is None else f"{value:.1f}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", type=Path, help="the folder of the limits runs")
    parser.add_argument("--chart", type=Path, default=Path("docs/dynamics/limits.png"))
    args = parser.parse_args(argv)
    found = [(label, json.loads((args.runs / name).read_text()))
             for name, label in RUNS if (args.runs / name).is_file()]
    if not found:
        print(f"no limits runs in {args.runs}", file=sys.stderr)
        return 2
    print("| configuration | tracks | below the lowest speed | min | q1 | median | q3 | max "
          "| at top speed |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for label, doc in found:
        s = doc["summary"]
        print(f"| {label} | {s['count']} | {s['below_min_speed']} | {_cell(s['min_m_s'])} | "
              f"{_cell(s['q1_m_s'])} | {_cell(s['median_m_s'])} | {_cell(s['q3_m_s'])} | "
              f"{_cell(s['max_m_s'])} | {s['at_top_speed']} |")
    fig, ax = plt.subplots(figsize=(9, 0.55 * len(found) + 1.5))
    data = [[r["limit_m_s"] for r in doc["per_seed"] if r["limit_m_s"] is not None]
            for _, doc in found]
    ax.boxplot(data, orientation="horizontal", tick_labels=[label for label, _ in found],
               whis=(0, 100))
    for y, values in enumerate(data, start=1):
        ax.scatter(values, [y] * len(values), s=6, alpha=0.4, color="tab:blue")
    ax.set_xlabel("speed limit: highest cruise speed completing the laps [m/s]")
    ax.invert_yaxis()
    ax.grid(axis="x", alpha=0.3)
    fig.tight_layout()
    args.chart.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.chart, dpi=110)
    print(f"\nwrote {args.chart}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
