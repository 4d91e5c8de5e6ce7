"""Stress test of the ROI reset logic: faults injected into closed-loop drives.

Each run: the PID drives a generated track from its start line at 1.5 m/s; ``ONSET_S``
seconds in one fault of the battery strikes (``FAULTS``), and the drive goes on for
``AFTER_S`` seconds after the fault has ended. The battery is in seconds and metres
(``tfalda_sim.faults``): on any camera its frames are counted at that camera's frame
rate. Every fault is run with the thesis' LIS and with its reset stage switched off
(``LisConfig(roi_reset=False)``), and a run without any fault counts the resets that
happen anyway. Per run:

- ``reset``: the LIS reset between the onset and ``AFTER_S`` after the end;
- ``frames_to_recover``: frames from the fault's end until the lanes are valid again —
  the detector's hit rate (from the track geometry) ≥ ``VALID_HIT_RATE`` for
  ``VALID_FRAMES`` frames in a row; None if they never are;
- ``false_resets``: resets before the onset or after the lanes were valid again (all the
  resets of the fault-free run);
- ``on_road``: the car never left the road.

``iter_battery`` streams the runs of a seed range from a process pool (bounded memory for
any range; results do not depend on the worker count); ``StressTally`` summarises them
as they come; ``tfalda-sim stress`` writes every run (JSON Lines) as it finishes, then the
summary as JSON, a Markdown table and a PNG chart.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from tfalda_sim.envs import TfaldaTrackEnv
from tfalda_sim.faults import (
    Blackout,
    CameraShake,
    Fault,
    FrameDropBurst,
    Glare,
    LatencySpike,
    LateralKick,
    MarkingGap,
    Overexposure,
    ServoOffset,
    WetPatch,
    frame_at,
)
from tfalda_sim.parallel import stream
from tfalda_sim.perception import DetectorConfig
from tfalda_sim.timing import TIMINGS, Timing, resolve_timing
from tfalda_sim.tracks import Lane, Obstacle, Track, generate
from tfalda_sim.tracks.dimensions import MAX_MARKING_GAP_M

from .pid import LanePid

ONSET_S: float = 3.0
"""Time at which the fault strikes [s] (frame 150 of the thesis camera)."""

AFTER_S: float = 3.0
"""Time driven after the fault's end [s]."""

THESIS_FRAME_S: float = 1.0 / 50.0
"""One frame of the thesis camera (50 frames/s) [s]: the length of a one-frame fault."""

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
    """One fault of the battery: its name, how long it lasts [s] (until its effect on
    the observations is over; 0: no fault) and how to make it for a drive that passes
    arc length ``s_onset`` [m] at the onset."""

    name: str
    duration_s: float
    make: Callable[[float], tuple[Fault, ...]]


LATENCY_SPIKE_S: tuple[float, float] = (0.5, 0.2)
"""The latency spike's window and extra delay [s]: for half a second the results come
10 thesis frames late (a stall of the processing, e.g. another process taking the CPU
of a prototype that ran at 100 % load, thesis 1.1)."""

WET_PATCH_M: float = 1.0
"""Length of the wet patch [m], laid where the car is at the onset."""

SERVO_OFFSET_RAD: float = 0.05
"""The knocked servo horn's offset [rad] (≈ 3°): a chosen stress, not a measured one —
less than one tooth of a 25-tooth servo spline (14.4°), as a horn slipped on a worn
spline or a bent steering link."""


def _battery(start: float) -> dict[str, Case]:
    ahead = SPEED_M_S * 0.2  # the gap starts a little ahead of the car at the onset
    window, extra = LATENCY_SPIKE_S
    return {c.name: c for c in (
        Case("none", 0.0, lambda s: ()),
        Case("blackout", 0.5, lambda s: (Blackout(start, 0.5),)),
        Case("overexposed", 0.5, lambda s: (Overexposure(start, 0.5, gain=4.0),)),
        # A reflection over the lower-right ROI: at pixel (520, 380) with a 70 px radius
        # on the thesis camera.
        Case("glare", 1.0, lambda s: (Glare(start, 1.0, ahead_m=0.26, left_m=-0.18,
                                            radius_m=0.115, peak_dn=220.0),)),
        Case("marking_gap", MAX_MARKING_GAP_M / SPEED_M_S, lambda s: (
            MarkingGap(s + ahead + 0.8, MAX_MARKING_GAP_M),)),
        Case("lateral_kick", THESIS_FRAME_S, lambda s: (LateralKick(start, 0.12),)),
        Case("camera_shake", 1.0, lambda s: (CameraShake(start, 1.0, amplitude_rad=0.03),)),
        # A carton on the left lane 1.2 m ahead (see _track_for), passed in ≈ 1 s.
        Case("obstacle", 1.0, lambda s: ()),
        # The tightest curve entered at 2× speed (see run_one): 3 m of it in 1 s.
        Case("fast_curve", 1.0, lambda s: ()),
        # Over when the last late result has arrived.
        Case("latency_spike", window + extra, lambda s: (LatencySpike(start, window, extra),)),
        Case("frame_drops", 0.5, lambda s: (FrameDropBurst(start, 0.5),)),
        # From where the car is at the onset; only the dynamic car (--vehicle dynamic)
        # feels it: the kinematic car drives as in the fault-free run.
        Case("wet_patch", WET_PATCH_M / SPEED_M_S, lambda s: (WetPatch(s, WET_PATCH_M),)),
        Case("servo_offset", 1.0, lambda s: (ServoOffset(start, 1.0, SERVO_OFFSET_RAD),)),
    )}


FAULTS: dict[str, Case] = _battery(ONSET_S)
"""The battery, by name."""


@dataclass
class StressRun:
    """The outcome of one fault on one track with one LIS configuration."""

    seed: int
    fault: str
    roi_reset_stage: bool
    roi_reset: bool
    frames_to_recover: int | None
    false_resets: int
    on_road: bool
    roi_resets: int


def _track_for(seed: int, fault: str, s_onset: float) -> Track:
    """The track of a run: the generated one; for ``obstacle`` with a carton standing on
    the left lane near the centre line 1.2 m ahead of the onset, hiding that line."""
    track = generate(seed).with_elements(obstacles=())
    if fault == "obstacle":
        s = (s_onset + 1.2) % track.length_m
        carton = Obstacle(s_m=s, lane=Lane.LEFT, length_m=0.3, width_m=0.2, height_m=0.2,
                          offset_m=-0.08)
        track = track.with_elements(obstacles=(carton,))
    return track


def run_one(seed: int, fault: str, roi_reset_stage: bool, camera: str = "thesis",
            vehicle: str = "kinematic", timing: str | Timing = "ideal",
            on_step: Callable[[TfaldaTrackEnv, dict[str, Any]], None] | None = None
            ) -> StressRun:
    """One closed-loop drive with ``fault`` on generated track ``seed`` by a car with
    ``camera`` (a profile name or file), ``vehicle`` and ``timing`` (the env's);
    ``on_step(env, info)`` after the reset and each step (a recording)."""
    case = FAULTS[fault]
    base = generate(seed).with_elements(obstacles=())
    speed = FAST_CURVE_SPEED_M_S if fault == "fast_curve" else SPEED_M_S
    start_s = base.start_line_s_m or 0.0
    if fault == "fast_curve":
        # Start so that the onset falls on the entry of the tightest curve.
        s_arc = _tightest_curve_start(base)
        start_s = (s_arc - speed * ONSET_S) % base.length_m
    s_onset = (start_s + speed * ONSET_S) % base.length_m
    track = _track_for(seed, fault, s_onset)
    cfg = DetectorConfig.thesis()
    if not roi_reset_stage:
        cfg = replace(cfg, lis=replace(cfg.lis, roi_reset=False))
    env = TfaldaTrackEnv(track=track, speed_m_s=speed, detector=cfg, camera=camera,
                         obstacles=fault == "obstacle", vehicle=vehicle, timing=timing)
    obs, info = env.reset(seed=seed, options={"start": (start_s, -0.5 * track.lane_width_m,
                                                        0.0),
                                              "faults": case.make(s_onset)})
    if on_step is not None:
        on_step(env, info)
    pid = LanePid(camera=env.camera)
    # The battery's seconds in this camera's frames, as the injector counts them.
    rate = env.camera.frame_rate_hz
    onset = frame_at(ONSET_S, rate)
    after = frame_at(AFTER_S, rate)
    end = onset + (max(1, frame_at(case.duration_s, rate)) if case.duration_s > 0 else 0)
    steps = end + after
    hits, resets = [], []
    on_road = True
    for _ in range(steps):
        obs, _, terminated, _, info = env.step(pid.act(obs))
        if on_step is not None:
            on_step(env, info)
        hits.append(info["detector_hit_rate"])
        resets.append(bool(info["roi_reset"]))
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
        back = end + (recovered if recovered is not None else after)
        in_window = any(onset <= k <= end + after for k in reset_steps)
        false = sum(1 for k in reset_steps if k < onset or k > back + VALID_FRAMES)
    return StressRun(seed=seed, fault=fault, roi_reset_stage=roi_reset_stage,
                     roi_reset=in_window, frames_to_recover=recovered, false_resets=false,
                     on_road=on_road, roi_resets=len(reset_steps))


def _tightest_curve_start(track: Track) -> float:
    """Arc length where the track's tightest arc begins [m]."""
    t = track.table
    k = int(np.argmax(np.abs(t.kappa)))
    return float(t.s0[k])


StressJob = tuple[int, str, bool, str] | tuple[int, str, bool, str, str, Timing]
"""(seed, fault, reset stage on, camera[, vehicle, timing]): one run of the battery; the
vehicle and the timing only when they are not the default car's."""


def run_job(job: StressJob) -> StressRun:
    """One job of the battery: the picklable top-level function every backend runs."""
    return run_one(*job)


def run_record(job: StressJob, run: StressRun) -> dict[str, Any]:
    """A run as its JSON record (a line of stress.jsonl and of ``--results``)."""
    return asdict(run)


def check_run_record(job: StressJob, rec: dict[str, Any]) -> None:
    """A stored record belongs to ``job`` and reads back as a ``StressRun``, else
    ValueError."""
    seed, fault, stage = job[:3]
    got = (rec.get("seed"), rec.get("fault"), rec.get("roi_reset_stage"))
    if got != (seed, fault, stage):
        raise ValueError(f"it holds the run (seed, fault, reset stage) {got}, the sweep's "
                         f"next run is {(seed, fault, stage)}")
    if set(rec) != {f.name for f in fields(StressRun)}:
        raise ValueError(f"its fields are {sorted(rec)}, a run has "
                         f"{sorted(f.name for f in fields(StressRun))}")


def check_fault_names(faults: Sequence[str] | None) -> list[str]:
    """The names of the stress battery's faults to run (default: the whole battery);
    unknown names refused (ValueError), and a name given twice (its runs would be made
    twice and pooled with themselves)."""
    names = list(FAULTS if faults is None else faults)
    unknown = [f for f in names if f not in FAULTS]
    if unknown or not names:
        raise ValueError(f"unknown fault(s) {', '.join(unknown) or '(none given)'}; "
                         f"known: {', '.join(FAULTS)}")
    repeated = [f for k, f in enumerate(names) if f in names[:k]]
    if repeated:
        raise ValueError(f"{repeated[0]} is named twice")
    return names


def battery_jobs(seeds: Iterable[int], faults: Sequence[str], camera: str = "thesis",
                 vehicle: str = "kinematic", timing: str | Timing = "ideal"
                 ) -> Iterator[StressJob]:
    """(seed, fault, reset stage, camera[, vehicle, timing]) for every run, seed by seed:
    a long range interrupted early has every fault of the seeds it reached, and the jobs
    are never all in memory. The timing travels read (a worker on another host need not
    have its file)."""
    resolved = resolve_timing(timing)
    env = () if vehicle == "kinematic" and resolved == TIMINGS["ideal"] else (vehicle,
                                                                               resolved)
    for seed in seeds:
        for fault in faults:
            for stage in (True, False):
                yield (int(seed), fault, stage, camera, *env)


def iter_battery(seeds: Iterable[int], faults: Sequence[str] | None = None, *,
                 workers: int = 1, camera: str = "thesis") -> Iterator[StressRun]:
    """Every fault × {with, without the reset stage} × seed, streamed from a process pool
    of ``workers`` (``tfalda_sim.parallel.stream``: bounded memory for any range, results
    in job order and independent of the worker count)."""
    yield from stream(run_job, battery_jobs(seeds, check_fault_names(faults), camera),
                      workers=workers)


@dataclass
class _Group:
    runs: int = 0
    roi_resets: int = 0
    false_resets: int = 0
    on_road: int = 0
    frames: Counter[int] = field(default_factory=Counter)


class StressTally:
    """The summary of a battery, updated run by run: memory bounded by the number of
    faults (``frames_to_recover`` is a count of the frames within ``AFTER_S``, kept as a
    histogram, so the median is exact)."""

    def __init__(self) -> None:
        self._groups: dict[tuple[str, bool], _Group] = {}
        self.runs = 0

    def add(self, run: StressRun) -> None:
        g = self._groups.setdefault((run.fault, run.roi_reset_stage), _Group())
        g.runs += 1
        g.roi_resets += run.roi_reset
        g.false_resets += run.false_resets
        g.on_road += run.on_road
        if run.frames_to_recover is not None:
            g.frames[run.frames_to_recover] += 1
        self.runs += 1

    def rows(self) -> list[dict[str, Any]]:
        """Per fault and reset stage: reset rate, recovery rate, median frames to
        recover, false resets per run, share of runs that stayed on the road."""
        rows = []
        for fault, stage in sorted(self._groups, key=lambda k: (list(FAULTS).index(k[0]),
                                                                not k[1])):
            g = self._groups[(fault, stage)]
            recovered = sum(g.frames.values())
            rows.append({
                "fault": fault, "roi_reset_stage": stage, "runs": g.runs,
                "roi_reset_rate": g.roi_resets / g.runs,
                "recovered_rate": recovered / g.runs,
                "median_frames_to_recover": _median(g.frames),
                "false_resets_per_run": g.false_resets / g.runs,
                "on_road_rate": g.on_road / g.runs,
            })
        return rows


def _median(counts: Counter[int]) -> float | None:
    """The median of a histogram of integers (numpy's convention for an even count)."""
    n = sum(counts.values())
    if n == 0:
        return None
    values = sorted(counts)
    cum = np.cumsum([counts[v] for v in values])
    lo = values[int(np.searchsorted(cum, (n - 1) // 2, side="right"))]
    hi = values[int(np.searchsorted(cum, n // 2, side="right"))]
    return (lo + hi) / 2.0


def summarise(runs: Iterable[StressRun]) -> list[dict[str, Any]]:
    """``StressTally.rows`` of ``runs``."""
    tally = StressTally()
    for run in runs:
        tally.add(run)
    return tally.rows()


def markdown_table(rows: Sequence[dict[str, Any]]) -> str:
    """The summary as a Markdown table."""
    lines = ["| fault | reset stage | runs | LIS reset | recovered | median frames to "
             "recover | false resets / run | stayed on road |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        med = r["median_frames_to_recover"]
        lines.append(
            f"| {r['fault']} | {'on' if r['roi_reset_stage'] else 'off'} | {r['runs']} | "
            f"{r['roi_reset_rate']:.0%} | {r['recovered_rate']:.0%} | "
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
                          and r["roi_reset_stage"] == stage), None) for f in faults]
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


REPORT_FILES: dict[str, str] = {"jsonl": "stress.jsonl", "json": "stress.json",
                               "md": "stress.md", "png": "stress.png"}
"""What ``tfalda-sim stress --out DIR`` writes into DIR: every run (JSON Lines, streamed
as the runs finish), the summary (JSON, Markdown) and its chart."""


def report_document(rows: Sequence[dict[str, Any]], runs: int) -> dict[str, Any]:
    """The content of ``stress.json``: the summary and the battery's constants."""
    return {"summary": list(rows), "runs": runs, "runs_file": REPORT_FILES["jsonl"],
            "onset_s": ONSET_S, "after_s": AFTER_S,
            "valid_hit_rate": VALID_HIT_RATE, "valid_frames": VALID_FRAMES}
