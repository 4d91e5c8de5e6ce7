"""BENCHMARKS.md from the benchmark scripts' ``--json`` results in ``benchmarks/results/``.

    python benchmarks/report.py                  # write BENCHMARKS.md from the results
    python benchmarks/report.py --check          # exit 1, with a diff, if it differs
    python benchmarks/report.py --run [NAME …]   # run the benchmarks (all, or the NAMEs,
                                                 # e.g. bench_env), store their JSON, write

The page holds only what the committed JSON says (the figures, the host, the date, the
commit measured, the command that reproduces them), so it cannot drift from the scripts:
``--check`` (a test runs it) fails when the page and the JSON disagree, and a test runs
the scripts with tiny sizes to check that every key the page reads is one they print.
"""

from __future__ import annotations

import argparse
import difflib
import json
import math
import subprocess
import sys
import textwrap
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
RESULTS = HERE / "results"
PAGE = REPO / "BENCHMARKS.md"


# --- reading the JSON, with a record of every key read ---------------------------------

class Tracked(Mapping):
    """A JSON object that records the path of every key read from it (into ``reads``), so
    that a test can check the page reads only keys the script prints. Lists and other
    values are leaves."""

    def __init__(self, data: dict[str, Any], reads: set[tuple[str, ...]],
                 path: tuple[str, ...] = ()) -> None:
        self._data, self._reads, self._path = data, reads, path

    def __getitem__(self, key: str) -> Any:
        value = self._data[key]
        path = (*self._path, key)
        self._reads.add(path)
        return Tracked(value, self._reads, path) if isinstance(value, dict) else value

    def __iter__(self) -> Iterator[str]:
        return iter(self._data)

    def __len__(self) -> int:
        return len(self._data)


def key_paths(data: Any, path: tuple[str, ...] = ()) -> set[tuple[str, ...]]:
    """Every key path of a JSON object (lists and other values are leaves)."""
    if not isinstance(data, dict):
        return set()
    out = set()
    for key, value in data.items():
        out.add((*path, key))
        out |= key_paths(value, (*path, key))
    return out


# --- formatting ------------------------------------------------------------------------

def num(value: float | None, digits: int = 2) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "–"
    return f"{value:,.{digits}f}".replace(",", " ")


def ratio(value: float | None, digits: int = 2) -> str:
    return "–" if value is None else f"{num(value, digits)}×"


def table(header: list[str], rows: list[list[str]], align: str = "") -> str:
    """A Markdown table; ``align`` one letter a column (l, r), default: the first left,
    the others right."""
    align = align or "l" + "r" * (len(header) - 1)
    rule = ["---:" if a == "r" else "---" for a in align]
    return "\n".join("| " + " | ".join(cells) + " |" for cells in [header, rule, *rows])


def host_line(result: Mapping) -> str:
    m = result["machine"]
    commit = m["commit"] or "unknown"
    note = " (with uncommitted changes)" if commit.endswith("+") else ""
    return (f"Host: {m['cpu']} ({m['simd']}), {m['cores']} cores, Python {m['python']}; "
            f"measured {m['date']} on commit `{commit.rstrip('+')}`{note}.")


# --- the benchmarks --------------------------------------------------------------------

@dataclass(frozen=True)
class Benchmark:
    name: str  # the script's name without .py, and its result file's
    title: str
    what: str  # what it measures, how, and its same-run reference
    run_args: tuple[str, ...]  # the arguments ``--run`` (``make bench``) gives it
    command: Callable[[Mapping], str]  # its arguments, as the JSON says it ran
    body: Callable[[Mapping], str]  # the tables


def tracks_body(r: Mapping) -> str:
    g, v, ra = r["generate"], r["validate"], r["rasterize"]
    rows = [["generate (incl. its checks and redraws)", num(g["median_ms"]), num(g["p95_ms"]),
             num(g["max_ms"]), f"{g['seeds']} seeds, {len(g['invalid'])} invalid, median "
             f"length {num(g['median_length_m'], 1)} m"],
            ["validate", num(v["median_ms"]), num(v["p95_ms"]), num(v["max_ms"]), ""],
            [f"rasterise at {num(ra['resolution_mm'], 0)} mm/px", num(ra["median_ms"]),
             num(ra["p95_ms"]), num(ra["max_ms"]),
             f"{ra['seeds']} tracks, median {num(ra['median_megapixels'], 1)} MPx"]]
    out = table(["stage [ms]", "median", "p95", "max", "note"], rows, "lrrrl")
    loc = [[name, str(x["segments"]), num(x["length_m"], 1), num(x["locate_us"]),
            num(x["locate_many_us_per_point"])] for name, x in r["locate"].items()]
    return out + "\n\n" + table(["`Track.locate`", "segments", "length [m]",
                                 "µs a call", "µs a point, batched"], loc)


def render_body(r: Mapping) -> str:
    rows = [[name, num(e["full_frame_median_ms"], 3), num(e["full_frame_p95_ms"], 3),
             num(e["rois_median_ms"], 3), num(e["moving_rois_median_ms"], 3),
             ratio(e["roi_speedup"], 1), str(e["frames"])]
            for name, e in r["effects"].items()]
    return table(["effects", "full frame median [ms]", "full frame p95 [ms]",
                  "4 ROIs median [ms]", "moving ROIs median [ms]",
                  "full frame / 4 ROIs", "frames"], rows)


def perception_body(r: Mapping) -> str:
    presets = r["presets"]
    hough = presets["Hough (simulator)"]["median_ms"]
    rows = [[name, num(p["median_ms"], 3), num(p["p95_ms"], 3), num(p["frames_per_s"], 0),
             num(p["median_ms"] / hough)] for name, p in presets.items()]
    return table(["preset", "median [ms]", "p95 [ms]", "frames/s", "× Hough (simulator)"],
                 rows)


REPLAY_MODES: tuple[tuple[str, str], ...] = (("read", "read alone"),
                                             ("tfalda", "TFALDA + LIS replay"),
                                             ("hough", "Hough replay"))
"""bench_replay's turns of a source kind (its JSON's keys) and their columns' names."""


def replay_body(r: Mapping) -> str:
    kinds = r["kinds"]
    header = ["source kind", "`open_source` kind", "MB a frame", "opening [ms]"]
    for _, label in REPLAY_MODES:
        header += [f"{label} [frames/s]", "× MP4"]
    rows = []
    for name, k in kinds.items():
        row = [name, f"`{k['source_kind']}`", num(k["mb_per_frame"], 3), num(k["open_ms"], 1)]
        for mode, _ in REPLAY_MODES:
            row += [num(k[mode]["frames_per_s"], 0), ratio(k[mode]["ratio_to_mp4"])]
        rows.append(row)
    rec = r["recording"]
    without, with_mcap = rec["without"], rec["with_mcap"]
    drives = table([f"drive, {rec['track']}, PID, {rec['drive_steps']} steps", "ms a step",
                    "steps/s", "cost × without"],
                   [["without a recording", num(without["ms_per_step"], 3),
                     num(without["steps_per_s"], 0), ratio(1.0)],
                    ["`--mcap FILE`", num(with_mcap["ms_per_step"], 3),
                     num(with_mcap["steps_per_s"], 0), ratio(rec["cost_ratio"])]])
    reference = r["reference"]
    pairs = {name: f"{num(k['tfalda']['detections_per_frame'])} / "
                   f"{num(k['hough']['detections_per_frame'])}" for name, k in kinds.items()}
    others = {pair for name, pair in pairs.items() if name != reference}
    if len(others) == 1:
        detections = (f"{others.pop()} from every other kind (their frames are the rendered "
                      f"ones exactly), {pairs[reference]} from the MP4 (H.264 is lossy)")
    else:
        detections = "; ".join(f"{name}: {pair}" for name, pair in pairs.items())
    return "\n".join([
        table(header, rows, "ll" + "r" * (len(header) - 2)),
        "",
        wrap(f"{r['frames']} frames of {r['frame_size_px'][0]}×{r['frame_size_px'][1]} px "
             f"a recording; medians of {r['rounds']} rounds, each ratio the median of its "
             "rounds' ratios. Detections a frame (TFALDA's lanes / Hough's segments): "
             f"{detections}."),
        "",
        drives,
        "",
        wrap(f"The drive's MCAP: {num(rec['mb_per_frame'], 3)} MB a frame "
             f"({rec['frames_recorded']} frames a drive of {rec['drive_steps']} steps: the "
             "start's and one a step)."),
    ])


def reset_body(r: Mapping) -> str:
    resets = r["reset"]
    eager = resets["new track, eager scene"]["median_ms"]
    rows = [[name, num(t["median_ms"]), num(t["p95_ms"]), num(t["max_ms"]),
             num(t["median_ms"] / eager)] for name, t in resets.items()]
    return (table(["`env.reset()`, lanes mode", "median [ms]", "p95 [ms]", "max [ms]",
                   "median / eager's"], rows)
            + f"\n\nEager / lazy (medians): **{ratio(r['eager_over_lazy'], 1)}**.")


def candidates_body(r: Mapping) -> str:
    rows = [[f"`{key}`: {k['label']}", k["image_type"], num(k["us_per_roi"], 1),
             num(k["useful_additions_per_ns"]), ratio(k["time_over_current"])]
            for key, k in r["kernels"].items()]
    sizes = r["roi_sizes_resampled"]
    p = r["per_roi_path"]
    return "\n".join([
        table(["kernel", "image", "µs a ROI", "useful additions a ns",
               "time / current's (same image type)"], rows, "llrrr"),
        "",
        f"{r['rois']} ROIs (resampled sizes {sizes[0][0]}×{sizes[0][1]} to "
        f"{sizes[-1][0]}×{sizes[-1][1]} px), best of {r['repeat']} passes; results "
        f"identical: {'yes' if r['identical_results'] else '**no**'}. Speed-up over the "
        f"previous kernel **{ratio(r['speed_up_over_previous'])}** (uint16 "
        f"{ratio(r['speed_up_over_previous_uint16'])}), over the first "
        f"{ratio(r['speed_up_over_first'])}. Additions a ROI: "
        f"{num(r['useful_additions_per_roi'], 0)} useful, "
        f"{num(r['executed_additions_per_roi'], 0)} executed (rows padded to whole SIMD "
        "blocks).",
        "",
        f"The detector's whole per-ROI path (resize, Sobel, search, the lane's choice): "
        f"{num(p['current_us_per_roi'], 1)} µs a ROI against the previous path's "
        f"{num(p['previous_us_per_roi'], 1)} (`cv2.resize` + `find_lane`): "
        f"{ratio(p['speed_up_over_previous'])}; lanes identical: "
        f"{'yes' if p['identical_lanes'] else '**no**'}.",
    ])


REFERENCE = "CarRacing-v3 (reference)"
GEN = "lanes, new generated track per reset"
FIXED = "lanes, fixed track (oval)"
DYNAMIC_COST = "step cost: dynamic car + real-car timing / kinematic car (lanes, fixed)"
VEC = "make_vec 2 envs / 1 env"
CEILING = "2 processes at once / 1 (the machine's ceiling)"
OWN_PACE = "2 processes, each at its own pace / 1"
GEN_FIXED = "generated / fixed track (lanes)"
GEN_FIXED_OFF = "generated / fixed track (lanes), resets off the clock"


def env_body(r: Mapping) -> str:
    envs = r["envs"]
    rows = []
    for name, e in envs.items():
        if not isinstance(e, Mapping):  # the reference was not available: its reason
            rows.append([name, e, "", "", "", ""])
            continue
        reset = e.get("ms_per_reset") if "ms_per_reset" in e else None
        rows.append([name, num(e["steps_per_s"], 0), num(e["ms_per_step"], 3),
                     str(e["episodes"]), ratio(e.get("ratio_to_car_racing")),
                     num(reset, 2) if "ms_per_reset" in e else ""])
    ratios = [[name, num(value)] for name, value in r["ratios"].items()]
    out = [table(["configuration", "steps/s", "ms a step", "episodes", "× CarRacing-v3",
                  "mean reset [ms]"], rows),
           "",
           table(["ratio (same run)", "value"], ratios)]
    ceiling = r["ratios"].get(CEILING)
    if ceiling is not None and ceiling < BUSY_CEILING:
        out += ["", wrap(f"**A busy host**: two single-env processes at once made only "
                f"{num(ceiling)}× one process's steps/s in this run, so other work (on the "
                "VM or its host) shared the cores; the vector figures of this run say "
                "little about the code.")]
    return "\n".join(out)


BUSY_CEILING = 1.5
"""Below this, two single-env processes at once against one (the machine's ceiling)
say the host's cores were busy with other work during the run."""


BENCHMARKS: tuple[Benchmark, ...] = (
    Benchmark(
        "bench_env", "Env steps: TfaldaTrack-v0 against CarRacing-v3",
        "Random-action env steps per second, resets included (random steering leaves the "
        "road every ≈ 50 steps), each of our envs timed after a warm-up (the steady state "
        "of a training run). Gymnasium's CarRacing-v3 is the reference every figure is "
        "divided by: it steps in the same rounds as the single envs (one core, OpenCV on "
        "one thread), in turns of 300 steps, so the host's drift stays out of the ratios. "
        "\"lanes\" renders only the ROIs (the training mode), \"image\" the full frame; "
        "both on a fixed track (the oval) and on a new generated track every reset, whose "
        "resets are also clocked apart. The vector configurations get every core and step "
        "the same two streams (the same seeds, tracks and actions): `make_vec` with 1 and "
        "2 envs, Gymnasium's `AsyncVectorEnv`, and the machine's ceiling, the same streams "
        "in single-env processes, one alone and two at once (pinned one a core; \"own "
        "pace\": each process's rate over its own stepping time, no synchronisation).",
        ("--steps", "3000"),
        lambda r: f"--steps {r['steps']} --warmup-steps {r['warmup_steps']}",
        env_body),
    Benchmark(
        "bench_reset", "Resets",
        "`env.reset()` in \"lanes\" mode, first observation included, on one core: onto a "
        "new generated track with the scene painted lazily (the env's default), eagerly "
        "(the whole marking map and mip atlas at reset: the previous implementation, the "
        "same-run reference) and in \"image\" mode, and on a fixed track. The kinds take "
        "turns, so a busy host slows them alike.",
        ("--resets", "200"),
        lambda r: f"--resets {next(iter(r['reset'].values()))['resets']}",
        reset_body),
    Benchmark(
        "bench_render", "Renderer",
        "Frames along the right lane's ideal line of two named and three generated tracks "
        "(obstacles included), on one core: full frames (the env's \"image\" mode), the "
        "four thesis ROIs only (\"lanes\" mode), and the ROIs moved every frame as the LIS "
        "does (nothing cached). The full frame is the same-run reference of the ROIs.",
        ("--frames", "1500"),
        lambda r: f"--frames {next(iter(r['effects'].values()))['frames']}",
        render_body),
    Benchmark(
        "bench_perception", "Lane detection: TFALDA + LIS and the Hough baseline",
        "Per-frame time of the detector on rendered frames (rendered first, not timed) of "
        "three named and two generated tracks, in driving order, on one core. Presets: "
        "the thesis (all on), without the LIS, the improved one with two and three ROI "
        "rows; the Hough baseline with the seed's numbers (they find no rendered marking: "
        "an almost empty pipeline) and with the simulator preset, the same-run reference.",
        ("--frames", "2000"),
        lambda r: f"--frames {next(iter(r['presets'].values()))['frames']}",
        perception_body),
    Benchmark(
        "bench_replay", "Replay: recordings as frame sources, and recording a drive",
        "The camera frames of a PID drive on the oval (rendered once, noise included), "
        "written untimed as every kind of recording `tfalda-sim replay` reads: an MP4 "
        "(H.264, as `drive --camera-video` writes it: the previous replay's only input, the "
        "same-run reference), a PNG folder, ROS 1 and ROS 2 (sqlite3) bags of "
        "`sensor_msgs/Image` mono8, a ROS 2 bag in MCAP storage of `CompressedImage` PNG, a "
        "plain MCAP file of Image mono8. In rounds, on one core, each kind is read alone "
        "(`open_source(…).frames()` + `to_grey`, its opening clocked apart) and replayed "
        "through each detector (`replay`'s own `frames_per_s`: first frame to last). Then "
        "the cost of recording: drives of the oval, `drive(…, max_steps=…)` without and with "
        "`mcap=` in turns, the recorder's closing inside the drive's clock.",
        ("--frames", "300", "--rounds", "5", "--drive-steps", "300"),
        lambda r: (f"--frames {r['frames']} --rounds {r['rounds']} "
                   f"--drive-steps {r['recording']['drive_steps']}"),
        replay_body),
    Benchmark(
        "bench_candidates", "TFALDA's candidate search kernel",
        "The detector's candidate search on the pre-processed ROIs of rendered frames, one "
        "core: the current kernel (blocks of starts summed in vector registers) against "
        "the previous one (row additions through memory, padded to SIMD blocks), the "
        "same-run reference, and the first one (unpadded rows), on int32 and uint16 "
        "images; all must give the same candidates. Then the detector's whole per-ROI "
        "path, current against previous.",
        ("--rois", "400", "--repeat", "20"),
        lambda r: f"--rois {r['rois']} --repeat {r['repeat']}",
        candidates_body),
    Benchmark(
        "bench_tracks", "Track layer",
        "Track generation (with its rule checks and redraws), validation, rasterisation "
        "of markings and labels at 4 mm/px, and the reverse query `Track.locate`, in one "
        "process. No same-run reference: absolute times, comparable only on the same CPU.",
        ("--seeds", "1000", "--raster-seeds", "50"),
        lambda r: f"--seeds {r['generate']['seeds']} --raster-seeds {r['rasterize']['seeds']}",
        tracks_body),
)

AB_SCRIPTS: tuple[tuple[str, str, str], ...] = (
    ("bench_ab.py", "--other ../old/.venv/bin/python --turns",
     "this checkout's lanes steps/s (fixed and generated tracks) and reset median against "
     "another checkout's, in turns on one core (or side by side on two)"),
    ("bench_vec_ab.py", "--other ../old/.venv/bin/python",
     "`make_vec` with 2 envs (both autoreset modes) and 1 env against another checkout's, "
     "in turns"),
    ("bench_kernel_ab.py", "--rev REV --module tfalda_sim.rendering.renderer "
     "--kernels _combine",
     "one module's numba kernels inside env steps, this checkout's against a git "
     "revision's, swapped between turns in one process"),
    ("bench_paint.py", "--rev REV",
     "the lazy marking paint on the tiles an env really paints, this checkout's kernel "
     "against a revision's (the paint must stay bit-identical)"),
)
"""A/B scripts: (script, its typical arguments, what it compares); they measure a
change against the code before it, so they have no standing figures here."""


# --- targets ---------------------------------------------------------------------------

@dataclass(frozen=True)
class Target:
    text: str
    source: str  # the benchmark whose JSON holds the figure ("" for a quoted one)
    figure: Callable[[Mapping], tuple[str, bool]] | None  # (the figures, met?)
    unmet: str | Callable[[Mapping], str] = ""  # why it is not met, when it is not
    quoted: tuple[str, bool] = ("", False)  # a figure no benchmark JSON holds



TARGETS: tuple[Target, ...] = (
    Target("lanes env step ≥ 14× CarRacing-v3's (fixed track)", "bench_env",
           lambda r: (f"{ratio(r['envs'][FIXED]['ratio_to_car_racing'])} "
                      f"({ratio(r['envs'][GEN]['ratio_to_car_racing'])} on generated "
                      "tracks)", r["envs"][FIXED]["ratio_to_car_racing"] >= 14.0),
           "the ratio depends on the host's CPU, which does not speed up CarRacing-v3 "
           "(Box2D, pygame) and our step (numba kernels, OpenCV) alike: AMD EPYC hosts "
           "read 15.5–16.6×, Xeon hosts 11.5–14.7×."),
    Target("a reset onto a new generated track ≤ 5 ms", "bench_env, bench_reset",
           None),  # two sources: filled in by ``targets``
    Target("steps on generated tracks ≥ 90 % of the fixed track's rate", "bench_env",
           lambda r: (f"{num(r['ratios'][GEN_FIXED])} ({num(r['ratios'][GEN_FIXED_OFF])} "
                      "with the resets off the clock)", r["ratios"][GEN_FIXED] >= 0.90),
           "a new track costs its reset and the ground each episode comes to see must be "
           "painted; generated tracks also hold more to detect than the oval, so even "
           "free resets (the second figure) leave no margin."),
    Target("`make_vec` with 2 envs ≥ 1.7× one env's steps/s", "bench_env",
           lambda r: (f"{num(r['ratios'][VEC])} (the machine's ceiling in the same run: "
                      f"{num(r['ratios'][CEILING])}, own pace {num(r['ratios'][OWN_PACE])})",
                      r["ratios"][VEC] >= 1.7),
           lambda r: "the two envs step in lockstep, one a core, so each vector step waits "
           "for the slower of two env steps and for this process, which also merges the "
           "infos. Two independent single-env processes in the same run (the machine's "
           f"ceiling) reach {num(r['ratios'][CEILING])}× one, "
           f"{num(r['ratios'][OWN_PACE])}× at their own pace: on "
           f"{r['machine']['cores']} vCPUs the target needs nearly all the host gives, and "
           "a quiet host's runs read 1.65–1.74, on both sides of it."),
    Target("a lanes step with the dynamic car and real-car timing costs ≤ 10 % more than "
           "with the kinematic car", "bench_env",
           lambda r: (f"{num(r['ratios'][DYNAMIC_COST])}× the kinematic car's step",
                      r["ratios"][DYNAMIC_COST] <= 1.10),
           "the dynamic car integrates its tyres in RK4 substeps of 1 ms (numba) at each "
           "physics step, and the timing keeps frames in flight."),
    Target("PPO, 120 k steps (`tfalda-sim train --timesteps 120000 --n-envs 2 --seed 0`) "
           "≤ 3 min", "", None,
           quoted=("40 s (twice, 2026-12-05, AMD EPYC, 2 vCPUs; docs/agents.md): not a "
                   "benchmark script's figure", True)),
    Target("track generation ≤ 50 ms median", "bench_tracks",
           lambda r: (f"{num(r['generate']['median_ms'])} ms",
                      r["generate"]["median_ms"] <= 50.0)),
    Target("rasterisation at 4 mm/px ≤ 200 ms median", "bench_tracks",
           lambda r: (f"{num(r['rasterize']['median_ms'], 1)} ms",
                      r["rasterize"]["median_ms"] <= 200.0)),
    Target("full frame ≤ 1.0 ms median (default effects)", "bench_render",
           lambda r: (f"{num(r['effects']['default']['full_frame_median_ms'], 3)} ms",
                      r["effects"]["default"]["full_frame_median_ms"] <= 1.0)),
    Target("the four ROIs ≥ 5× faster than the full frame", "bench_render",
           lambda r: (ratio(r["effects"]["default"]["roi_speedup"], 1),
                      r["effects"]["default"]["roi_speedup"] >= 5.0)),
    Target("TFALDA + LIS, thesis preset ≤ 0.5 ms median a frame", "bench_perception",
           lambda r: (f"{num(r['presets']['thesis']['median_ms'], 3)} ms",
                      r["presets"]["thesis"]["median_ms"] <= 0.5)),
)


def targets(results: Mapping[str, Mapping]) -> str:
    rows, notes = [], []
    for t in TARGETS:
        if t.source == "bench_env, bench_reset":
            env, reset = results["bench_env"], results["bench_reset"]
            mean = env["envs"][GEN]["ms_per_reset"]
            median = reset["reset"]["new track, lazy scene"]["median_ms"]
            figure = (f"{num(mean)} ms mean in steps (bench_env); {num(median)} ms median "
                      "(bench_reset)", max(mean or 0.0, median) <= 5.0)
        elif t.figure is None:
            figure = t.quoted
        else:
            figure = t.figure(results[t.source])
        met = "yes" if figure[1] else "**no**"
        rows.append([t.text, figure[0], met, t.source or "quoted"])
        if not figure[1] and t.unmet:
            why = t.unmet if isinstance(t.unmet, str) else t.unmet(results[t.source])
            notes.append(wrap(f"- {t.text}: {why}"))
    env = results["bench_env"]["machine"]
    out = table(["target", "current", "met?", "source"], rows, "llll")
    if notes:
        out += "\n\n" + wrap(f"Why the unmet ones are not met (on {env['cores']} cores of "
                             f"{env['cpu']}):") + "\n\n" + "\n".join(notes)
    return out


# --- the page --------------------------------------------------------------------------

INTRO = """\
<!-- Generated by benchmarks/report.py from benchmarks/results/*.json: do not edit.
     Rerun with `make bench`, or one benchmark with
     `python benchmarks/report.py --run bench_env`. -->

# Benchmarks

Current figures only, each from its benchmark script's `--json` output, stored in
`benchmarks/results/` (history: `git log -p benchmarks/results/`). `make bench` reruns
every benchmark and writes this page; `python benchmarks/report.py --run NAME` reruns
one; `python benchmarks/report.py --check` says whether the page matches the results.
The project's targets, and whether the current figures meet them: [Targets](#targets), at
the end.

How the figures are measured:

- Per core: a benchmark pins itself to one CPU with OpenCV on one thread (the vector envs
  and the machine's ceiling excepted: they get every core). Numba kernels are compiled
  and the envs warmed up before anything is timed.
- This VM's speed drifts by up to 2× within a day, and the VM has been moved between
  hosts of different CPUs. So every figure comes with the host's CPU and core count, the
  date and the commit measured, and where the benchmark has one, as a ratio to a
  reference measured in the same run, in turns with it: CarRacing-v3 for env steps,
  the previous implementation for a kernel or a reset. The ratios are what compare
  across runs and hosts; absolute figures compare only on the same CPU and hour.
"""


def load_results(reads: dict[str, set[tuple[str, ...]]] | None = None
                 ) -> dict[str, Mapping]:
    """Every benchmark's committed result, each a ``Tracked`` recording into
    ``reads[name]``."""
    out = {}
    for b in BENCHMARKS:
        path = RESULTS / f"{b.name}.json"
        data = json.loads(path.read_text(encoding="utf-8"))
        out[b.name] = Tracked(data, (reads if reads is not None else {}).setdefault(
            b.name, set()))
    return out


def wrap(text: str) -> str:
    """A paragraph (or a bullet, ``- …``) wrapped at ``WIDTH``; code spans stay whole."""
    indent = "  " if text.startswith("- ") else ""
    return textwrap.fill(text, WIDTH, subsequent_indent=indent, break_long_words=False,
                         break_on_hyphens=False)


WIDTH = 90
"""The page's prose is wrapped at this width (tables are not)."""


def render(results: Mapping[str, Mapping]) -> str:
    parts = [INTRO]
    for b in BENCHMARKS:
        r = results[b.name]
        parts += [f"## {b.title} (`benchmarks/{b.name}.py`)\n", wrap(b.what), "",
                  f"`python benchmarks/{b.name}.py {b.command(r)} --json`", "",
                  wrap(host_line(r)), "", b.body(r), ""]
    parts += ["## A/B scripts\n",
              wrap("These compare this checkout with other code in the same minutes (a "
                   "speed-up is only ever measured so); they have no standing figures: "
                   "quote theirs with the change they measure."), ""]
    parts += [wrap(f"- `python benchmarks/{script} {args}`: {what}.") for script, args, what
              in AB_SCRIPTS]
    parts += ["", "## Targets\n", targets(results)]
    return "\n".join(parts).rstrip("\n") + "\n"


def run_benchmarks(names: list[str]) -> int:
    """Run the named benchmarks (all if none) with ``--json`` into ``RESULTS``; a failed
    one keeps its previous result. The number of failures."""
    known = {b.name: b for b in BENCHMARKS}
    unknown = [n for n in names if n.removesuffix(".py") not in known]
    if unknown:
        raise SystemExit(f"report.py: unknown benchmark {', '.join(unknown)}; give one of "
                         f"{', '.join(known)}")
    failures = 0
    RESULTS.mkdir(exist_ok=True)
    for b in [known[n.removesuffix(".py")] for n in names] or list(BENCHMARKS):
        command = [sys.executable, str(HERE / f"{b.name}.py"), *b.run_args, "--json"]
        print(f"running {' '.join(command[1:])}", file=sys.stderr, flush=True)
        done = subprocess.run(command, stdout=subprocess.PIPE, text=True, check=False)
        try:
            result = json.loads(done.stdout)
        except json.JSONDecodeError:
            print(f"report.py: {b.name} failed (exit {done.returncode}); its previous "
                  "result is kept", file=sys.stderr)
            failures += 1
            continue
        if done.returncode != 0:
            print(f"report.py: {b.name} exited {done.returncode} (its JSON is kept)",
                  file=sys.stderr)
            failures += 1
        (RESULTS / f"{b.name}.json").write_text(
            json.dumps(result, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    return failures


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true",
                        help="write nothing; exit 1 with a diff if BENCHMARKS.md differs")
    parser.add_argument("--run", nargs="*", metavar="NAME",
                        help="run these benchmarks (default: all) first")
    args = parser.parse_args(argv)
    if args.check and args.run is not None:
        parser.error("--check and --run contradict each other: give one")
    failures = run_benchmarks(args.run) if args.run is not None else 0
    page = render(load_results())
    if args.check:
        current = PAGE.read_text(encoding="utf-8") if PAGE.exists() else ""
        if current == page:
            return 0
        sys.stdout.writelines(difflib.unified_diff(
            current.splitlines(keepends=True), page.splitlines(keepends=True),
            "BENCHMARKS.md", "BENCHMARKS.md as generated"))
        print("BENCHMARKS.md differs from what benchmarks/report.py generates from "
              "benchmarks/results/: run `python benchmarks/report.py`", file=sys.stderr)
        return 1
    PAGE.write_text(page, encoding="utf-8")
    print(f"wrote {PAGE.name} ({len(page.encode())} bytes)", file=sys.stderr)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
