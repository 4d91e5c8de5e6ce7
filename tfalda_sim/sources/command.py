"""The options that pick a recording's frames, shared by the commands that read one
(``replay``, ``camera fit``): ``--topic``, ``--frames A:B``, ``--rate HZ``. No command of its
own."""

from __future__ import annotations

import argparse

from ..cli_common import bounded_float_arg
from .base import FrameRange

RATE_RANGE_HZ: tuple[float, float] = (0.1, 1000.0)
"""``--rate``'s range [1/s]: a frame every 10 s to a high-speed camera's 1000 frames/s."""


def frame_range_arg(text: str) -> FrameRange:
    """``--frames A:B`` (argparse type)."""
    try:
        return FrameRange.parse(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_source_options(parser: argparse.ArgumentParser) -> None:
    """``--topic``, ``--frames`` and ``--rate``: which frames of a recording to read."""
    parser.add_argument("--topic", help="the image topic of a ROS bag or MCAP file (default: "
                                        "its only image topic, or the one it names as its "
                                        "camera)")
    parser.add_argument("--frames", type=frame_range_arg, metavar="A:B",
                        help="frames A to B−1 of the recording, counted from 0 (A: or :B "
                             "too)")
    parser.add_argument("--rate", type=bounded_float_arg(*RATE_RANGE_HZ, "1/s"), metavar="HZ",
                        help="an image folder's or video's frame rate [1/s] (its time "
                             "stamps; default: from the file names or the video)")
