"""The thesis' three scenarios run with the two untried explanations of its
unreproduced curve behaviour — listing A.2's one-frame-late ROI placement
(``LisConfig.roi_from_current_lanes=False``) and a camera whose upper-left ROI also sees
the opposite lane's outer line — each alone and both, with and without the LIS.

    python tools/thesis_variants.py [--json]

Per scenario, variant and run: mean and minimum confidence, frames below 0.75, and the
frames in which the upper-left lane lies on the opposite lane's outer line (≥ 50 % of its
pixels within 5 px of that line's label) — the thesis' failure of the run without the LIS
(sections 4.2.2 and 4.2.3: from frame 133 of the curve to the end). The table goes into
docs/evaluation.md.
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import replace

import numpy as np

from tfalda_sim.camera import FisheyeCamera
from tfalda_sim.evaluation.metrics import lane_hit_rates, truth_distance
from tfalda_sim.evaluation.runner import run_scenario
from tfalda_sim.evaluation.scenarios import ScenarioKind, thesis_scenario
from tfalda_sim.perception import DetectorConfig
from tfalda_sim.rendering import Renderer
from tfalda_sim.tracks import Marking

SEEING_PITCH_RAD: float = math.radians(1.5)
"""Pitch of the camera whose upper-left ROI sees the opposite lane's outer line [rad]."""
SEEING_HEIGHT_M: float = 0.30
"""Its height [m]. The thesis camera (5.5°, 0.20 m) tilted less and mounted higher: the
upper ROI row looks nearer the vanishing point and the road's lines lie closer together,
so the outer line runs through the upper-left ROI as listing A.6 places it (in all 81
frames of the curve). Searched over pitch 1–5.5° and height 0.20–0.30 m: no camera that
meets table 2.3's widths puts the outer line in that ROI; this one does, and its lane is
135–143 px wide at rows 334–340 where table 2.3 asks 200–272 (docs/evaluation.md)."""

SEES: float = 0.5
"""The upper-left ROI sees the outer line in a frame when the line's label crosses at
least this share of the ROI's rows [1]."""

ON_OUTER: float = 0.5
"""The upper-left lane is on the outer line when this share of its pixels is [1]."""


def variants() -> dict[str, tuple[FisheyeCamera, bool]]:
    """name → (camera, ROIs from this frame's lanes)."""
    thesis = FisheyeCamera.default()
    seeing = thesis.with_mount(pitch_rad=SEEING_PITCH_RAD, height_m=SEEING_HEIGHT_M)
    return {"as built": (thesis, True), "late ROIs (A.2)": (thesis, False),
            "UL sees outer line": (seeing, True), "both": (seeing, False)}


def run(kind: ScenarioKind, camera: FisheyeCamera, current: bool) -> dict[str, dict]:
    configs = {}
    for label, cfg in (("with LIS", DetectorConfig.thesis()),
                       ("without LIS", DetectorConfig.without_lis())):
        configs[label] = replace(cfg, lis=replace(cfg.lis, roi_from_current_lanes=current))
    outer: dict[str, list[int]] = {k: [] for k in configs}
    seen: dict[str, int] = {k: 0 for k in configs}

    def on_frame(seq, frame, truth, observations) -> None:
        dist = truth_distance(truth.labels, (Marking.LEFT_LINE,))
        for label, obs in observations.items():
            if lane_hit_rates(obs.lanes[:1], dist)[0] >= ON_OUTER:
                outer[label].append(int(seq))
            x, y, w, h = (int(v) for v in obs.rois[0])
            rows = (truth.labels[y:y + h, x:x + w] == int(Marking.LEFT_LINE)).any(axis=1)
            seen[label] += int(rows.mean() >= SEES)

    # The thesis' literal pixel layout on both cameras: the question is what the thesis'
    # numbers do on a camera like the thesis' own, not a geometry derived for it.
    runs = run_scenario(thesis_scenario(kind), configs, renderer=Renderer(camera),
                        on_frame=on_frame)
    out = {}
    for label, r in runs.items():
        conf = r.confidence
        out[label] = {"mean": float(conf.mean()), "min": float(conf.min()),
                      "below_0_75": int((conf < 0.75).sum()),
                      "upper_left_on_outer_line": len(outer[label]),
                      "first_on_outer_line": outer[label][0] if outer[label] else None,
                      "upper_left_roi_sees_outer_line": seen[label],
                      "roi_resets": int(r.roi_reset.sum())}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    rows = []
    for kind in (ScenarioKind.STRAIGHT, ScenarioKind.CURVE, ScenarioKind.TRACK):
        for name, (camera, current) in variants().items():
            for label, fig in run(kind, camera, current).items():
                rows.append({"scenario": kind.value, "variant": name, "run": label, **fig})
    if args.json:
        print(json.dumps(rows, indent=1))
        return
    print("| scenario | variant | run | mean | min | frames < 0.75 | UL ROI sees the outer "
          "line | UL lane on it (first) | resets |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        first = "—" if r["first_on_outer_line"] is None else str(r["first_on_outer_line"])
        print(f"| {r['scenario']} | {r['variant']} | {r['run']} | {r['mean']:.3f} | "
              f"{r['min']:.3f} | {r['below_0_75']} | {r['upper_left_roi_sees_outer_line']} | "
              f"{r['upper_left_on_outer_line']} "
              f"({first}) | {r['roi_resets']} |")


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
