"""Replay a recorded drive in an endless loop through a lane detector (the second seed's
set-up: "Lesen Sie diesen als Endlosschleife ein").

    tfalda-sim replay VIDEO --detector hough|tfalda [--loops N | --forever]
                            [--max-frames N] [--out annotated.mp4 [--stages]] [--json]

The video is read frame by frame (``video.VideoReader``: colour → grey, other sizes
resized to the camera's 752×480), each frame goes through the detector, and after the last
frame the file is read again from its start — ``--loops`` times, or until Ctrl-C with
``--forever``; ``--max-frames`` stops it after that many frames in either mode (and so
bounds the annotated video, which grows ``OUT_BYTES_PER_FRAME`` a frame). A Ctrl-C ends
the replay cleanly in either mode: the frames so far are counted, the annotated video so
far is kept, the summary printed.

TFALDA + LIS keeps its state across the loop's seam (a recorded lap is a closed loop; the
LIS resets if the seam does not fit); the Hough baseline has no state between frames.
The command exits 0 after ``--loops N``, ``--max-frames N`` or a Ctrl-C of ``--forever``,
130 when a Ctrl-C cut ``--loops N`` short, 2 for an unreadable video or a bad option.
"""

from __future__ import annotations

import enum
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from ..camera import Camera, load_camera
from ..histogram import TimeHistogram
from ..interrupts import INTERRUPTS, holding_stops, is_interrupt
from ..perception import (
    DetectorConfig,
    HoughConfig,
    HoughDetector,
    TfaldaDetector,
)
from ..perception.hough import BINARISE_LEVEL, REAL_FRAME_BINARISE_LEVEL, SIMULATOR_BINARISE_LEVEL
from ..perception.params import IMAGE_HEIGHT_PX, IMAGE_WIDTH_PX, is_thesis_camera
from ..rendering.overlay import draw_hough, draw_observation, stage_view
from ..video import VideoReader, VideoWriter

DEFAULT_FPS: float = 25.0
"""Frame rate of the annotated video when the recording declares none [1/s]."""

OUT_BYTES_PER_FRAME: tuple[int, int] = (2_000, 3_500)
"""What the annotated video grows by a frame (H.264 of a 752×480 drive) [bytes]: the
annotated frames, and the 2×2 stage view. At 100–200 frames/s that is ≈ 1 GB an hour."""


class Detector(enum.Enum):
    """The detectors ``replay`` runs."""

    HOUGH = "hough"
    TFALDA = "tfalda"


class HoughPreset(enum.Enum):
    """The Hough baseline's settings: the seed's numbers, the simulator preset
    (``HoughConfig.simulator``: our markings' grey level, our car's bonnet as the mask), or
    a real camera's frames (``REAL_FRAME_BINARISE_LEVEL``). On a camera other than the
    thesis', the crop and mask are derived for it (``HoughConfig.for_camera``) and only
    the binarising level comes from the preset."""

    SEED = "seed"
    SIMULATOR = "simulator"
    REAL = "real"

    def config(self, camera: Camera | None = None) -> HoughConfig:
        level = {HoughPreset.SEED: BINARISE_LEVEL,
                 HoughPreset.SIMULATOR: SIMULATOR_BINARISE_LEVEL,
                 HoughPreset.REAL: REAL_FRAME_BINARISE_LEVEL}[self]
        if camera is None or is_thesis_camera(camera):
            if self is HoughPreset.SEED:
                return HoughConfig()
            if self is HoughPreset.SIMULATOR:
                return HoughConfig.simulator()
            camera = camera or load_camera("thesis")
        return HoughConfig.for_camera(camera, level)


def _frame_step(detector: Detector, hough: HoughDetector | None,
                tfalda: TfaldaDetector | None, frame: np.ndarray,
                annotate: bool, text: str, stages: bool = False
                ) -> tuple[int, bool, np.ndarray | None, float]:
    """Run the detector on one frame: (detections, LIS reset, annotated frame or None —
    with ``stages`` the Hough baseline's 2×2 stage view instead of the frame —, the
    detector's own time [s], drawing not included)."""
    t0 = time.perf_counter()
    if detector is Detector.HOUGH:
        assert hough is not None
        result = hough.detect(frame)
        dt = time.perf_counter() - t0
        segments = result.segments
        picture = None
        if annotate:
            picture = stage_view(result) if stages else draw_hough(frame, result, text=text)
        return len(segments), False, picture, dt
    assert tfalda is not None
    obs = tfalda.process(frame)
    dt = time.perf_counter() - t0
    # TFALDA always returns a lane per ROI; a detection is one the LIS did not replace by
    # last frame's.
    lanes = int((np.all(np.isfinite(obs.lanes), axis=1) & ~obs.replaced).sum())
    picture = draw_observation(frame, obs, text=text) if annotate else None
    return lanes, bool(obs.roi_reset), picture, dt


def replay(path: str | Path, detector: Detector, *, loops: int | None = 1,
           out: Path | None = None, hough: HoughPreset = HoughPreset.SIMULATOR,
           stages: bool = False, progress: bool = False, camera: Camera | None = None,
           max_frames: int | None = None) -> dict[str, Any]:
    """Replay ``path`` ``loops`` times (``None``: until Ctrl-C) through ``detector``, or
    until ``max_frames`` frames; the summary: frames, loops, frames/s, detector ms/frame,
    detections, conversions, and how it stopped (``"loops"``, ``"max_frames"`` or
    ``"interrupted"``). ``out`` gets the annotated frames,
    or with ``stages`` (Hough only) the seed's 2×2 stage view of each frame. ``camera``
    (default: the thesis'): frames are converted to its size and both detectors use the
    geometry derived for it."""
    if stages and detector is not Detector.HOUGH:
        raise ValueError("stages is the Hough baseline's 2×2 view; use the hough detector")
    if max_frames is not None and max_frames < 1:
        raise ValueError(f"max_frames must be ≥ 1 or None, got {max_frames}")
    size = (camera.width, camera.height) if camera is not None else (IMAGE_WIDTH_PX,
                                                                       IMAGE_HEIGHT_PX)
    reader = VideoReader(path, size=size)
    hough_det = HoughDetector(hough.config(camera)) if detector is Detector.HOUGH else None
    tfalda_cfg = DetectorConfig.thesis() if camera is None else \
        DetectorConfig.thesis().on_camera(camera)
    tfalda_det = TfaldaDetector(tfalda_cfg) if detector is Detector.TFALDA else None
    fps = reader.info.fps if math.isfinite(reader.info.fps) and reader.info.fps > 0 else \
        DEFAULT_FPS
    per_loop = reader.info.frame_count or None
    # Running sums and a time histogram: --forever runs for days in flat memory.
    frames = detections = frames_without = resets = 0
    times = TimeHistogram()
    stopped = "loops"
    t_start = time.perf_counter()
    writer: VideoWriter | None = None
    bar = None
    keep = False  # the annotated video replaces --out only after a clean stop
    try:
        if out is not None:
            writer = VideoWriter(out, fps)
        total = loops * per_loop if loops and per_loop else None
        if max_frames is not None:
            total = min(total or max_frames, max_frames)
        bar = tqdm(total=total, unit="frame", desc=f"replay {detector.value}",
                   disable=not progress)
        for loop, frame in reader.loop(loops):
            found, reset, picture, dt = _frame_step(
                detector, hough_det, tfalda_det, frame, writer is not None,
                f"loop {loop + 1} frame {frames + 1}", stages)
            times.add(dt)
            frames += 1
            detections += found
            frames_without += found == 0
            resets += reset
            if writer is not None and picture is not None:
                writer.write(picture)
            bar.update()
            if max_frames is not None and frames >= max_frames:
                stopped = "max_frames"
                break
        keep = True
    except INTERRUPTS as exc:
        if not is_interrupt(exc):
            raise
        stopped = "interrupted"
        keep = True
    finally:
        with holding_stops():  # closing the video must not be cut by a second Ctrl-C
            if bar is not None:
                bar.close()
            if writer is not None:
                writer.close(keep=keep)
    wall = time.perf_counter() - t_start
    return {
        "video": str(path), "detector": detector.value,
        "hough_preset": hough.value if detector is Detector.HOUGH else None,
        "codec": reader.info.codec, "source_size_px": [reader.info.width_px,
                                                      reader.info.height_px],
        "conversions": reader.conversions,
        "frames": frames, "loops_completed": reader.passes_completed,
        "stopped": stopped,
        "frames_per_s": frames / wall if wall > 0 else None,
        "detector_ms_median": times.median_ms(),  # to 0.01 ms (binned)
        "detections_per_frame": detections / frames if frames else None,
        "frames_without_detection": frames_without,
        "roi_resets": resets if detector is Detector.TFALDA else None,
        "out": str(out) if writer is not None and writer.frames else None,
    }
