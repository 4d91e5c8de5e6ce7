"""Shared by the benchmarks: pin to one core and describe the machine."""

from __future__ import annotations

import os
import platform

import cv2


def pin_to_one_core() -> None:
    """Run on one CPU with OpenCV on one thread (the targets are per core)."""
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    cv2.setNumThreads(1)


def machine() -> dict[str, object]:
    return {"cores": os.cpu_count(), "pinned_to_one_core": True,
            "opencv_threads": cv2.getNumThreads(), "python": platform.python_version()}
