"""Recordings out: a run as MCAP or a ROS 2 bag (Foxglove- and RViz-readable).

``Recorder(path, RecordingFormat.MCAP | ROSBAG, camera_info=…, source=…)`` takes one
``RecordedStep`` per camera frame (``write``) and puts the finished recording in place on
``close(keep=True)``. Modules: ``step`` (what a step holds), ``messages`` (the ROS 2 message
definitions), ``channels`` (a step as messages: the channel table), ``sinks`` (MCAP file
and bag folder), ``writer`` (the recorder: temporary files, errors, interrupts).
"""

from tfalda_sim.recording.channels import CHANNELS, Channel
from tfalda_sim.recording.clock import RecordingClock
from tfalda_sim.recording.step import RecordedStep, polyline_segments
from tfalda_sim.recording.writer import (
    CAMERA_TOPIC,
    CUSTOM_DATA_KEY,
    METADATA_NAME,
    Recorder,
    RecordingFormat,
)

__all__ = ["CAMERA_TOPIC", "CHANNELS", "CUSTOM_DATA_KEY", "METADATA_NAME", "Channel",
           "RecordedStep", "Recorder", "RecordingClock", "RecordingFormat", "polyline_segments"]
