"""The renderer's command: ``render`` (one camera frame of a track, and its truth)."""

from __future__ import annotations

import argparse
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from ..camera.command import add_camera_option, camera_input, resolve_camera_arg
from ..cli_common import (
    CliError,
    add_force_option,
    add_json_option,
    check_outputs,
    finite_float_arg,
    json_text,
    seed_arg,
)
from ..outputs import Outputs
from ..tracks.command import TRACK_ARG_HELP, resolve_track_arg, track_arg_label, track_file_arg


def register(sub: Any) -> None:
    """Add ``render`` to the ``tfalda-sim`` subparsers."""
    ren = sub.add_parser("render", help="render one camera frame of a track")
    ren.add_argument("--track", required=True, help=TRACK_ARG_HELP)
    ren.add_argument("--s", type=finite_float_arg, required=True,
                     help="arc length of the car [m]: 0 to the track's length (a closed track "
                          "wraps: -length to length)")
    ren.add_argument("--lateral", type=finite_float_arg, default=-0.2,
                     help="lateral offset from the centre line [m], left > 0, on the road "
                          "(|lateral| ≤ half the road's width; default: the middle of the "
                          "right lane)")
    ren.add_argument("--heading", type=finite_float_arg, default=0.0,
                     help="heading relative to the road [rad], left > 0, within ±π")
    ren.add_argument("--out", type=Path, required=True,
                     help="frame PNG (grayscale, the camera's size: 752×480 for thesis)")
    ren.add_argument("--truth", type=Path, help="ground-truth PNG (labels in colour, ego lane "
                                                "boundaries in green)")
    ren.add_argument("--effects", choices=("off", "default", "random"), default="default",
                     help="photometric effects (random: drawn with --seed)")
    ren.add_argument("--seed", type=seed_arg, default=0,
                     help="seed of the random effects, the scene layout and the sensor noise")
    add_camera_option(ren)
    add_force_option(ren)
    add_json_option(ren)
    ren.set_defaults(func=cmd_render)



def _write_png(path: Path, image: np.ndarray) -> None:
    ok, buf = cv2.imencode(".png", image)
    if not ok:
        raise CliError(f"could not encode {path}")
    path.write_bytes(buf.tobytes())


def cmd_render(args: argparse.Namespace) -> int:
    from tfalda_sim.rendering import (
        DomainRandomization,
        Effects,
        Renderer,
        build_scene,
        frame_truth,
    )

    check_outputs({"out": args.out, "truth": args.truth}, {"out": ".png", "truth": ".png"},
                  args.force,
                  inputs={"track": track_file_arg(args.track), "camera": camera_input(args.camera)})
    camera = resolve_camera_arg(args.camera)
    track = resolve_track_arg(args.track)
    try:
        track.check_place(args.s, args.lateral, args.heading,
                          names=("--s", "--lateral", "--heading"))
    except ValueError as exc:
        raise CliError(str(exc)) from None
    rng = np.random.default_rng(args.seed)
    effects = {"off": Effects.off, "default": Effects,
               "random": lambda: DomainRandomization().sample(rng)}[args.effects]()
    x, y, h = (float(v) for v in track.pose(args.s, args.lateral))
    pose = (x, y, h + args.heading)
    renderer = Renderer(camera)
    try:
        scene = build_scene(track, effects, rng)
    except ValueError as exc:  # a legal but huge track: the marking map's pixel cap
        raise CliError(f"--track {args.track}: cannot render this track: {exc}") from None
    renderer.render(scene, pose, frame_seed=args.seed)  # warm-up (JIT, caches) for the timing
    t0 = time.perf_counter()
    frame = renderer.render(scene, pose, frame_seed=args.seed)
    render_ms = 1000.0 * (time.perf_counter() - t0)
    summary: dict[str, Any] = {
        "track": track_arg_label(args.track), "s_m": args.s, "lateral_m": args.lateral,
        "heading_rad": args.heading, "pose": list(pose), "camera": args.camera,
        "image_size_px": [camera.width, camera.height], "effects": asdict(effects),
        "render_ms": render_ms, "out": str(args.out),
    }
    with Outputs() as outs:  # the frame and the truth picture, or neither
        _write_png(outs.path(args.out), frame)
        if args.truth is not None:
            truth = frame_truth(track, renderer.camera, pose, s_hint_m=args.s)
            picture = truth.colour()
            for line in (truth.left_boundary_px, truth.right_boundary_px):
                if len(line) > 1:
                    cv2.polylines(picture, [np.rint(line).astype(np.int32)], False,
                                  (0, 255, 0), 1, cv2.LINE_AA)
            _write_png(outs.path(args.truth), picture)
            summary["truth"] = str(args.truth)
        outs.commit()
    if args.json:
        print(json_text(summary))
    else:
        print(f"rendered {summary['track']} at s = {args.s:.2f} m, lateral "
              f"{args.lateral:+.2f} m, heading {args.heading:+.3f} rad in {render_ms:.2f} ms")
        for key in ("out", "truth"):
            if key in summary:
                print(f"wrote {summary[key]}")
    return 0
