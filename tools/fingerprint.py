"""Fingerprints of what must not change in a refactor: renders, detector outputs,
rollouts and a closed-loop PID drive for a fixed set of seeds, as SHA-256 digests.

    python tools/fingerprint.py [--out F.json]      # then diff two runs

Renders: frames of named and generated tracks at several poses, with the default, off and
randomised effects, full frames and ROI windows; ground truth labels. Detector: TFALDA +
LIS (thesis, improved, without LIS) and the Hough baseline on those frames. Rollouts:
200 random-action steps of TfaldaTrack-v0 per observation mode, with domain randomisation
and faults. Drive: the PID on generated track 7 for 300 frames.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from typing import Any

import numpy as np

from tfalda_sim.tracks import generate, load_named

_FIRST_NAMES = {"roi_reset": "lis_reset", "roi_resets": "lis_resets"}
"""Names renamed since the first fingerprints, hashed under the first name so
digests stay comparable across the rename."""


def _roi_reset(obs: Any) -> bool:
    return obs.roi_reset if hasattr(obs, "roi_reset") else obs.reset


def _h(*arrays: Any) -> str:
    d = hashlib.sha256()
    for a in arrays:
        if isinstance(a, np.ndarray):
            d.update(str(a.dtype).encode() + str(a.shape).encode())
            d.update(np.ascontiguousarray(a).tobytes())
        else:
            d.update(json.dumps(a, sort_keys=True, default=str).encode())
    return d.hexdigest()[:16]


def renders() -> dict[str, str]:
    from tfalda_sim.perception import DetectorConfig, HoughConfig, HoughDetector, TfaldaDetector
    from tfalda_sim.rendering import (
        DomainRandomization,
        Effects,
        Renderer,
        build_scene,
        frame_truth,
    )

    out: dict[str, str] = {}
    renderer = Renderer()
    for name in ("oval", "thesis", 7, 10003):
        track = load_named(name) if isinstance(name, str) else generate(name)
        for fx in ("default", "off", "random"):
            rng = np.random.default_rng(5)
            effects = {"default": Effects(), "off": Effects.off(),
                       "random": DomainRandomization().sample(rng)}[fx]
            scene = build_scene(track, effects, rng)
            for s in (0.5, 3.0, 7.7):
                x, y, h = (float(v) for v in track.pose(s, -0.2))
                for dh in (0.0, 0.15):
                    pose = (x, y, h + dh)
                    frame = renderer.render(scene, pose, speed_m_s=2.0, frame_seed=11)
                    key = f"{name}/{fx}/s{s}/h{dh}"
                    out[f"render/{key}"] = _h(frame)
                    wins = [(195, 260, 150, 75), (10, 350, 300, 75), (400, 300, 200, 60)]
                    out[f"windows/{key}"] = _h(*renderer.render_windows(
                        scene, pose, wins, speed_m_s=2.0, frame_seed=11))
                    truth = frame_truth(track, renderer.camera, pose, s_hint_m=s)
                    out[f"truth/{key}"] = _h(truth.labels, truth.left_boundary_px,
                                             truth.right_boundary_px)
                    for label, cfg in (("thesis", DetectorConfig.thesis()),
                                       ("improved", DetectorConfig.improved()),
                                       ("nolis", DetectorConfig.without_lis())):
                        det = TfaldaDetector(cfg)
                        obs = [det.process(frame) for _ in range(3)]
                        out[f"tfalda-{label}/{key}"] = _h(*[o.lanes for o in obs],
                                                          *[o.rois for o in obs],
                                                          [bool(_roi_reset(o)) for o in obs])
                    for label, hcfg in (("seed", HoughConfig()),
                                        ("sim", HoughConfig.simulator())):
                        out[f"hough-{label}/{key}"] = _h(HoughDetector(hcfg).detect(frame)
                                                         .segments)
    return out


def rollouts() -> dict[str, str]:
    import gymnasium as gym

    import tfalda_sim  # noqa: F401
    from tfalda_sim.faults import Blackout, CameraShake, Glare, LateralKick

    out: dict[str, str] = {}
    # At 50 frames/s: a blackout from step 30 for 5 frames, a glare at pixel (500, 380)
    # with a 60 px radius from step 60 for 10, a shake from step 90 for 10, a kick at 120.
    faults = (Blackout(0.6, 0.1), Glare(1.2, 0.2, ahead_m=0.265, left_m=-0.154,
                                        radius_m=0.098, peak_dn=200.0),
              CameraShake(1.8, 0.2, amplitude_rad=0.02), LateralKick(2.4, 0.05))
    for mode in ("lanes", "image", "dict"):
        for dr in (False, True):
            env = gym.make("TfaldaTrack-v0", observation=mode, domain_randomization=dr,
                           track=None if dr else "oval")
            env.action_space.seed(3)
            obs, info = env.reset(seed=42, options={"faults": faults})
            digests = []
            for _ in range(200):
                obs, r, term, trunc, info = env.step(env.action_space.sample())
                o = obs["lanes"] if mode == "dict" else obs
                digests.append(_h(o, [r, term, trunc],
                                  {_FIRST_NAMES.get(k, k): v for k, v in info.items()
                                   if k != "track"}))
                if term or trunc:
                    obs, info = env.reset()
            out[f"rollout/{mode}/dr{dr}"] = _h(digests)
            env.close()
    return out


def drive() -> dict[str, str]:
    from dataclasses import replace

    from tfalda_sim.agents.drive import drive as run_drive
    from tfalda_sim.agents.pid import LanePid
    track = replace(generate(7), obstacles=())
    res = run_drive(LanePid(), track, laps=1, max_steps=300)
    s = res.summary()
    # Means to 12 digits: the drive sums them per step (a running sum, not np.mean).
    s = {_FIRST_NAMES.get(k, k): v for k, v in s.items()}
    return {"drive/pid/7": _h([float(f"{s[k]:.12g}") for k in (
        "laps_completed", "departures", "lis_resets", "mean_abs_cross_track_m",
        "max_abs_cross_track_m", "mean_hit_rate", "distance_m", "steps")])}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", help="write the digests as JSON here (default: stdout)")
    args = parser.parse_args(argv)
    digests = {**renders(), **rollouts(), **drive()}
    text = json.dumps(digests, indent=1, sort_keys=True)
    if args.out:
        with open(args.out, "w", encoding="utf-8") as fh:
            fh.write(text + "\n")
    else:
        print(text)
    print(f"{len(digests)} digests, overall {_h(sorted(digests.items()))}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
