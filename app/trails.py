"""Each track's recent path and colour, shared by the top view and the 3D view.

This is display state (what was drawn), not tracking: the positions are the
tracker's own, kept for ``trail_seconds``.
"""

from __future__ import annotations

import bisect
from collections import deque

import numpy as np

from optrack.types import TrackBatch

__all__ = ["TrailHistory", "track_color"]

# Tableau 10: distinct on both the dark 3D background and the light top view.
_PALETTE = (
    (78, 121, 167),
    (242, 142, 43),
    (225, 87, 89),
    (118, 183, 178),
    (89, 161, 79),
    (237, 201, 72),
    (176, 122, 161),
    (255, 157, 167),
    (156, 117, 95),
    (186, 176, 172),
)


def track_color(track_id: int) -> tuple[int, int, int]:
    """The colour a track is drawn in (the same in every view), RGB 0-255."""
    return _PALETTE[track_id % len(_PALETTE)]


#: A batch stamped this much before the newest one means the site's time went back (a
#: replay restarted); less is the usual order of frames from several sensors.
RESTART_S = 1.0


class TrailHistory:
    """The last ``seconds`` of each track's (x, y), by track id, in stamp order."""

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds
        self._points: dict[int, deque[tuple[float, float, float]]] = {}
        self._last_stamp: float | None = None

    def update(self, batch: TrackBatch) -> None:
        if self._last_stamp is not None and batch.stamp < self._last_stamp - RESTART_S:
            self._points.clear()  # time went back: a replay restarted
            self._last_stamp = None
        newest = batch.stamp if self._last_stamp is None else max(self._last_stamp, batch.stamp)
        self._last_stamp = newest
        for track in batch.tracks:
            points = self._points.setdefault(track.id, deque())
            point = (batch.stamp, track.x, track.y)
            if points and batch.stamp < points[-1][0]:  # another sensor's earlier frame
                points.insert(bisect.bisect(points, batch.stamp, key=lambda p: p[0]), point)
            else:
                points.append(point)
        oldest = newest - self.seconds
        for track_id in list(self._points):
            points = self._points[track_id]
            while points and points[0][0] < oldest:
                points.popleft()
            if not points:
                del self._points[track_id]

    def ids(self) -> list[int]:
        return sorted(self._points)

    def trail(self, track_id: int) -> np.ndarray:
        """Nx2 (x, y) world points, oldest first; empty when the id has no trail."""
        points = self._points.get(track_id)
        if not points:
            return np.zeros((0, 2))
        return np.array([(x, y) for _, x, y in points], dtype=np.float64)

    def clear(self) -> None:
        self._points.clear()
        self._last_stamp = None
