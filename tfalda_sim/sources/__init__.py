"""Frame sources: videos, image folders, ROS 1/2 bags and MCAP files read as frames
with their time stamps (``base``), for replay, camera fit and evaluate --frames.

``open_source(path, topic=, frames=, rate_hz=)`` finds the kind (``open``); each kind has
its module (``video``, ``images``, ``ros``, ``mcap_file``), ROS image messages are decoded
in ``decode``, and one pass over the frames (range, sizes, stamp order) is ``stream``.
"""

from tfalda_sim.sources.base import (
    CameraInfo,
    FrameRange,
    FrameSource,
    SourceError,
    SourceFrame,
    SourceInfo,
    to_grey,
)
from tfalda_sim.sources.open import KINDS, open_source

__all__ = ["KINDS", "CameraInfo", "FrameRange", "FrameSource", "SourceError", "SourceFrame",
           "SourceInfo", "open_source", "to_grey"]
