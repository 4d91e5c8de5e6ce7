"""PNG charts of evaluation runs (matplotlib, headless): confidence per frame as in the
thesis' figures 4.2–4.6, per-seed summaries and the LIS ablation."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .runner import LOW_CONFIDENCE, WITH_LIS, WITHOUT_LIS, RunResult

RUN_COLOURS = {WITH_LIS: "tab:red", WITHOUT_LIS: "tab:blue"}
"""The thesis' colours: red "mit LIS alles aktiviert", blue "ohne LIS Stand Studienarbeit"."""


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")  # headless: files only
    import matplotlib.pyplot as plt

    return plt


def _save(fig: Any, path: str | os.PathLike[str]) -> None:
    from tfalda_sim.fileio import atomic_write

    with atomic_write(path, "wb") as f:
        fig.savefig(f, format="png", dpi=110)


def plot_confidence(runs: Mapping[str, RunResult], path: str | os.PathLike[str], *,
                    title: str) -> None:
    """Confidence per frame [%] of each run over the sequence numbers, the 75 % line and
    the frames where a run reset (×)."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(8.0, 3.6))
    for label, run in runs.items():
        colour = RUN_COLOURS.get(label)
        conf = 100 * run.confidence
        ax.plot(run.seq, conf, lw=1.3, color=colour, label=label)
        if run.roi_reset.any():
            ax.plot(run.seq[run.roi_reset], conf[run.roi_reset], "x", color=colour, ms=7,
                    label=f"{label}: reset")
    ax.axhline(100 * LOW_CONFIDENCE, color="grey", lw=0.8, ls="--")
    ax.set_ylim(0, 102)
    ax.set_xlabel("sequence number")
    ax.set_ylabel("lanes on a marking [%]")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower left", fontsize=8)
    fig.tight_layout()
    _save(fig, path)
    plt.close(fig)


def plot_seeds(per_seed: Sequence[Mapping[str, Any]], path: str | os.PathLike[str], *,
               title: str) -> None:
    """Mean confidence and frames below 75 % per generated track (one summary dict per
    seed and run, as ``RunResult.summary`` gives)."""
    plt = _pyplot()
    labels = list(dict.fromkeys(s["run"] for s in per_seed))
    seeds = sorted({s["seed"] for s in per_seed})
    index = {seed: i for i, seed in enumerate(seeds)}
    fig, (a0, a1) = plt.subplots(2, 1, figsize=(8.0, 5.0), sharex=True)
    width = 0.8 / max(1, len(labels))
    for j, label in enumerate(labels):
        rows = [s for s in per_seed if s["run"] == label]
        x = np.array([index[s["seed"]] for s in rows]) + (j - (len(labels) - 1) / 2) * width
        colour = RUN_COLOURS.get(label)
        a0.bar(x, [100 * s["mean_confidence"] for s in rows], width, color=colour, label=label)
        a1.bar(x, [s["frames_below_0_75"] for s in rows], width, color=colour, label=label)
    a0.set_ylabel("mean confidence [%]")
    a0.set_ylim(0, 102)
    a1.set_ylabel("frames < 75 %")
    a1.set_xlabel("track seed")
    step = max(1, len(seeds) // 25)
    a1.set_xticks(range(0, len(seeds), step), [str(s) for s in seeds[::step]])
    a0.set_title(title)
    a0.legend(loc="lower left", fontsize=8)
    for a in (a0, a1):
        a.grid(alpha=0.3, axis="y")
    fig.tight_layout()
    _save(fig, path)
    plt.close(fig)


def plot_ablation(rows: Sequence[Mapping[str, Any]], path: str | os.PathLike[str], *,
                  title: str) -> None:
    """One bar per configuration: mean confidence, frames below 75 % and resets."""
    plt = _pyplot()
    names = [r["config"] for r in rows]
    y = np.arange(len(rows))
    fig, axes = plt.subplots(1, 3, figsize=(10.0, 0.4 * len(rows) + 1.4), sharey=True)
    for ax, key, label in zip(axes, ("mean_confidence", "frames_below_0_75", "roi_resets"),
                              ("mean confidence [%]", "frames < 75 %", "roi_resets"), strict=True):
        values = [100 * r[key] if key == "mean_confidence" else r[key] for r in rows]
        ax.barh(y, values, color="tab:gray")
        ax.set_xlabel(label)
        ax.grid(alpha=0.3, axis="x")
        if key == "mean_confidence":
            lo = min(values)
            ax.set_xlim(max(0.0, lo - 5), 100)
    axes[0].set_yticks(y, names)
    axes[0].invert_yaxis()
    fig.suptitle(title)
    fig.tight_layout()
    _save(fig, path)
    plt.close(fig)
