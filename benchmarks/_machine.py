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


SIMD_FLAGS: tuple[str, ...] = ("avx512f", "avx2", "avx", "sse4_2", "neon", "asimd")
"""CPU flags named in ``cpu()``'s vector instruction set, widest first."""


def cpu() -> dict[str, str]:
    """The CPU's model name and its widest vector instruction set (Linux's
    ``/proc/cpuinfo``; ``platform.processor()`` elsewhere): figures of different sessions
    compare only on the same CPU, and this VM's host has changed between sessions (2.0 GHz
    in the sixth to twelfth, a 2.8 GHz Xeon with AVX-512 in the thirteenth)."""
    model, flags = "", set()
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            for line in f:  # the first core's lines (x86: "model name"; ARM: "Model")
                key, _, value = (part.strip() for part in line.partition(":"))
                if key in ("model name", "Model") and not model:
                    model = value
                elif key in ("flags", "Features") and not flags:
                    flags = set(value.split())
    except OSError:
        pass
    simd = next((flag for flag in SIMD_FLAGS if flag in flags), "unknown")
    return {"cpu": model or platform.processor() or platform.machine() or "unknown",
            "simd": simd}


def machine() -> dict[str, object]:
    return {"cores": os.cpu_count(), **cpu(), "pinned_to_one_core": True,
            "opencv_threads": cv2.getNumThreads(), "python": platform.python_version()}
