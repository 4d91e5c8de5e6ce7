"""Replay a recording in an endless loop through a lane detector (the second seed's
set-up: "Lesen Sie diesen als Endlosschleife ein").

    tfalda-sim replay SOURCE --detector hough|tfalda [--topic T] [--frames A:B] [--rate HZ]
                             [--loops N | --forever] [--max-frames N]
                             [--out annotated.mp4 [--stages]] [--per-frame F.jsonl] [--json]

SOURCE is anything ``sources.open_source`` reads (a video, an image folder or glob, a
ROS 1 or ROS 2 bag, an MCAP file). Its frames are read one by one (colour → grey, other
sizes resized to the camera's, ``sources.to_grey``), each goes through the detector, and
after the last frame the recording is read again from its start — ``--loops`` times, or
until Ctrl-C with ``--forever``; ``--max-frames`` stops it after that many frames in either
mode (and so bounds the annotated video, which grows ``OUT_BYTES_PER_FRAME`` a frame). A
Ctrl-C ends the replay cleanly in either mode: the frames so far are counted, the
annotated video and the per-frame lines so far are kept, the summary printed. The
recording's own frame rate (from its time stamps) is reported beside the processing
rate, and said when it is not the camera profile's (``rate_note``).

TFALDA + LIS keeps its state across the loop's seam (a recorded lap is a closed loop; the
LIS resets if the seam does not fit); the Hough baseline has no state between frames.
The command exits 0 after ``--loops N``, ``--max-frames N`` or a Ctrl-C of ``--forever``,
130 when a Ctrl-C cut ``--loops N`` short, 2 for an unreadable video or a bad option.
"""

from __future__ import annotations

import contextlib
import enum
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from ..camera import Camera, load_camera
from ..camera.ros_info import camera_info_of
from ..cli_common import json_text
from ..fileio import atomic_write
from ..histogram import TimeHistogram
from ..interrupts import INTERRUPTS, holding_stops, is_interrupt
from ..perception import (
    DetectorConfig,
    HoughConfig,
    HoughDetector,
    LaneObservation,
    TfaldaDetector,
)
from ..perception.hough import (
    BINARISE_LEVEL,
    REAL_FRAME_BINARISE_LEVEL,
    SIMULATOR_BINARISE_LEVEL,
    HoughResult,
)
from ..perception.params import IMAGE_HEIGHT_PX, IMAGE_WIDTH_PX, is_thesis_camera
from ..recording import RecordedStep, Recorder, RecordingClock, RecordingFormat
from ..rendering.overlay import draw_hough, draw_observation, stage_view
from ..sources import FrameRange, SourceError, SourceInfo, open_source, to_grey
from ..video import VideoWriter, is_grey
from .per_frame import lanes_record, segments_record

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
                ) -> tuple[int, bool, np.ndarray | None, float, HoughResult | LaneObservation]:
    """Run the detector on one frame: (detections, LIS reset, annotated frame or None —
    with ``stages`` the Hough baseline's 2×2 stage view instead of the frame —, the
    detector's own time [s], drawing not included, the detector's result)."""
    t0 = time.perf_counter()
    if detector is Detector.HOUGH:
        assert hough is not None
        result = hough.detect(frame)
        dt = time.perf_counter() - t0
        segments = result.segments
        picture = None
        if annotate:
            picture = stage_view(result) if stages else draw_hough(frame, result, text=text)
        return len(segments), False, picture, dt, result
    assert tfalda is not None
    obs = tfalda.process(frame)
    dt = time.perf_counter() - t0
    # TFALDA always returns a lane per ROI; a detection is one the LIS did not replace by
    # last frame's.
    lanes = int(obs.accepted.sum())
    picture = draw_observation(frame, obs, text=text) if annotate else None
    return lanes, bool(obs.roi_reset), picture, dt, obs


RATE_MISMATCH: float = 0.05
"""A recording whose frame rate differs from the camera profile's by more than this share
is said: the LIS's filters and the ROI rules count frames, not seconds [1]."""


def _conversions(info: SourceInfo, first: np.ndarray, size: tuple[int, int]) -> list[str]:
    """What turning the source's frames into the camera's grey ``size`` does, judged on
    the first frame."""
    out: list[str] = []
    if first.ndim == 3 and first.shape[2] in (3, 4) and not is_grey(first):
        out.append("colour → grey")
    h, w = first.shape[:2]
    if (w, h) != size:
        out.append(f"{w}×{h} → {size[0]}×{size[1]} px")
        if abs(w / h - size[0] / size[1]) > 0.01:
            out.append("aspect ratio changed")
    return out


def _recorded(t_s: float, frame: np.ndarray, result: HoughResult | LaneObservation
              ) -> RecordedStep:
    """One replayed frame as a recording's step."""
    if isinstance(result, HoughResult):
        return RecordedStep(t_s=t_s, frame=frame, segments=result.segments)
    return RecordedStep(t_s=t_s, frame=frame, lanes=result.lanes,
                        accepted=result.accepted, rois=result.rois,
                        fault_counter=int(result.fault_count),
                        roi_reset=bool(result.roi_reset), state=result.state.value)


def camera_info_note(info: SourceInfo, camera: Camera) -> str | None:
    """The line saying that the recording's camera_info is not the camera profile's
    calibration (None when it has none, or the same size and K)."""
    ci = info.camera_info
    if ci is None:
        return None
    if (ci.width_px, ci.height_px) == (camera.width, camera.height) and np.allclose(
            np.asarray(ci.K, np.float64).reshape(3, 3), camera.K, rtol=1e-6, atol=1e-6):
        return None
    return (f"the recording's camera_info ({ci.width_px}×{ci.height_px} px, focal "
            f"{float(np.asarray(ci.K).ravel()[0]):.1f} px) is not the camera profile's "
            f"({camera.width}×{camera.height} px, {float(camera.K[0, 0]):.1f} px): "
            "`tfalda-sim camera fit` on the recording writes a profile with it, for --camera")


def rate_note(recording_hz: float | None, camera_hz: float) -> str | None:
    """The line saying that the recording's frame rate is not the camera profile's, or
    None when they agree (within ``RATE_MISMATCH``) or the recording has none."""
    if recording_hz is None or not math.isfinite(recording_hz) or recording_hz <= 0:
        return None
    if abs(recording_hz / camera_hz - 1.0) <= RATE_MISMATCH:
        return None
    return (f"the recording runs at {recording_hz:.3g} frames/s, the camera profile at "
            f"{camera_hz:.3g}: the detectors count frames, so their filters act "
            f"{recording_hz / camera_hz:.2f}× as fast in seconds (camera fit writes a "
            "profile with the recording's rate)")


def replay(path: str | Path, detector: Detector, *, loops: int | None = 1,
           out: Path | None = None, hough: HoughPreset = HoughPreset.SIMULATOR,
           stages: bool = False, progress: bool = False, camera: Camera | None = None,
           max_frames: int | None = None, topic: str | None = None,
           frames: FrameRange | None = None, rate_hz: float | None = None,
           per_frame: Path | None = None, mcap: Path | None = None,
           rosbag: Path | None = None) -> dict[str, Any]:
    """Replay the recording ``path`` (anything ``sources.open_source`` reads: a video, an
    image folder or glob, a ROS 1/2 bag, an MCAP file; ``topic``, ``frames`` and
    ``rate_hz`` as there) ``loops`` times (``None``: until Ctrl-C) through ``detector``,
    or until ``max_frames`` frames; the summary: frames, loops, the recording's and the
    processing frame rate, detector ms/frame, detections, conversions, and how it stopped
    (``"loops"``, ``"max_frames"`` or ``"interrupted"``). ``out`` gets the annotated
    frames, or with ``stages`` (Hough only) the seed's 2×2 stage view of each frame;
    ``per_frame`` a JSON line a frame (``per_frame.py``); ``mcap`` / ``rosbag`` the replay
    as a recording (the frames as the detector saw them, its lanes or segments, the LIS
    state: ``recording``). ``camera`` (default: the
    thesis'): frames are converted to its size and both detectors use the geometry derived
    for it. Every output is written
    in full or not at all; a Ctrl-C keeps the frames finished in each."""
    if stages and detector is not Detector.HOUGH:
        raise ValueError("stages is the Hough baseline's 2×2 view; use the hough detector")
    if max_frames is not None and max_frames < 1:
        raise ValueError(f"max_frames must be ≥ 1 or None, got {max_frames}")
    if loops is not None and loops < 1:
        raise ValueError(f"loops must be ≥ 1 or None (endless), got {loops}")
    size = (camera.width, camera.height) if camera is not None else (IMAGE_WIDTH_PX,
                                                                       IMAGE_HEIGHT_PX)
    source = open_source(path, topic=topic, frames=frames, rate_hz=rate_hz)
    info = source.info
    hough_det = HoughDetector(hough.config(camera)) if detector is Detector.HOUGH else None
    tfalda_cfg = DetectorConfig.thesis() if camera is None else \
        DetectorConfig.thesis().on_camera(camera)
    tfalda_det = TfaldaDetector(tfalda_cfg) if detector is Detector.TFALDA else None
    if mcap is not None and rosbag is not None:
        raise ValueError("mcap and rosbag both record the replay: give one")
    cam = camera or load_camera("thesis")
    camera_hz = cam.frame_rate_hz
    fps = info.rate_hz if info.rate_hz and math.isfinite(info.rate_hz) and info.rate_hz > 0 \
        else DEFAULT_FPS
    per_loop = info.frame_count or None
    # Running sums and a time histogram: --forever runs for days in flat memory.
    n = detections = frames_without = resets = passes = 0
    times = TimeHistogram()
    stopped = "loops"
    conversions: list[str] | None = None
    t_start = time.perf_counter()
    writer: VideoWriter | None = None
    recorder: Recorder | None = None
    clock = RecordingClock(fps)
    bar = None
    keep = False  # the outputs replace existing files only after a clean stop
    with contextlib.ExitStack() as outputs:
        try:
            if out is not None:
                writer = VideoWriter(out, fps)
            lines = outputs.enter_context(atomic_write(per_frame)) if per_frame else None
            if mcap is not None or rosbag is not None:
                recorder = Recorder(mcap or rosbag, RecordingFormat.MCAP if mcap is not None
                                    else RecordingFormat.ROSBAG,
                                    camera_info=camera_info_of(cam), source=str(path))
            total = loops * per_loop if loops and per_loop else None
            if max_frames is not None:
                total = min(total or max_frames, max_frames)
            bar = tqdm(total=total, unit="frame", desc=f"replay {detector.value}",
                       disable=not progress)
            while loops is None or passes < loops:
                empty = True
                for item in source.frames():
                    empty = False
                    if conversions is None:
                        conversions = _conversions(info, item.image, size)
                    frame = to_grey(item.image, size)
                    found, reset, picture, dt, result = _frame_step(
                        detector, hough_det, tfalda_det, frame, writer is not None,
                        f"loop {passes + 1} frame {item.index}", stages)
                    times.add(dt)
                    n += 1
                    detections += found
                    frames_without += found == 0
                    resets += reset
                    if writer is not None and picture is not None:
                        writer.write(picture)
                    if lines is not None:
                        record_line = (lanes_record if detector is Detector.TFALDA
                                       else segments_record)
                        lines.write(json_text(record_line(item.index, passes, item.t_s,
                                                          result)) + "\n")
                    if recorder is not None:
                        recorder.write(_recorded(clock.time(item.t_s), frame, result))
                    bar.update()
                    if max_frames is not None and n >= max_frames:
                        stopped = "max_frames"
                        break
                if stopped == "max_frames":
                    break
                if empty:
                    raise SourceError(f"{path}: a pass over the recording gave no frame")
                passes += 1
            keep = True
        except INTERRUPTS as exc:
            if not is_interrupt(exc):
                raise
            stopped = "interrupted"
            keep = True
        finally:
            with holding_stops():  # closing the outputs must not be cut by a second Ctrl-C
                if bar is not None:
                    bar.close()
                if writer is not None:
                    writer.close(keep=keep)
                if recorder is not None:
                    recorder.close(keep=keep)
    wall = time.perf_counter() - t_start
    notes = [*info.notes, *getattr(source, "notes", [])]
    note = rate_note(info.rate_hz, camera_hz)
    return {
        "source": str(path), "kind": info.kind, "topic": info.topic,
        "detector": detector.value,
        "hough_preset": hough.value if detector is Detector.HOUGH else None,
        "source_size_px": [info.width_px, info.height_px],
        "conversions": (conversions or []) + notes,
        "frames": n, "loops_completed": passes,
        "stopped": stopped,
        "recording_rate_hz": info.rate_hz,
        "camera_rate_hz": camera_hz,
        "rate_note": note,
        "camera_info_note": camera_info_note(info, cam),
        "frames_per_s": n / wall if wall > 0 else None,
        "detector_ms_median": times.median_ms(),  # to 0.01 ms (binned)
        "detections_per_frame": detections / n if n else None,
        "frames_without_detection": frames_without,
        "roi_resets": resets if detector is Detector.TFALDA else None,
        "out": str(out) if writer is not None and writer.frames else None,
        "per_frame": str(per_frame) if per_frame is not None else None,
        "recording": str(mcap or rosbag) if recorder is not None and recorder.frames
        else None,
    }
