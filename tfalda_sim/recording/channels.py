"""A recorded step as ROS 2 messages, one per channel (topic) that has data in it.

=============================  ==================================  =========================
topic                          type                                written when
=============================  ==================================  =========================
/camera/image/compressed       sensor_msgs/msg/CompressedImage     every step
/camera/camera_info            sensor_msgs/msg/CameraInfo          every step, with
                                                                   ``camera_info``
/camera/annotations            foxglove_msgs/msg/ImageAnnotations  lanes, rois, segments,
                                                                   truth_lanes or the LIS
/tfalda/lanes                  tfalda_msgs/msg/Lanes               lanes, rois or segments
/tfalda/lis                    tfalda_msgs/msg/LisState            the LIS fields
/car/pose                      geometry_msgs/msg/PoseStamped       pose
/car/odometry                  nav_msgs/msg/Odometry               pose (twist: speed_m_s)
/truth/cross_track             tfalda_msgs/msg/CrossTrack          cross_track_m
/topdown/image/compressed      sensor_msgs/msg/CompressedImage     top_view
=============================  ==================================  =========================

Every message of a step has the step's time stamp, ``header.stamp`` = the recording's
start + ``t_s`` (the recorder's ``start_ns``: by default the wall-clock time it was made,
so Foxglove shows when the run was recorded, and no frame has the stamp 0 that ROS tools
read as "no stamp"), which is also the messages' log time: Foxglove pairs an image with
its annotations and camera_info by it.

- The camera frame is PNG (lossless: a replay of the recording detects exactly what the
  run detected), frame ``camera``; the top view is JPEG (``TOP_VIEW_JPEG_QUALITY``),
  frame ``topdown``.
- ``/tfalda/lanes`` holds the detector's numbers as the run had them; an empty array is a
  field the step did not give (see ``messages.py`` for the layout).
- ``/camera/annotations`` draws them over the camera image: accepted lanes
  ``ACCEPTED_COLOR``, lanes the LIS replaced ``REPLACED_COLOR``, the regions of interest
  as closed outlines, Hough segments, the true lane lines and a line of LIS state.
  Foxglove's image coordinates have the top-left *corner* of the top-left pixel at
  (0, 0), the detector's that pixel's centre: points move by half a pixel, ROI outlines
  (pixel edges) do not.
- The car's pose is in frame ``map`` (the track's), yaw as a rotation about z; the
  odometry's twist is in ``base_link``, the car: ``linear.x`` is its forward speed [m/s]
  (0 in a step without ``speed_m_s``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from tfalda_sim.recording import messages as m
from tfalda_sim.recording.step import LANE_COUNT, RecordedStep
from tfalda_sim.sources.base import CameraInfo


@dataclass(frozen=True)
class Channel:
    """A topic of the recording: its name, message type and ``header.frame_id``."""

    topic: str
    msgtype: str
    frame_id: str


CAMERA_IMAGE = Channel("/camera/image/compressed", m.COMPRESSED_IMAGE, "camera")
CAMERA_INFO = Channel("/camera/camera_info", m.CAMERA_INFO, "camera")
ANNOTATIONS = Channel("/camera/annotations", m.IMAGE_ANNOTATIONS, "camera")
LANES = Channel("/tfalda/lanes", m.LANES, "camera")
LIS = Channel("/tfalda/lis", m.LIS_STATE, "camera")
POSE = Channel("/car/pose", m.POSE_STAMPED, "map")
ODOMETRY = Channel("/car/odometry", m.ODOMETRY, "map")
CROSS_TRACK = Channel("/truth/cross_track", m.CROSS_TRACK, "map")
TOP_VIEW = Channel("/topdown/image/compressed", m.COMPRESSED_IMAGE, "topdown")

CHANNELS: tuple[Channel, ...] = (CAMERA_IMAGE, CAMERA_INFO, ANNOTATIONS, LANES, LIS, POSE,
                                 ODOMETRY, CROSS_TRACK, TOP_VIEW)
"""Every channel a recording can have, in the order a step's messages are written."""

CAR_FRAME = "base_link"
"""The odometry's child frame: the car."""

IMAGE_FORMATS = ("png", "jpeg")
"""Formats the camera frames can be written in: PNG is lossless (a replay detects as the
run did), JPEG smaller (it does not)."""

JPEG_QUALITY = 90
"""Quality of camera frames written as JPEG (0–100)."""

TOP_VIEW_JPEG_QUALITY = 90
"""Quality of the top view's JPEG (0–100): a picture to look at, kept small."""

# Annotation colours (r, g, b, a in 0–1) and line widths [px].
ACCEPTED_COLOR = (0.1, 0.9, 0.2, 1.0)
REPLACED_COLOR = (1.0, 0.45, 0.0, 1.0)
ROI_COLOR = (0.2, 0.6, 1.0, 0.9)
SEGMENT_COLOR = (1.0, 0.9, 0.1, 0.9)
TRUTH_COLOR = (0.9, 0.2, 0.9, 0.8)
TEXT_COLOR = (1.0, 1.0, 1.0, 1.0)
TEXT_BACKGROUND = (0.0, 0.0, 0.0, 0.6)
LANE_WIDTH_PX = 3.0
THIN_WIDTH_PX = 1.5
FONT_SIZE_PX = 14.0

PIXEL_CENTRE = 0.5
"""Where the detector's pixel (0, 0) is in Foxglove's image coordinates [px]."""


def offset_ns(t_s: float) -> int:
    """A step's time from the run's start [s] in the recording's unit [ns]."""
    return round(t_s * 1e9)


def encode_image(image: np.ndarray, fmt: str, quality: int = JPEG_QUALITY) -> np.ndarray:
    """``image`` (grey or BGR uint8) as PNG or JPEG bytes (a uint8 array)."""
    if fmt == "png":
        ok, buf = cv2.imencode(".png", image)
    elif fmt == "jpeg":
        ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    else:
        raise ValueError(f"image format must be one of {IMAGE_FORMATS}, got {fmt!r}")
    if not ok:
        raise ValueError(f"OpenCV cannot encode a {image.dtype} {image.shape} image as {fmt}")
    return buf.reshape(-1)


class StepMessages:
    """Turns recorded steps into messages: ``messages(step)`` is the list of
    ``(channel, message)`` for the channels the step has data for (in ``CHANNELS``
    order); the messages are rosbags typestore objects (``messages.typestore``)."""

    def __init__(self, *, camera_info: CameraInfo | None = None,
                 image_format: str = "png") -> None:
        if image_format not in IMAGE_FORMATS:
            raise ValueError(f"compress_frames must be one of {IMAGE_FORMATS}, got "
                             f"{image_format!r}")
        self.camera_info = camera_info
        self.image_format = image_format
        self._t = m.typestore().types

    # -- building blocks ------------------------------------------------------------------

    def _time(self, ns: int) -> Any:
        return self._t["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000,
                                                      nanosec=ns % 1_000_000_000)

    def _header(self, ns: int, frame_id: str) -> Any:
        return self._t["std_msgs/msg/Header"](stamp=self._time(ns), frame_id=frame_id)

    def _color(self, rgba: tuple[float, float, float, float]) -> Any:
        r, g, b, a = rgba
        return self._t[m.COLOR](r=r, g=g, b=b, a=a)

    def _point(self, x: float, y: float) -> Any:
        return self._t[m.POINT2](x=float(x), y=float(y))

    def _compressed(self, ns: int, frame_id: str, image: np.ndarray, fmt: str,
                    quality: int) -> Any:
        return self._t[m.COMPRESSED_IMAGE](header=self._header(ns, frame_id), format=fmt,
                                           data=encode_image(image, fmt, quality))

    def _points(self, ns: int, kind: int, points: list[tuple[float, float]],
                rgba: tuple[float, float, float, float], width: float) -> Any:
        return self._t[m.POINTS_ANNOTATION](
            timestamp=self._time(ns), type=kind,
            points=[self._point(x, y) for x, y in points],
            outline_color=self._color(rgba), outline_colors=[],
            fill_color=self._color((0.0, 0.0, 0.0, 0.0)), thickness=width)

    # -- channels ---------------------------------------------------------------------------

    def camera_info_msg(self, ns: int) -> Any:
        info = self.camera_info
        assert info is not None
        k = np.asarray(info.K, dtype=np.float64).reshape(3, 3)
        p = np.zeros((3, 4))
        p[:, :3] = k
        roi = self._t["sensor_msgs/msg/RegionOfInterest"](
            x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
        return self._t[m.CAMERA_INFO](
            header=self._header(ns, CAMERA_INFO.frame_id), height=int(info.height_px),
            width=int(info.width_px), distortion_model=str(info.distortion_model),
            d=np.asarray(info.D, dtype=np.float64).reshape(-1), k=k.reshape(-1),
            r=np.eye(3).reshape(-1), p=p.reshape(-1), binning_x=0, binning_y=0, roi=roi)

    def lanes_msg(self, ns: int, step: RecordedStep) -> Any:
        def flat(a: np.ndarray | None, dtype: type) -> np.ndarray:
            return np.zeros(0, dtype) if a is None else np.asarray(a, dtype).reshape(-1)

        return self._t[m.LANES](
            header=self._header(ns, LANES.frame_id), lanes=flat(step.lanes, np.float64),
            accepted=flat(step.accepted, np.bool_), rois=flat(step.rois, np.int32),
            segments=flat(step.segments, np.float64))

    def lis_msg(self, ns: int, step: RecordedStep) -> Any:
        replaced = np.zeros(LANE_COUNT, np.bool_) if step.accepted is None else \
            ~np.asarray(step.accepted, np.bool_)
        return self._t[m.LIS_STATE](
            header=self._header(ns, LIS.frame_id), fault_counter=int(step.fault_counter or 0),
            replaced=replaced, roi_reset=bool(step.roi_reset), state=str(step.state))

    def _pose(self, pose: tuple[float, float, float]) -> Any:
        x, y, yaw = (float(v) for v in pose)
        point = self._t["geometry_msgs/msg/Point"](x=x, y=y, z=0.0)
        quat = self._t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2),
                                                        w=math.cos(yaw / 2))
        return self._t["geometry_msgs/msg/Pose"](position=point, orientation=quat)

    def pose_msg(self, ns: int, step: RecordedStep) -> Any:
        assert step.pose is not None
        return self._t[m.POSE_STAMPED](header=self._header(ns, POSE.frame_id),
                                       pose=self._pose(step.pose))

    def odometry_msg(self, ns: int, step: RecordedStep) -> Any:
        assert step.pose is not None
        vec = self._t["geometry_msgs/msg/Vector3"]
        twist = self._t["geometry_msgs/msg/Twist"](
            linear=vec(x=float(step.speed_m_s or 0.0), y=0.0, z=0.0),
            angular=vec(x=0.0, y=0.0, z=0.0))
        return self._t[m.ODOMETRY](
            header=self._header(ns, ODOMETRY.frame_id), child_frame_id=CAR_FRAME,
            pose=self._t["geometry_msgs/msg/PoseWithCovariance"](
                pose=self._pose(step.pose), covariance=np.zeros(36)),
            twist=self._t["geometry_msgs/msg/TwistWithCovariance"](
                twist=twist, covariance=np.zeros(36)))

    def cross_track_msg(self, ns: int, step: RecordedStep) -> Any:
        assert step.cross_track_m is not None
        return self._t[m.CROSS_TRACK](header=self._header(ns, CROSS_TRACK.frame_id),
                                      cross_track_m=float(step.cross_track_m))

    def annotations_msg(self, ns: int, step: RecordedStep) -> Any:
        c = PIXEL_CENTRE
        line_list = self._t[m.POINTS_ANNOTATION].LINE_LIST
        line_loop = self._t[m.POINTS_ANNOTATION].LINE_LOOP
        points = []

        def segments(rows: np.ndarray) -> list[tuple[float, float]]:
            out = []
            for x0, y0, x1, y1 in np.asarray(rows, np.float64):
                if np.isfinite((x0, y0, x1, y1)).all():
                    out += [(x0 + c, y0 + c), (x1 + c, y1 + c)]
            return out

        if step.truth_lanes is not None:
            points.append((segments(step.truth_lanes), TRUTH_COLOR, THIN_WIDTH_PX, line_list))
        if step.segments is not None:
            points.append((segments(step.segments), SEGMENT_COLOR, THIN_WIDTH_PX, line_list))
        if step.rois is not None:
            for x, y, w, h in np.asarray(step.rois, np.float64):
                if w > 0 and h > 0:  # pixel edges: Foxglove's coordinates as they are
                    points.append(([(x, y), (x + w, y), (x + w, y + h), (x, y + h)],
                                   ROI_COLOR, THIN_WIDTH_PX, line_loop))
        if step.lanes is not None:
            kept = np.ones(LANE_COUNT, bool) if step.accepted is None else \
                np.asarray(step.accepted, bool)
            lanes = np.asarray(step.lanes, np.float64)
            points.append((segments(lanes[kept]), ACCEPTED_COLOR, LANE_WIDTH_PX, line_list))
            points.append((segments(lanes[~kept]), REPLACED_COLOR, LANE_WIDTH_PX, line_list))
        texts = []
        if step.has_lis:
            line = f"LIS {step.state}  faults {step.fault_counter}" + \
                ("  ROI reset" if step.roi_reset else "")
            texts.append(self._t[m.TEXT_ANNOTATION](
                timestamp=self._time(ns), position=self._point(8.0, 8.0 + FONT_SIZE_PX),
                text=line, font_size=FONT_SIZE_PX, text_color=self._color(TEXT_COLOR),
                background_color=self._color(TEXT_BACKGROUND)))
        return self._t[m.IMAGE_ANNOTATIONS](
            circles=[],
            points=[self._points(ns, kind, pts, rgba, width)
                    for pts, rgba, width, kind in points if pts],
            texts=texts)

    def messages(self, step: RecordedStep, ns: int) -> list[tuple[Channel, Any]]:
        """The step's messages, ``(channel, message)``, in ``CHANNELS`` order, stamped
        ``ns`` [ns since the Unix epoch]."""
        out: list[tuple[Channel, Any]] = [
            (CAMERA_IMAGE, self._compressed(ns, CAMERA_IMAGE.frame_id, step.frame,
                                            self.image_format, JPEG_QUALITY))]
        if self.camera_info is not None:
            out.append((CAMERA_INFO, self.camera_info_msg(ns)))
        detector = (step.lanes, step.rois, step.segments)
        if any(v is not None for v in detector) or step.truth_lanes is not None \
                or step.has_lis:
            out.append((ANNOTATIONS, self.annotations_msg(ns, step)))
        if any(v is not None for v in detector):
            out.append((LANES, self.lanes_msg(ns, step)))
        if step.has_lis:
            out.append((LIS, self.lis_msg(ns, step)))
        if step.pose is not None:
            out.append((POSE, self.pose_msg(ns, step)))
            out.append((ODOMETRY, self.odometry_msg(ns, step)))
        if step.cross_track_m is not None:
            out.append((CROSS_TRACK, self.cross_track_msg(ns, step)))
        if step.top_view is not None:
            out.append((TOP_VIEW, self._compressed(ns, TOP_VIEW.frame_id, step.top_view,
                                                   "jpeg", TOP_VIEW_JPEG_QUALITY)))
        return out
