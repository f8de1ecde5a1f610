"""Write a simulation to a recording: every sensor's frames plus ground truth."""

from __future__ import annotations

import heapq
import os
import sys
import time
from collections.abc import Callable, Sequence
from typing import TextIO

from optrack import __version__
from optrack.params import Params
from optrack.recording import RecordingWriter
from optrack.sim.world import Simulation

__all__ = ["ProgressBar", "write_recording"]


class ProgressBar:
    """A one-line progress bar on a text stream (stderr), redrawn at most every
    ``interval`` seconds."""

    def __init__(
        self, label: str, total: int, stream: TextIO | None = None, interval: float = 0.25
    ) -> None:
        self.label, self.total = label, max(total, 1)
        self.stream = stream if stream is not None else sys.stderr
        self.interval = interval
        self.started = time.perf_counter()
        self._last = -float("inf")
        self.done = 0

    def update(self, done: int) -> None:
        self.done = done
        now = time.perf_counter()
        if now - self._last < self.interval and done < self.total:
            return
        self._last = now
        width = 30
        filled = int(width * done / self.total)
        rate = done / max(now - self.started, 1e-9)
        self.stream.write(
            f"\r{self.label} [{'#' * filled}{'.' * (width - filled)}] {100 * done / self.total:3.0f}% "
            f"{done}/{self.total} frames, {rate:.1f} frames/s"
        )
        self.stream.flush()

    def close(self) -> None:
        self.update(self.done)
        self.stream.write("\n")
        self.stream.flush()


def write_recording(
    sim: Simulation,
    path: str | os.PathLike[str],
    *,
    noise: bool = True,
    progress: Callable[[int, int], None] | None = None,
    params: Params | None = None,
    instants: Sequence[float] | None = None,
) -> dict[str, int]:
    """Render every sensor's frames in time order into a new recording at ``path``,
    with ground truth at each capture instant; returns frames per sensor.

    Frames are rendered in the world at their true capture time; their
    timestamps are on each sensor's own clock (offset and jitter included).
    ``params`` are the ``recording`` stage's (image encodings). ``instants``
    (world seconds) keeps only each sensor's frame nearest to each of them: a
    short recording of chosen moments (tests, quick checks).
    """
    counts = [sim.frame_count(k) for k in range(len(sim.sensors))]
    wanted: list[list[int]] | None = None
    if instants is not None:
        wanted = []
        for k, sensor in enumerate(sim.sensors):
            chosen = {int(round((t - sensor.phase) * sensor.model.fps)) for t in instants} & set(
                range(counts[k])
            )
            wanted.append(sorted(chosen))
        counts = [len(w) for w in wanted]
    total = sum(counts)

    def number(k: int, i: int) -> int:
        return wanted[k][i] if wanted is not None else i

    extra = {
        "scenario": sim.scenario.name,
        "scenario_file": sim.scenario.source,
        "seed": sim.seed,
        "seconds": sim.seconds,
        "people": len(sim.crowd.people),
        "clock_offsets": {s.id: s.clock_offset for s in sim.sensors},
        "optrack": __version__,
    }
    schedule = [
        (sim.sensors[k].frame_time(number(k, 0)), k, 0)
        for k in range(len(sim.sensors))
        if counts[k] > 0
    ]
    heapq.heapify(schedule)
    done = 0
    with RecordingWriter(
        path,
        [s.info for s in sim.sensors],
        ground_truth=True,
        source="optrack sim",
        extra=extra,
        params=params,
    ) as writer:
        state, state_t = None, None
        while schedule:
            t, k, i = heapq.heappop(schedule)
            if state_t != t:
                state, state_t = sim.snapshot(t), t
                writer.write_ground_truth(sim.truth(state))
            writer.write(sim.frame(k, number(k, i), state, noise=noise))
            done += 1
            if progress is not None:
                progress(done, total)
            if i + 1 < counts[k]:
                heapq.heappush(schedule, (sim.sensors[k].frame_time(number(k, i + 1)), k, i + 1))
    return writer.frame_counts
