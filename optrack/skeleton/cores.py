"""How many CPU threads the skeleton's kernels share their particles among when the
``threads`` parameter is 0 (auto): this process's cores that no other process keeps busy.

Two threads on two cores make a person's frame about 1.4 times faster when the second
core is idle (the kernels 1.3-2 times, by the minute on a virtual machine; the rest of a
frame is one thread); when
another process keeps that core busy, each of a frame's parallel regions waits for the
thread the system has put aside, and a frame is several times slower. So the cores' use
is sampled (Linux's /proc/stat, every ``period`` seconds at most): what the whole machine
spent less what this process spent is what the others keep busy; a core counts as spare
when the others leave at least 70 % of it free. Without /proc/stat: one thread, said once
in the log.
"""

from __future__ import annotations

import logging
import os
import time

import numba

__all__ = ["SpareCores", "auto_threads"]

log = logging.getLogger("optrack.skeleton")

# A core counts as spare when the other processes use less than this share of it.
_BUSY_SHARE = 0.3


def _usable_cores() -> int:
    """The cores this process may run on, at most numba's thread pool."""
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cores = os.cpu_count() or 1
    return max(1, min(cores, int(numba.config.NUMBA_NUM_THREADS)))


class SpareCores:
    """Threads for this process's kernels: 1 plus the cores the other processes leave
    free (see the module docstring). ``stat``: the file of the machine's CPU times (the
    first line of Linux's /proc/stat); ``period``: seconds between two samples."""

    def __init__(self, period: float = 0.5, stat: str = "/proc/stat") -> None:
        self.period = float(period)
        self.stat = stat
        self.threads = 1
        self.others = 0.0  # cores the other processes kept busy over the last period
        self._last: tuple[float, float, float] | None = None  # wall, machine busy, own
        self._unreadable = False  # the CPU times could not be read: one thread from then on
        self._tick = float(os.sysconf("SC_CLK_TCK")) if hasattr(os, "sysconf") else 100.0

    def _machine_busy(self) -> float:
        """CPU seconds the whole machine has spent not idle (every core) since boot."""
        with open(self.stat, encoding="ascii") as f:
            fields = f.readline().split()
        if not fields or fields[0] != "cpu":
            raise ValueError(f"{self.stat} does not start with the machine's CPU times")
        # user nice system idle iowait irq softirq steal (guest time is within user)
        user, nice, system, _, _, irq, softirq, steal = (float(v) for v in fields[1:9])
        return (user + nice + system + irq + softirq + steal) / self._tick

    def __call__(self) -> int:
        """The threads to use now (sampled again once ``period`` has passed)."""
        if self._unreadable:
            return 1
        wall = time.monotonic()
        if self._last is not None and wall - self._last[0] < self.period:
            return self.threads
        own = time.process_time()
        try:
            busy = self._machine_busy()
        except (OSError, ValueError, IndexError) as error:
            log.info(
                "The skeleton's auto threads could not read the CPU times (%s); it uses one "
                "thread (set skeleton.threads to use more).",
                error,
            )
            self._unreadable, self.threads = True, 1
            return 1
        if self._last is not None:
            spent = wall - self._last[0]
            self.others = max(0.0, (busy - self._last[1]) - (own - self._last[2])) / spent
            cores = _usable_cores()
            spare = cores - 1 - self.others
            self.threads = max(1, min(cores, 1 + int(spare + _BUSY_SHARE)))
        self._last = (wall, busy, own)
        return self.threads


_SPARE = SpareCores()


def auto_threads() -> int:
    """This process's :class:`SpareCores` now."""
    return _SPARE()
