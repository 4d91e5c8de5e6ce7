"""Score detectors on labelled real frames with the thesis' black-box metric: a folder of
frames (a sequence, in name order) and a folder of their labels (``labels.py``)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..camera import Camera
from ..perception import DetectorConfig, HoughConfig, HoughDetector, TfaldaDetector
from ..video import ImageError, read_grey_image
from .baseline import band_rows, score_lines
from .labels import LabelsError, labelled_frame, labels_path_for, load_labels
from .metrics import EPSILON_PX, lane_hit_rates, truth_distance

FRAME_SUFFIXES: tuple[str, ...] = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
"""Image files ``frame_files`` takes."""

MAX_FRAMES_IN_DIR: int = 100_000
"""Most frames one folder may hold (a sequence of 33 minutes at 50 frames/s)."""

ON_MARKING: float = 0.8
"""A lane is on a marking when at least this share of its pixels is [1] (docs/cameras.md)."""


class FramesError(ValueError):
    """Frames or labels that cannot be scored; the message names the file."""


def frame_files(folder: Path, labels: Path) -> list[tuple[Path, Path]]:
    """(frame, labels file) pairs of ``folder``'s images in name order; every frame needs
    ``<stem>.labels.json`` in ``labels`` whose ``frame`` (if given) names it."""
    if not folder.is_dir():
        raise FramesError(f"--frames {folder}: not a folder")
    if not labels.is_dir():
        raise FramesError(f"--labels {labels}: not a folder")
    frames = sorted(p for p in folder.iterdir() if p.suffix.lower() in FRAME_SUFFIXES)
    if not frames:
        raise FramesError(f"--frames {folder}: no image files ({', '.join(FRAME_SUFFIXES)})")
    if len(frames) > MAX_FRAMES_IN_DIR:
        raise FramesError(f"--frames {folder}: {len(frames)} frames, at most "
                          f"{MAX_FRAMES_IN_DIR}")
    pairs = []
    for f in frames:
        lab = labels_path_for(f, labels)
        if not lab.is_file():
            raise FramesError(f"{f.name} has no labels: expected {lab}")
        try:  # before any scoring: a mismatch found at the last frame wastes the run
            labelled_frame(lab, f)
        except LabelsError as exc:
            raise FramesError(str(exc)) from None
        pairs.append((f, lab))
    return pairs


def read_frame(path: Path, camera: Camera) -> np.ndarray:
    """``path`` as the camera's 8-bit grey frame (colour converted; another size refused)."""
    try:
        img = read_grey_image(path)
    except ImageError as exc:
        raise FramesError(str(exc)) from None
    if img.shape != (camera.height, camera.width):
        raise FramesError(f"{path}: {img.shape[1]}×{img.shape[0]} px, the camera's frames are "
                          f"{camera.width}×{camera.height}: give the camera it was taken with")
    return img


@dataclass(frozen=True)
class FrameScores:
    """One detector's figures over the frames."""

    label: str
    per_frame: list[dict[str, Any]]

    def summary(self) -> dict[str, Any]:
        rates = [r["mean_hit_rate"] for r in self.per_frame]
        out: dict[str, Any] = {"frames": len(rates), "mean_hit_rate": float(np.mean(rates))}
        if "lanes_on_markings" in self.per_frame[0]:
            out["mean_lanes_on_markings"] = float(np.mean(
                [r["lanes_on_markings"] for r in self.per_frame]))
        if "ego_found" in self.per_frame[0]:
            out["ego_found_share"] = float(np.mean([all(r["ego_found"])
                                                    for r in self.per_frame]))
        return out


def score_frames(pairs: Sequence[tuple[Path, Path]], camera: Camera, *,
                 tfalda: Mapping[str, DetectorConfig] | None = None,
                 hough: Mapping[str, HoughConfig] | None = None, repeat: int = 1,
                 stills: bool = False, epsilon_px: float = EPSILON_PX) -> list[FrameScores]:
    """Every detector on the frame sequence: each TFALDA configuration sees each frame
    ``repeat`` times (the LIS's filters settle on a still image) and is scored after the
    last; the Hough baseline (stateless) once. Per frame: the lanes' or segments' hit
    rates, how many lanes lie on a marking (≥ ``ON_MARKING``) and whether a line follows
    each labelled ego boundary. ``stills``: the frames are unrelated pictures, each
    detector starts afresh on each (a first frame, table 2.4's ROIs)."""
    if repeat < 1:
        raise ValueError(f"repeat must be ≥ 1, got {repeat}")
    tfalda = dict(tfalda or {})
    hough = dict(hough or {})
    dets = {k: TfaldaDetector(c) for k, c in tfalda.items()}
    houghs = {k: HoughDetector(c) for k, c in hough.items()}
    band = band_rows(next(iter(tfalda.values()))) if tfalda else band_rows(
        DetectorConfig.for_camera(camera))
    scores: dict[str, list[dict[str, Any]]] = {k: [] for k in (*dets, *houghs)}
    for frame_path, labels_path in pairs:
        frame = read_frame(frame_path, camera)
        try:
            truth = load_labels(labels_path, camera.width, camera.height, frame=frame_path)
        except LabelsError as exc:
            raise FramesError(str(exc)) from None
        dist = truth_distance(truth.labels)
        for label, det in dets.items():
            if stills:
                det.reset()
            for _ in range(repeat):
                obs = det.process(frame)
            rates = lane_hit_rates(obs.lanes, dist, epsilon_px)
            line = score_lines(obs.lanes, truth, dist, epsilon_px=epsilon_px, band=band)
            scores[label].append({
                "frame": frame_path.name, "hit_rates": rates.round(4).tolist(),
                "mean_hit_rate": float(rates.mean()),
                "lanes_on_markings": int((rates >= ON_MARKING).sum()),
                "ego_found": line.ego_found.tolist(), "roi_reset": bool(obs.roi_reset)})
        for label, hd in houghs.items():
            seg = hd.detect(frame).segments
            line = score_lines(seg, truth, dist, epsilon_px=epsilon_px, band=band)
            scores[label].append({
                "frame": frame_path.name, "segments": len(seg),
                "hit_rates": line.hit_rates.round(4).tolist(),
                "mean_hit_rate": float(line.hit_rates.mean()) if len(seg) else 0.0,
                "ego_found": line.ego_found.tolist()})
    return [FrameScores(k, v) for k, v in scores.items()]
