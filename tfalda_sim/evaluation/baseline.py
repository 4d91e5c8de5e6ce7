"""The Hough baseline against TFALDA (with and without the LIS): the same rendered frames,
the same ground truth, one metric for both.

The two detectors give different things — TFALDA one lane per ROI (four), the Hough
baseline up to five line segments anywhere in its crop — so both are scored as a set of
line segments in image pixels:

- **hit rate**: the thesis' black-box test (section 4.1.7, ``lane_hit_rates``): the share
  of a line's pixels within ε (5 px) of a painted longitudinal marking; per frame the mean
  over the lines given, 0 for a frame without any line. It measures how much of what a
  detector reports lies on markings (a precision): TFALDA always reports its four lanes,
  Hough up to five segments, however many it finds — one good segment scores 1;
- **false positive**: a line with less than half of it on a marking
  (``LANE_FAILURE_HIT_RATE``) — a line where there is none (``tfalda-sim evaluate`` counts
  its TuSimple false positives per ROI instead, which Hough has no ROIs for);
- **ego lines found** (the recall): the share of frames in which the car's own lane
  boundaries (left: the centre line, right: the side line), where visible in TFALDA's ROI
  rows (``BAND_ROWS``, inside the Hough crop), are followed by some line: TuSimple's point
  accuracy of the line against the boundary ≥ 0.85 over at least ``MIN_MATCH_ROWS`` rows;
- **compute time**: wall-clock time of the detector alone per frame [ms] (TFALDA + LIS:
  the thesis pipeline on the full frame; Hough: the seed's steps), in the same process.

``iter_compare`` runs the thesis' scenarios and generated tracks (seeds in a process
pool), ``CompareTally`` pools them;
``tfalda-sim compare`` prints the table, ``--json``, and writes JSON, Markdown and a PNG.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..camera import Camera, load_camera
from ..histogram import TimeHistogram
from ..parallel import stream
from ..perception import DetectorConfig, HoughConfig, HoughDetector, LaneObservation
from ..perception.hough import SIMULATOR_BINARISE_LEVEL
from ..perception.params import IMAGE_HEIGHT_PX, IMAGE_WIDTH_PX, INITIAL_ROIS, is_thesis_camera
from ..rendering import FrameTruth, Renderer
from ..tracks import seed_name
from .metrics import (
    EPSILON_PX,
    LANE_FAILURE_HIT_RATE,
    TUSIMPLE_MIN_ACCURACY,
    boundary_x_at_rows,
    lane_hit_rates,
    lane_x_at_rows,
    truth_distance,
    tusimple_accuracy,
)
from .runner import run_scenario
from .scenarios import Scenario, ScenarioKind, generated_scenario, thesis_scenario

HOUGH_SEED = "Hough (seed values)"
HOUGH_SIMULATOR = "Hough (simulator preset)"
TFALDA_LIS = "TFALDA + LIS"
TFALDA_NO_LIS = "TFALDA without LIS"

MIN_MATCH_ROWS: int = 10
"""A line finds an ego boundary only over at least this many image rows [px]."""

BAND_ROWS: tuple[int, int] = (min(r[1] for r in INITIAL_ROIS),
                              max(r[1] + r[3] for r in INITIAL_ROIS))
"""Image rows [first, stop) [px] in which an ego boundary counts as visible: the rows of
TFALDA's ROIs (260–425, table 2.4), which both detectors look at (the Hough crop is rows
219–477, its simulator mask starts at 441)."""

MIN_VISIBLE_ROWS: int = 20
"""An ego boundary is visible in a frame when it crosses at least this many rows of the
band [px]."""


def hough_detectors(camera: Camera | None = None) -> dict[str, HoughConfig]:
    """The Hough runs of the comparison: the seed's numbers as they are, and the simulator
    preset (the binarising level of our markings, our car's bonnet as the mask; on another
    camera its crop and mask derived, ``HoughConfig.for_camera``). The seed's numbers run
    only on a 752×480 camera (they are rows and columns of one)."""
    if camera is None or is_thesis_camera(camera):
        return {HOUGH_SEED: HoughConfig(), HOUGH_SIMULATOR: HoughConfig.simulator()}
    out = {HOUGH_SIMULATOR: HoughConfig.for_camera(camera, SIMULATOR_BINARISE_LEVEL)}
    if (camera.width, camera.height) == (IMAGE_WIDTH_PX, IMAGE_HEIGHT_PX):
        out = {HOUGH_SEED: HoughConfig(), **out}
    return out


def tfalda_detectors(camera: Camera | None = None) -> dict[str, DetectorConfig]:
    """The TFALDA runs: the thesis' configuration with and without the LIS (on another
    camera with its derived geometry)."""
    configs = {TFALDA_LIS: DetectorConfig.thesis(), TFALDA_NO_LIS: DetectorConfig.without_lis()}
    return configs if camera is None else {k: c.on_camera(camera) for k, c in configs.items()}


def band_rows(config: DetectorConfig) -> tuple[int, int]:
    """Image rows [first, stop) [px] of a configuration's ROI band (``BAND_ROWS`` for the
    thesis layout)."""
    table = config.layout.table_px
    return min(r[1] for r in table), max(r[1] + r[3] for r in table)


@dataclass(frozen=True)
class LineScore:
    """One frame's lines ``(N, 4)`` (x1, y1, x2, y2) [px] against the truth."""

    hit_rates: np.ndarray
    """(N,) black-box hit rate of each line [0, 1]."""
    false_positive: np.ndarray
    """(N,) bool: the line lies mostly off the markings."""
    ego_visible: np.ndarray
    """(2,) bool: the ego lane's left, right boundary crosses the band."""
    ego_found: np.ndarray
    """(2,) bool: a line follows the visible left, right boundary."""

    @property
    def confidence(self) -> float:
        """The frame's mean hit rate, 0 without any line."""
        return float(self.hit_rates.mean()) if len(self.hit_rates) else 0.0


def _follows(line: np.ndarray, boundary: np.ndarray) -> bool:
    """The line matches the boundary polyline over its rows (TuSimple, ≥ MIN_MATCH_ROWS)."""
    y0, y1 = sorted((float(line[1]), float(line[3])))
    rows = np.arange(np.ceil(y0), np.floor(y1) + 1)
    if len(rows) < MIN_MATCH_ROWS:
        return False
    truth_x = boundary_x_at_rows(boundary, rows)
    if np.isfinite(truth_x).sum() < MIN_MATCH_ROWS:
        return False
    return tusimple_accuracy(lane_x_at_rows(line, rows), truth_x, rows) >= TUSIMPLE_MIN_ACCURACY


def score_lines(lines: np.ndarray, truth: FrameTruth, distance: np.ndarray | None = None, *,
                epsilon_px: float = EPSILON_PX, band: tuple[int, int] = BAND_ROWS
                ) -> LineScore:
    """Score a frame's lines ``(N, 4)`` [px]; rows with a non-finite value are no line.
    Pass ``distance`` (``truth_distance(truth.labels)``) to reuse it; ``band``: the rows
    [first, stop) in which an ego boundary counts as visible."""
    lines = np.asarray(lines, np.float64).reshape(-1, 4)
    lines = lines[np.all(np.isfinite(lines), axis=1)]
    if distance is None:
        distance = truth_distance(truth.labels)
    hits = lane_hit_rates(lines, distance, epsilon_px)
    rows = np.arange(*band, dtype=np.float64)
    visible = np.zeros(2, bool)
    found = np.zeros(2, bool)
    for k, boundary in enumerate((truth.left_boundary_px, truth.right_boundary_px)):
        visible[k] = np.isfinite(boundary_x_at_rows(boundary, rows)).sum() >= MIN_VISIBLE_ROWS
        found[k] = visible[k] and any(_follows(line, boundary) for line in lines)
    return LineScore(hit_rates=hits, false_positive=hits < LANE_FAILURE_HIT_RATE,
                     ego_visible=visible, ego_found=found)


@dataclass
class Tally:
    """One detector's sums over frames (tallies of several tracks add up with ``+``)."""

    frames: int = 0
    confidence_sum: float = 0.0
    frames_without_line: int = 0
    lines: int = 0
    false_positives: int = 0
    ego_visible: np.ndarray = field(default_factory=lambda: np.zeros(2, np.int64))
    ego_found: np.ndarray = field(default_factory=lambda: np.zeros(2, np.int64))
    times: TimeHistogram = field(default_factory=TimeHistogram)
    """Detector time per frame (binned: memory bounded by the bins, not the frames)."""

    def add(self, score: LineScore, time_s: float) -> None:
        self.frames += 1
        self.confidence_sum += score.confidence
        self.frames_without_line += int(len(score.hit_rates) == 0)
        self.lines += len(score.hit_rates)
        self.false_positives += int(score.false_positive.sum())
        self.ego_visible += score.ego_visible
        self.ego_found += score.ego_found
        self.times.add(time_s)

    def __add__(self, other: Tally) -> Tally:
        return Tally(self.frames + other.frames, self.confidence_sum + other.confidence_sum,
                     self.frames_without_line + other.frames_without_line,
                     self.lines + other.lines, self.false_positives + other.false_positives,
                     self.ego_visible + other.ego_visible, self.ego_found + other.ego_found,
                     self.times + other.times)

    def to_json(self) -> dict[str, Any]:
        """The sums as JSON values (``from_json`` reads them back exactly)."""
        return {"frames": self.frames, "confidence_sum": self.confidence_sum,
                "frames_without_line": self.frames_without_line, "lines": self.lines,
                "false_positives": self.false_positives,
                "ego_visible": [int(v) for v in self.ego_visible],
                "ego_found": [int(v) for v in self.ego_found],
                "times": sorted([int(b), int(c)] for b, c in self.times.counts.items())}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Tally:
        """A tally from ``to_json``'s values (KeyError, TypeError or ValueError if they
        are not)."""
        times = TimeHistogram()
        for b, c in data["times"]:
            times.counts[int(b)] = int(c)
        out = cls(int(data["frames"]), float(data["confidence_sum"]),
                  int(data["frames_without_line"]), int(data["lines"]),
                  int(data["false_positives"]), np.array(data["ego_visible"], np.int64),
                  np.array(data["ego_found"], np.int64), times)
        if out.ego_visible.shape != (2,) or out.ego_found.shape != (2,):
            raise ValueError("ego_visible and ego_found hold two counts each")
        return out

    def summary(self) -> dict[str, Any]:
        """The figures (rates in [0, 1], times in ms)."""
        n = max(self.frames, 1)
        found = [float(f / v) if v else None
                 for f, v in zip(self.ego_found, self.ego_visible, strict=True)]
        return {
            "frames": self.frames,
            "hit_rate": self.confidence_sum / n,
            "lines_per_frame": self.lines / n,
            "frames_without_line": self.frames_without_line,
            "false_positives_per_frame": self.false_positives / n,
            "false_positive_share": self.false_positives / max(self.lines, 1),
            "ego_left_found": found[0],
            "ego_right_found": found[1],
            "ms_per_frame_median": self.times.median_ms(),  # to 0.01 ms (binned)
            "ms_per_frame_p95": self.times.p95_ms(),
        }


def compare_scenario(scenario: Scenario, *, renderer: Renderer | None = None,
                     hough: Mapping[str, HoughConfig] | None = None,
                     tfalda: Mapping[str, DetectorConfig] | None = None,
                     epsilon_px: float = EPSILON_PX, progress: bool = False
                     ) -> dict[str, Tally]:
    """Every detector on every frame of ``scenario``: a tally per detector label (by
    default the detectors of ``renderer``'s camera)."""
    camera = renderer.camera if renderer is not None else None
    hough = hough_detectors(camera) if hough is None else dict(hough)
    tfalda = tfalda_detectors(camera) if tfalda is None else dict(tfalda)
    if not tfalda:
        raise ValueError("give at least one TFALDA configuration (the frames come from its "
                         "scenario runner)")
    if set(hough) & set(tfalda):
        raise ValueError("detector labels must differ, both have "
                         f"{sorted(set(hough) & set(tfalda))}")
    detectors = {label: HoughDetector(cfg) for label, cfg in hough.items()}
    tallies = {label: Tally() for label in (*tfalda, *hough)}
    scores: dict[str, list[LineScore]] = {label: [] for label in tfalda}
    band = band_rows(next(iter(tfalda.values())))

    def on_frame(seq: int, frame: np.ndarray, truth: FrameTruth,
                 observations: Mapping[str, LaneObservation]) -> None:
        distance = truth_distance(truth.labels)
        for label, obs in observations.items():
            scores[label].append(score_lines(obs.lanes, truth, distance, epsilon_px=epsilon_px,
                                             band=band))
        for label, det in detectors.items():
            t0 = time.perf_counter()
            segments = det.detect(frame).segments
            dt = time.perf_counter() - t0
            tallies[label].add(score_lines(segments, truth, distance, epsilon_px=epsilon_px,
                                           band=band), dt)

    runs = run_scenario(scenario, tfalda, renderer=renderer, epsilon_px=epsilon_px,
                        progress=progress, on_frame=on_frame)
    for label, run in runs.items():  # TFALDA's time as the runner measured it
        for score, dt in zip(scores[label], run.detector_s, strict=True):
            tallies[label].add(score, float(dt))
    return tallies


_RENDERERS: dict[str, Renderer] = {}


def _one(job: tuple[str, int | None, int | None, str]) -> tuple[str, dict[str, Tally]]:
    kind, seed, max_frames, camera = job
    renderer = _RENDERERS.get(camera)
    if renderer is None:  # one per camera and worker process: its pixel geometry is costly
        renderer = _RENDERERS[camera] = Renderer(load_camera(camera))
    if seed is None:
        scenario = thesis_scenario(ScenarioKind(kind))
        group = kind
    else:
        scenario = generated_scenario(seed, max_frames=max_frames)
        group = "generated"
    return group, compare_scenario(scenario, renderer=renderer)


CompareJob = tuple[str, int | None, int | None, str]
"""(thesis scenario or "random", seed, max frames, camera): one scenario of the comparison."""


def run_job(job: CompareJob) -> tuple[str, dict[str, Tally]]:
    """One scenario: the picklable top-level function every backend runs."""
    return _one(job)


def job_name(job: CompareJob) -> str:
    """The scenario's name in compare.jsonl: the thesis scenario or ``seed-N``
    (``tracks.seed_name``, as every output labels a generated track)."""
    return job[0] if job[1] is None else seed_name(job[1])


def run_record(job: CompareJob, result: tuple[str, Mapping[str, Tally]]) -> dict[str, Any]:
    """A scenario's JSON record (a line of ``--results``): its figures and its tallies."""
    group, tallies = result
    return {"scenario": job_name(job), "group": group,
            "detectors": {k: t.summary() for k, t in tallies.items()},
            "tallies": {k: t.to_json() for k, t in tallies.items()}}


def check_run_record(job: CompareJob, rec: dict[str, Any]) -> None:
    """A stored record is ``job``'s scenario and its tallies read back, else an error."""
    if rec.get("scenario") != job_name(job):
        raise ValueError(f"it holds scenario {rec.get('scenario')!r}, the sweep's next one is "
                         f"{job_name(job)!r}")
    if not isinstance(rec.get("group"), str) or not isinstance(rec.get("tallies"), dict):
        raise ValueError("it lacks the scenario's group or tallies")
    for tally in rec["tallies"].values():
        Tally.from_json(tally)


def compare_jobs(thesis: Sequence[str], seeds: Iterable[int], max_frames: int | None,
                 camera: str = "thesis") -> Iterator[tuple[str, int | None, int | None, str]]:
    """The comparison's jobs, generated as they are needed: the thesis scenarios, then
    one per generated track (never all in memory: ``seeds`` may be a huge range)."""
    for kind in thesis:
        if kind not in ("straight", "curve", "track"):
            raise ValueError(f"unknown thesis scenario {kind!r}; use straight, curve, track")
    for kind in thesis:
        yield kind, None, None, camera
    for seed in seeds:
        yield "random", int(seed), max_frames, camera


class CompareTally:
    """The comparison's tallies per scenario group and detector, job by job."""

    def __init__(self) -> None:
        self.groups: dict[str, dict[str, Tally]] = {}
        self.jobs = 0

    def add(self, group: str, tallies: Mapping[str, Tally]) -> None:
        into = self.groups.setdefault(group, {})
        for label, tally in tallies.items():
            into[label] = into[label] + tally if label in into else tally
        self.jobs += 1

    def result(self, thesis: Sequence[str], seeds: Sequence[int],
               max_frames: int | None) -> dict[str, Any]:
        seed_span = ([seeds.start, seeds.stop] if isinstance(seeds, range)
                     else [int(s) for s in seeds])
        return {
            "thesis_scenarios": list(thesis), "seeds": seed_span,
            "max_frames": max_frames, "epsilon_px": EPSILON_PX,
            "groups": {group: {label: t.summary() for label, t in tallies.items()}
                       for group, tallies in self.groups.items()},
        }


def iter_compare(thesis: Sequence[str], seeds: Iterable[int], *,
                 max_frames: int | None = None, workers: int = 1, camera: str = "thesis"
                 ) -> Iterator[tuple[str, dict[str, Tally]]]:
    """(group, tallies) per job, streamed from ``workers`` processes in job order;
    ``camera`` a profile name or file."""
    yield from stream(_one, compare_jobs(thesis, seeds, max_frames, camera), workers=workers)


def markdown_table(result: Mapping[str, Any]) -> str:
    """The comparison as a Markdown table (one row per scenario group and detector)."""
    head = ("| scenario | detector | frames | hit rate | false positives / frame | FP share "
            "| ego left found | ego right found | ms / frame (median) |")
    lines = [head, "|" + "---|" * 9]

    def pct(v: float | None) -> str:
        return "–" if v is None else f"{100 * v:.0f} %"

    for group, runs in result["groups"].items():
        for label, s in runs.items():
            lines.append(
                f"| {group} | {label} | {s['frames']} | {s['hit_rate']:.3f} "
                f"| {s['false_positives_per_frame']:.2f} | {pct(s['false_positive_share'])} "
                f"| {pct(s['ego_left_found'])} | {pct(s['ego_right_found'])} "
                f"| {s['ms_per_frame_median']:.2f} |")
    return "\n".join(lines) + "\n"


def plot(result: Mapping[str, Any], path: str | os.PathLike[str]) -> None:
    """Grouped bars: hit rate, false positives per frame and ms per frame per detector."""
    from .charts import _pyplot, _save

    plt = _pyplot()
    groups = list(result["groups"])
    labels = list(next(iter(result["groups"].values())))
    metrics = (("hit_rate", "hit rate"), ("false_positives_per_frame", "false positives / frame"),
               ("ms_per_frame_median", "ms / frame (median)"))
    fig, axes = plt.subplots(1, len(metrics), figsize=(15, 4.2))
    width = 0.8 / len(labels)
    x = np.arange(len(groups))
    for ax, (key, title) in zip(axes, metrics, strict=True):
        for k, label in enumerate(labels):
            values = [result["groups"][g][label][key] or 0.0 for g in groups]
            ax.bar(x + (k - (len(labels) - 1) / 2) * width, values, width, label=label)
        ax.set_xticks(x, groups)
        ax.set_title(title)
        ax.grid(axis="y", alpha=0.3)
    axes[0].legend(fontsize=8, loc="lower left")
    fig.suptitle("Hough baseline vs TFALDA (same frames, same ground truth)")
    _save(fig, path)
