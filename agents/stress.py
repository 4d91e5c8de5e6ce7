"""Stress test of the ROI reset logic: faults injected into closed-loop drives.

Each run: the PID drives a generated track from its start line at 1.5 m/s; after
``ONSET_STEP`` frames one fault of the battery strikes (``FAULTS``), and the drive goes on
for ``AFTER_STEPS`` frames after the fault has ended. Every fault is run with the thesis'
LIS and with its reset stage switched off (``LisConfig(reset=False)``), and a run without
any fault counts the resets that happen anyway. Per run:

- ``reset``: the LIS reset between the onset and ``AFTER_STEPS`` frames after the end;
- ``frames_to_recover``: frames from the fault's end until the lanes are valid again —
  the detector's hit rate (from the track geometry) ≥ ``VALID_HIT_RATE`` for
  ``VALID_FRAMES`` frames in a row; None if they never are;
- ``false_resets``: resets before the onset or after the lanes were valid again (all the
  resets of the fault-free run);
- ``on_road``: the car never left the road.

``run_battery`` runs seed ranges in a process pool (results do not depend on the worker
count) with a progress bar; ``report`` writes JSON, a Markdown table and a PNG chart.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from envs import TfaldaTrackEnv
from tfalda_sim.faults import (
    Blackout,
    CameraShake,
    Fault,
    Glare,
    LateralKick,
    MarkingGap,
    Overexposure,
)
from tfalda_sim.perception import DetectorConfig
from tracks import Lane, Obstacle, Track, generate
from tracks.rules import MAX_MARKING_GAP_M

from .pid import LanePid

ONSET_STEP: int = 150
"""Frame at which the fault strikes (3 s into the drive) [frames]."""

AFTER_STEPS: int = 150
"""Frames driven after the fault's end [frames]."""

VALID_HIT_RATE: float = 0.75
"""The lanes count as valid from this mean hit rate on (the thesis' 0.75 line) [-]."""

VALID_FRAMES: int = 5
"""…for this many frames in a row [frames]."""

SPEED_M_S: float = 1.5
"""Cruise speed of the stress drives [m/s]."""

FAST_CURVE_SPEED_M_S: float = 3.0
"""Speed at which the tightest curve is entered in the ``fast_curve`` case [m/s]."""


@dataclass(frozen=True)
class Case:
    """One fault of the battery: its name, how long it lasts [frames] and how to make
    it for a drive that passes arc length ``s_onset`` [m] at the onset."""

    name: str
    duration: int
    make: Callable[[float], tuple[Fault, ...]]


def _battery(start: int) -> dict[str, Case]:
    ahead = SPEED_M_S * 0.2  # the gap starts a little ahead of the car at the onset
    return {c.name: c for c in (
        Case("none", 0, lambda s: ()),
        Case("blackout", 25, lambda s: (Blackout(start, 25),)),
        Case("overexposed", 25, lambda s: (Overexposure(start, 25, gain=4.0),)),
        Case("glare", 50, lambda s: (Glare(start, 50, u_px=520.0, v_px=380.0, radius_px=70.0,
                                           peak_dn=220.0),)),
        Case("marking_gap", int(MAX_MARKING_GAP_M / SPEED_M_S * 50), lambda s: (
            MarkingGap(s + ahead + 0.8, MAX_MARKING_GAP_M),)),
        Case("lateral_kick", 1, lambda s: (LateralKick(start, 0.12),)),
        Case("camera_shake", 50, lambda s: (CameraShake(start, 50, amplitude_rad=0.03),)),
        # A carton on the left lane 1.2 m ahead (see _track_for), passed in ≈ 50 frames.
        Case("obstacle", 50, lambda s: ()),
        # The tightest curve entered at 2× speed (see run_one): 3 m of it in 50 frames.
        Case("fast_curve", 50, lambda s: ()),
    )}


FAULTS: dict[str, Case] = _battery(ONSET_STEP)
"""The battery, by name."""


@dataclass
class StressRun:
    """The outcome of one fault on one track with one LIS configuration."""

    seed: int
    fault: str
    lis_reset_stage: bool
    reset: bool
    frames_to_recover: int | None
    false_resets: int
    on_road: bool
    resets: int


def _track_for(seed: int, fault: str, s_onset: float) -> Track:
    """The track of a run: the generated one; for ``obstacle`` with a carton standing on
    the left lane near the centre line 1.2 m ahead of the onset, hiding that line."""
    track = replace(generate(seed), obstacles=())
    if fault == "obstacle":
        s = (s_onset + 1.2) % track.length_m
        carton = Obstacle(s_m=s, lane=Lane.LEFT, length_m=0.3, width_m=0.2, height_m=0.2,
                          offset_m=-0.08)
        track = replace(track, obstacles=(carton,))
    return track


def run_one(seed: int, fault: str, lis_reset_stage: bool) -> StressRun:
    """One closed-loop drive with ``fault`` on generated track ``seed``."""
    case = FAULTS[fault]
    base = replace(generate(seed), obstacles=())
    speed = FAST_CURVE_SPEED_M_S if fault == "fast_curve" else SPEED_M_S
    start_s = base.start_line_s_m or 0.0
    if fault == "fast_curve":
        # Start so that the onset falls on the entry of the tightest curve.
        s_arc = _tightest_curve_start(base)
        start_s = (s_arc - speed * ONSET_STEP / 50.0) % base.length_m
    s_onset = (start_s + speed * ONSET_STEP / 50.0) % base.length_m
    track = _track_for(seed, fault, s_onset)
    cfg = DetectorConfig.thesis()
    if not lis_reset_stage:
        cfg = replace(cfg, lis=replace(cfg.lis, reset=False))
    env = TfaldaTrackEnv(track=track, speed_m_s=speed, detector=cfg,
                         obstacles=fault == "obstacle")
    obs, _ = env.reset(seed=seed, options={"start": (start_s, -0.5 * track.lane_width_m, 0.0),
                                           "faults": case.make(s_onset)})
    pid = LanePid()
    end = ONSET_STEP + case.duration
    steps = end + AFTER_STEPS
    hits, resets = [], []
    on_road = True
    for _ in range(steps):
        obs, _, terminated, _, info = env.step(pid.act(obs))
        hits.append(info["detector_hit_rate"])
        resets.append(bool(info["lis_reset"]))
        if terminated:
            on_road = False
            break
    hits_a = np.array(hits)
    valid = hits_a >= VALID_HIT_RATE
    recovered = None
    for k in range(end, len(valid) - VALID_FRAMES + 1):
        if valid[k:k + VALID_FRAMES].all():
            recovered = k - end
            break
    reset_steps = [k + 1 for k, r in enumerate(resets) if r]
    if fault == "none":
        false = len(reset_steps)
        in_window = False
    else:
        back = end + (recovered if recovered is not None else AFTER_STEPS)
        in_window = any(ONSET_STEP <= k <= end + AFTER_STEPS for k in reset_steps)
        false = sum(1 for k in reset_steps if k < ONSET_STEP or k > back + VALID_FRAMES)
    return StressRun(seed=seed, fault=fault, lis_reset_stage=lis_reset_stage,
                     reset=in_window, frames_to_recover=recovered, false_resets=false,
                     on_road=on_road, resets=len(reset_steps))


def _tightest_curve_start(track: Track) -> float:
    """Arc length where the track's tightest arc begins [m]."""
    t = track.table
    k = int(np.argmax(np.abs(t.kappa)))
    return float(t.s0[k])


def _run(args: tuple[int, str, bool]) -> StressRun:
    return run_one(*args)


def run_battery(seeds: Sequence[int], faults: Sequence[str] | None = None, *,
                workers: int | None = None, progress: bool = True) -> list[StressRun]:
    """Every fault × {with, without the reset stage} × seed, in a process pool."""
    names = list(faults or FAULTS)
    unknown = [f for f in names if f not in FAULTS]
    if unknown:
        raise ValueError(f"unknown fault(s) {', '.join(unknown)}; known: {', '.join(FAULTS)}")
    jobs = [(seed, f, stage) for f in names for stage in (True, False) for seed in seeds]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        return list(tqdm(pool.map(_run, jobs, chunksize=1), total=len(jobs), desc="stress",
                         disable=not progress))


def summarise(runs: Sequence[StressRun]) -> list[dict[str, Any]]:
    """Per fault and reset stage: reset rate, recovery rate, median frames to recover,
    false resets per run, share of runs that stayed on the road."""
    rows = []
    keys = sorted({(r.fault, r.lis_reset_stage) for r in runs},
                  key=lambda k: (list(FAULTS).index(k[0]), not k[1]))
    for fault, stage in keys:
        group = [r for r in runs if r.fault == fault and r.lis_reset_stage == stage]
        frames = [r.frames_to_recover for r in group if r.frames_to_recover is not None]
        rows.append({
            "fault": fault, "lis_reset_stage": stage, "runs": len(group),
            "reset_rate": float(np.mean([r.reset for r in group])),
            "recovered_rate": len(frames) / len(group),
            "median_frames_to_recover": float(np.median(frames)) if frames else None,
            "false_resets_per_run": float(np.mean([r.false_resets for r in group])),
            "on_road_rate": float(np.mean([r.on_road for r in group])),
        })
    return rows


def markdown_table(rows: Sequence[dict[str, Any]]) -> str:
    """The summary as a Markdown table."""
    lines = ["| fault | reset stage | runs | LIS reset | recovered | median frames to "
             "recover | false resets / run | stayed on road |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        med = r["median_frames_to_recover"]
        lines.append(
            f"| {r['fault']} | {'on' if r['lis_reset_stage'] else 'off'} | {r['runs']} | "
            f"{r['reset_rate']:.0%} | {r['recovered_rate']:.0%} | "
            f"{'–' if med is None else f'{med:.0f}'} | {r['false_resets_per_run']:.2f} | "
            f"{r['on_road_rate']:.0%} |")
    return "\n".join(lines)


def plot(rows: Sequence[dict[str, Any]], path: Path) -> None:
    """Recovery rate and median frames to recover per fault, reset stage on vs off."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    faults = [f for f in FAULTS if any(r["fault"] == f for r in rows)]
    x = np.arange(len(faults))
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    for k, (key, label) in enumerate((("recovered_rate", "lanes valid again [share of runs]"),
                                      ("median_frames_to_recover", "median frames to recover"),
                                      ("on_road_rate", "stayed on the road [share]"))):
        ax = axes[k]
        for j, stage in enumerate((True, False)):
            vals = [next((r[key] for r in rows if r["fault"] == f
                          and r["lis_reset_stage"] == stage), None) for f in faults]
            vals = [math.nan if v is None else v for v in vals]
            ax.bar(x + (j - 0.5) * 0.38, vals, 0.38,
                   label=f"LIS reset stage {'on' if stage else 'off'}")
        ax.set_xticks(x, faults, rotation=35, ha="right")
        ax.set_title(label)
        ax.grid(axis="y", alpha=0.3)
    axes[0].legend()
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def report(runs: Sequence[StressRun], out_dir: Path) -> dict[str, Any]:
    """Write ``stress.json``, ``stress.md`` and ``stress.png`` to ``out_dir``."""
    rows = summarise(runs)
    out_dir.mkdir(parents=True, exist_ok=True)
    result = {"summary": rows, "runs": [asdict(r) for r in runs],
              "onset_step": ONSET_STEP, "after_steps": AFTER_STEPS,
              "valid_hit_rate": VALID_HIT_RATE, "valid_frames": VALID_FRAMES}
    (out_dir / "stress.json").write_text(json.dumps(result, indent=1))
    (out_dir / "stress.md").write_text(markdown_table(rows) + "\n")
    plot(rows, out_dir / "stress.png")
    return result
