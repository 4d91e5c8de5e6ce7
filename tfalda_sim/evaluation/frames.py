"""Score detectors on labelled real frames with the thesis' black-box metric: a folder of
frames (a sequence, in name order) and a folder of their labels (``labels.py``), or the
labelled frames of a recording (a video, a ROS bag, an MCAP file: ``sources``), whose
frame ``i`` (counted from 0, as ``replay --per-frame`` counts) is labelled by
``frame-<i>.labels.json`` naming ``"frame": "frame-<i>"``; the detectors see every frame
of the recording in order and are scored on the labelled ones."""

from __future__ import annotations

import re
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..camera import Camera
from ..perception import DetectorConfig, HoughConfig, HoughDetector, TfaldaDetector
from ..sources import FrameSource, to_grey
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


_RECORDING_LABELS = re.compile(r"frame-(\d+)\.labels\.json\Z")


def recording_frame_name(index: int) -> str:
    """The name a recording's frame ``index`` has in its labels (``frame``)."""
    return f"frame-{index}"


def recording_labels(labels: Path, source_name: str) -> dict[int, Path]:
    """``frame index → labels file`` of ``labels``' ``frame-<i>.labels.json`` files (the
    labelled frames of a recording); refuses a folder with none, naming the pattern."""
    if not labels.is_dir():
        raise FramesError(f"--labels {labels}: not a folder")
    found: dict[int, Path] = {}
    for p in labels.iterdir():
        m = _RECORDING_LABELS.fullmatch(p.name)
        if m is not None:
            index = int(m.group(1))
            if index in found:
                raise FramesError(f"--labels {labels}: {found[index].name} and {p.name} both "
                                  f"label frame {index}; keep one")
            found[index] = p
    if not found:
        raise FramesError(f"--labels {labels}: no frame-<i>.labels.json files (the labels of "
                          f"{source_name}'s frame i, counted from 0)")
    for index, p in found.items():
        try:  # before any scoring: a mismatch found at the last frame wastes the run
            labelled_frame(p, recording_frame_name(index))
        except LabelsError as exc:
            raise FramesError(str(exc)) from None
    return found


Labelled = tuple[str, np.ndarray, "Path | None"]
"""A frame to process: its name, the camera-sized grey image, its labels file (None: the
detectors see it but it is not scored)."""


def folder_frames(pairs: Iterable[tuple[Path, Path]], camera: Camera) -> Iterator[Labelled]:
    """The frames of ``frame_files``' pairs, read one at a time."""
    for frame_path, labels_path in pairs:
        yield frame_path.name, read_frame(frame_path, camera), labels_path


def source_frames(source: FrameSource, labels: Mapping[int, Path], camera: Camera, *,
                  stills: bool = False) -> Iterator[Labelled]:
    """A recording's frames in order up to its last labelled one (``stills``: only the
    labelled ones), as the camera's grey frames; a recording whose frames are not the
    camera's size is refused (the labels' pixels would not be its)."""
    last = max(labels)
    seen: set[int] = set()
    for item in source.frames():
        if item.index > last:
            break
        lab = labels.get(item.index)
        if stills and lab is None:
            continue
        h, w = item.image.shape[:2]
        if (w, h) != (camera.width, camera.height):
            raise FramesError(f"{source.info.path}: frames of {w}×{h} px, the camera's are "
                              f"{camera.width}×{camera.height}: give the camera they were "
                              "taken with")
        seen.add(item.index)
        yield recording_frame_name(item.index), to_grey(item.image, (w, h)), lab
    missing = sorted(set(labels) - seen)
    if missing:
        raise FramesError(f"labels name frame {missing[0]} ({len(missing)} labelled frames in "
                          f"all) that {source.info.path} does not have in the range read")


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


def score_frames(frames: Iterable[Labelled], camera: Camera, *,
                 tfalda: Mapping[str, DetectorConfig] | None = None,
                 hough: Mapping[str, HoughConfig] | None = None, repeat: int = 1,
                 stills: bool = False, epsilon_px: float = EPSILON_PX) -> list[FrameScores]:
    """Every detector on the frame sequence (``folder_frames``, ``source_frames``): each
    TFALDA configuration sees each frame ``repeat`` times (the LIS's filters settle on a
    still image) and is scored after the last on a frame with labels; the Hough baseline
    (stateless) once, on the labelled frames. Per frame: the lanes' or segments' hit
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
    for name, frame, labels_path in frames:
        if labels_path is None:
            for det in dets.values():
                for _ in range(repeat):
                    det.process(frame)
            continue
        try:
            truth = load_labels(labels_path, camera.width, camera.height, frame=name)
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
                "frame": name, "hit_rates": rates.round(4).tolist(),
                "mean_hit_rate": float(rates.mean()),
                "lanes_on_markings": int((rates >= ON_MARKING).sum()),
                "ego_found": line.ego_found.tolist(), "roi_reset": bool(obs.roi_reset)})
        for label, hd in houghs.items():
            seg = hd.detect(frame).segments
            line = score_lines(seg, truth, dist, epsilon_px=epsilon_px, band=band)
            scores[label].append({
                "frame": name, "segments": len(seg),
                "hit_rates": line.hit_rates.round(4).tolist(),
                "mean_hit_rate": float(line.hit_rates.mean()) if len(seg) else 0.0,
                "ego_found": line.ego_found.tolist()})
    return [FrameScores(k, v) for k, v in scores.items()]
