"""What the benchmarks share: progress on stderr, the shared data folder, one-core pinning."""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import optrack

__all__ = ["info", "pin_to_one_core", "shared_data"]


def info(message: str) -> None:
    """A progress line on stderr (stdout carries only the JSON figures)."""
    print(message, file=sys.stderr, flush=True)


def shared_data() -> Path:
    """../shared/data beside the project checkout (real frames and images)."""
    return Path(optrack.__file__).resolve().parent.parent.parent / "shared" / "data"


def _idle_ticks() -> dict[int, int]:
    ticks = {}
    with open("/proc/stat", encoding="ascii") as handle:
        for line in handle:
            name, *fields = line.split()
            if name.startswith("cpu") and name != "cpu":
                ticks[int(name[3:])] = int(fields[3]) + int(fields[4])  # idle + iowait
    return ticks


def pin_to_one_core(sample_seconds: float = 0.3) -> int | None:
    """Restrict this process to the idlest core it may use (idle time sampled over
    ``sample_seconds`` from /proc/stat) and OpenCV to one thread; returns the core
    (None where the OS cannot pin)."""
    import cv2

    if not hasattr(os, "sched_setaffinity"):
        return None
    allowed = sorted(os.sched_getaffinity(0))
    core = allowed[0]
    try:
        before = _idle_ticks()
        time.sleep(sample_seconds)
        after = _idle_ticks()
        core = max(allowed, key=lambda c: after.get(c, 0) - before.get(c, 0))
    except (OSError, ValueError, IndexError):
        pass
    os.sched_setaffinity(0, {core})
    cv2.setNumThreads(1)
    return core
