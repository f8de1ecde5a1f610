"""The still-board rule: which sensors saw the checkerboard at one and the same pose.

A sensor's search of one of its images finds the board's corners or not. Two
consecutive finds of one sensor, at most ``max_gap_s`` apart, whose corners
moved less than ``max_motion_px`` (RMS) show the board held still in that
sensor over the interval between them, ``(previous find, this find]``.
Sensors whose still intervals share a moment saw the same board pose: one
:class:`StillBoard` for :meth:`NetworkCalibrator.add`, its floor flag the
majority of the sensors' floor tests. A sensor is in a still board once (a
later still interval of it that reaches into the same board is the same pose
again). A still board is ready once no sensor can join it any more: every
other sensor has searched an image after its end, and no find of theirs
before its end is waiting for a partner (or ``max_gap_s`` has passed since).

The one rule serves both readers of board views:

* a recording (``optrack calibrate network``, :mod:`optrack.calibration.session`):
  every sensor's image of one time bin is searched and stamped with the bin's
  time, so each bin makes one still board of the sensors that held it still
  since the previous bin;
* a running site (the wizard, :mod:`optrack.calibration.live`): each node
  searches a few images per second at its own instants, so fixed bins would
  rarely hold two sensors at once; overlapping still intervals do.

``max_motion_px`` 0 turns the stillness check off: every find counts, still
since the sensor's previous search.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable

import numpy as np

__all__ = ["StillBoard", "StillBoards", "corner_motion_px"]


def corner_motion_px(corners: np.ndarray, before: np.ndarray) -> float:
    """RMS distance (px) between two sets of the same corners."""
    return float(np.sqrt(np.mean(np.sum((corners - before) ** 2, axis=1))))


@dataclasses.dataclass
class StillBoard:
    """Sensors that saw the board held still over intervals sharing ``(start, end]``."""

    start: float
    end: float
    corners: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    floor_votes: dict[str, bool] = dataclasses.field(default_factory=dict)

    def on_floor(self, sensors: Iterable[str] | None = None) -> bool:
        """The majority of the floor tests (of ``sensors`` only, when given)."""
        chosen = None if sensors is None else set(sensors)
        votes = [v for s, v in self.floor_votes.items() if chosen is None or s in chosen]
        return bool(votes) and sum(votes) * 2 > len(votes)


class StillBoards:
    """Groups the board views of ``sensors`` into still boards (see the module docstring).

    Feed every search, found or not, in each sensor's time order with :meth:`add`; take
    the still boards no sensor can join any more, oldest first, with :meth:`ready`.
    """

    def __init__(
        self, sensors: Iterable[str], max_motion_px: float, max_gap_s: float = math.inf
    ) -> None:
        self.sensors = list(sensors)
        self.max_motion_px = float(max_motion_px)
        self.max_gap_s = float(max_gap_s)
        self.open: list[StillBoard] = []
        self._found: dict[str, tuple[float, np.ndarray]] = {}  # each sensor's last find
        self._latest: dict[str, float] = {}  # each sensor's newest search
        self._newest = -math.inf

    def clear(self) -> None:
        """Forget every view (a new capture starts)."""
        self.open.clear()
        self._found.clear()
        self._latest.clear()
        self._newest = -math.inf

    def add(
        self,
        sensor: str,
        stamp: float,
        corners: np.ndarray | None,
        on_floor: bool | None = None,
    ) -> None:
        """One search of ``sensor`` at ``stamp``: the corners found (None: no board) and,
        when the sensor could tell, whether the board lay on the floor."""
        searched = self._latest.get(sensor)
        self._latest[sensor] = stamp if searched is None else max(searched, stamp)
        self._newest = max(self._newest, stamp)
        if corners is None:
            self._found.pop(sensor, None)
            return
        previous = self._found.get(sensor)
        self._found[sensor] = (stamp, corners)
        if self.max_motion_px > 0:
            if previous is None or not 0 < stamp - previous[0] <= self.max_gap_s:
                return
            if corner_motion_px(corners, previous[1]) > self.max_motion_px:
                return
            start = previous[0]
        else:  # no stillness check: still since the sensor last looked
            start = max(-math.inf if searched is None else searched, stamp - self.max_gap_s)
        self._join(sensor, start, stamp, corners, on_floor)

    def _join(
        self, sensor: str, start: float, end: float, corners: np.ndarray, on_floor: bool | None
    ) -> None:
        overlapping = [b for b in self.open if b.start < end and start < b.end]
        if any(sensor in b.corners for b in overlapping):
            return  # the same board pose as a still board this sensor is already in
        if overlapping:
            board = overlapping[0]
            board.start, board.end = max(board.start, start), min(board.end, end)
        else:
            board = StillBoard(start, end)
            self.open.append(board)
        board.corners[sensor] = corners
        if on_floor is not None:
            board.floor_votes[sensor] = bool(on_floor)

    def _waiting(self, board: StillBoard) -> bool:
        """Whether a sensor not in ``board`` may still join it."""
        for sensor in self.sensors:
            if sensor in board.corners:
                continue
            if self._latest.get(sensor, -math.inf) < board.end:
                return True
            found = self._found.get(sensor)
            if found is not None and found[0] < board.end:
                return True
        return False

    def ready(self, final: bool = False) -> list[StillBoard]:
        """Take the still boards that no sensor can join any more (all when ``final``),
        oldest first."""
        done = [
            b
            for b in self.open
            if final or self._newest - b.end > self.max_gap_s or not self._waiting(b)
        ]
        for board in done:
            self.open.remove(board)
        return sorted(done, key=lambda b: b.end)
