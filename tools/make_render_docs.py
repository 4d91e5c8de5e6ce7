"""Regenerate the renderer's documentation images in ``docs/``.

    python tools/make_render_docs.py

- ``docs/render-vs-reference.png``: a rendered frame beside ``shared/reference/straight-road.png``;
- ``docs/render-effects.png``: the same view with default, off and three randomised effects;
- ``docs/render-truth.png``: a frame of a generated track and its ground truth.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from tfalda_sim.rendering import DomainRandomization, Effects, Renderer, build_scene, frame_truth
from tfalda_sim.tracks import generate, load_named

ROOT = Path(__file__).resolve().parents[1]
REFERENCE = ROOT.parent / "shared" / "reference" / "straight-road.png"


def label(img: np.ndarray, text: str) -> np.ndarray:
    out = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR) if img.ndim == 2 else img.copy()
    cv2.putText(out, text, (10, 26), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (0, 255, 255), 2, cv2.LINE_AA)
    return out


def main() -> None:
    renderer = Renderer()
    track = load_named("oval")
    x, y, h = (float(v) for v in track.pose(0.6, -0.2))
    pose = (x, y, h)
    frame = renderer.render(build_scene(track, Effects()), pose, frame_seed=1)
    docs = ROOT / "docs"
    if REFERENCE.exists():
        ref = cv2.imread(str(REFERENCE), cv2.IMREAD_GRAYSCALE)
        side = np.hstack([label(frame, "tfalda-sim (oval, default effects)"),
                          label(ref, "reference: straight-road.png")])
        cv2.imwrite(str(docs / "render-vs-reference.png"), side)
    rng = np.random.default_rng(4)
    tiles = [label(frame, "default"),
             label(renderer.render(build_scene(track, Effects.off()), pose), "off")]
    for k in range(4):
        fx = DomainRandomization().sample(rng)
        tiles.append(label(renderer.render(build_scene(track, fx, rng), pose, speed_m_s=3.0,
                                           frame_seed=k), f"randomised #{k + 1}"))
    grid = np.vstack([np.hstack(tiles[i:i + 2]) for i in range(0, len(tiles), 2)])
    cv2.imwrite(str(docs / "render-effects.png"), cv2.resize(grid, None, fx=0.5, fy=0.5,
                                                             interpolation=cv2.INTER_AREA))
    gen = generate(3)
    x, y, h = (float(v) for v in gen.pose(gen.intersections[0].s1_m - 1.6, -0.2))
    pose = (x, y, h)
    img = renderer.render(build_scene(gen, Effects()), pose)
    truth = frame_truth(gen, renderer.camera, pose)
    pic = truth.colour()
    for line in (truth.left_boundary_px, truth.right_boundary_px):
        cv2.polylines(pic, [np.rint(line).astype(np.int32)], False, (0, 255, 0), 1, cv2.LINE_AA)
    cv2.imwrite(str(docs / "render-truth.png"),
                np.hstack([label(img, "seed 3, before the intersection"),
                           label(pic, "ground truth + ego lane")]))


if __name__ == "__main__":
    main()
