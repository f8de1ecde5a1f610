"""Replay a stream of detection batches through the tracker and sample its output.

The output sampled is what an operator receives: the tracker's tracks
through the output smoother (moving average, tracks unseen for 0.6 s left
out), taken at each ground-truth instant.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Iterable, Sequence

import numpy as np

from optrack.tracking.smoothing import OutputSmoother
from optrack.tracking.tracker import Tracker
from optrack.types import DetectionBatch, TrackBatch

__all__ = ["Replay", "replay"]


@dataclasses.dataclass
class Replay:
    outputs: list[TrackBatch]  # one per requested instant
    update_ms: np.ndarray  # time of each tracker update, ms
    dropped_batches: int

    @property
    def ms_per_update(self) -> float:
        return float(np.median(self.update_ms)) if self.update_ms.size else 0.0


def replay(
    batches: Iterable[DetectionBatch],
    times: Sequence[float] | np.ndarray,
    tracker: Tracker,
    smoother: OutputSmoother | None = None,
) -> Replay:
    """Feed batches in their order; at each of ``times`` (ascending) take the smoothed output
    of every batch stamped before it."""
    smoother = smoother if smoother is not None else OutputSmoother()
    times = np.asarray(times, dtype=np.float64)
    outputs: list[TrackBatch] = []
    update_ms: list[float] = []
    k = 0
    for batch in batches:
        while k < len(times) and times[k] < batch.stamp:
            outputs.append(smoother.publish(float(times[k])))
            k += 1
        started = time.perf_counter()
        out = tracker.update(batch)
        update_ms.append((time.perf_counter() - started) * 1000.0)
        if out is not None:
            smoother.add(out)
    while k < len(times):
        outputs.append(smoother.publish(float(times[k])))
        k += 1
    return Replay(outputs, np.asarray(update_ms), tracker.dropped)
