"""Shared by the benchmarks: pin to one core and describe the host and the code measured."""

from __future__ import annotations

import datetime
import os
import platform
import subprocess
from pathlib import Path

import cv2

REPO = Path(__file__).resolve().parents[1]
"""The checkout the benchmarks belong to (its commit is reported with the figures)."""


def pin_to_one_core() -> None:
    """Run on one CPU with OpenCV on one thread (the targets are per core)."""
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    cv2.setNumThreads(1)


SIMD_FLAGS: tuple[str, ...] = ("avx512f", "avx2", "avx", "sse4_2", "neon", "asimd")
"""CPU flags named in ``cpu()``'s vector instruction set, widest first."""


def cpu() -> dict[str, str]:
    """The CPU's model name and its widest vector instruction set (Linux's
    ``/proc/cpuinfo``; ``platform.processor()`` elsewhere): figures compare only on the
    same CPU, and the VM this project is measured on has been moved between hosts of
    different CPUs (a 2.0 GHz one, a 2.8 GHz Xeon with AVX-512, an AMD EPYC)."""
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


PACKAGE_DIRS: tuple[str, ...] = ("tfalda_sim", "tracks", "envs", "agents")
"""The checkout's folders that hold the package's code (pyproject.toml's package-dir)."""


def commit() -> str:
    """The checkout's commit (short hash, ``+`` if the package's tracked files differ
    from it), or "" outside a git checkout: which code the figures are of."""
    def git(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(["git", "-C", str(REPO), *args], capture_output=True,
                              text=True, check=False)
    try:
        head = git("rev-parse", "--short", "HEAD")
        if head.returncode != 0:
            return ""
        dirty = git("diff", "--quiet", "HEAD", "--", *PACKAGE_DIRS).returncode != 0
    except OSError:
        return ""
    return head.stdout.strip() + ("+" if dirty else "")


def host() -> dict[str, object]:
    """What every benchmark's JSON reports about where and when it ran: the core count,
    the CPU, Python, the date (UTC) and the commit measured."""
    return {"cores": os.cpu_count(), **cpu(), "python": platform.python_version(),
            "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
            "commit": commit()}


def machine() -> dict[str, object]:
    """``host()`` for a benchmark pinned to one core with OpenCV on one thread."""
    return {**host(), "pinned_to_one_core": True, "opencv_threads": cv2.getNumThreads()}
