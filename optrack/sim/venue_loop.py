"""A venue that closes its loop: each loop ends in the state it began in.

A live simulated venue that loops (``sim://...&loop=true``: the embedded venue of
``optrack run``) starts again from its beginning every ``seconds``, forwards, on every
sensor that shares its clock. So that the new loop takes up where the last one ended,
without anyone jumping, :func:`close_loop` makes the venue end as it began:

- in the loop's last :data:`LOOP_CLOSE` ``return_s`` seconds, everyone who was there at
  its start walks back to the spot where they started (the social force model still
  steers them round furniture and each other) and turns to the way they faced then;
- they arrive before the last ``settle_s`` seconds and stand there, so that their walk
  fades out (gait amplitude to rest), as it was at the start;
- whoever came in later (enter and leave) heads for their door at the latest 5 % of
  the loop before the return begins, and is gone by its end;
- a loop's length is a multiple of ``sway_period_s``, the period of a standing person's
  sway, so the sway goes on through the loop's end too.

A restarted node joins the loop where the clock is, stepping the crowd from the loop's
start (a loop short enough to keep that to seconds: ``LIVE_LOOP_S`` of
:mod:`optrack.runtime.venue`). :func:`loop_seam` measures how far the end of a loop is
from its start (docs/runtime.md gives the figures).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from optrack.sim.behaviours import Behaviour, EnterLeave

if TYPE_CHECKING:
    from optrack.sim.crowd import Crowd
    from optrack.sim.world import Simulation

__all__ = ["LOOP_CLOSE", "ClosingLoop", "close_loop", "loop_seam"]

#: How a loop closes: the return starts ``return_s`` before its end (at most
#: ``return_share`` of the loop), people stand still for its last ``settle_s`` (at most
#: ``settle_share``); a standing person's sway repeats every ``sway_period_s``
#: (optrack.sim.crowd: sin(pi t / 2)).
LOOP_CLOSE = {
    "return_s": 30.0,
    "return_share": 0.25,
    "settle_s": 8.0,
    "settle_share": 0.05,
    "sway_period_s": 4.0,
}


class ClosingLoop(Behaviour):
    """A person's own behaviour until ``back_at``, then back to where they were at the
    loop's start, facing the way they faced (see the module docstring). From
    ``settle_at`` on they stand firm (no social force moves them) and step the last
    centimetres the forces left (people and walls push a standing person off their spot)
    onto it, in the first half of what is left of the loop."""

    def __init__(self, inner: Behaviour, back_at: float, settle_at: float, end: float) -> None:
        self.inner = inner
        self.back_at, self.settle_at, self.end = back_at, settle_at, end
        self.home: np.ndarray | None = None  # None: not there at the loop's start
        self.home_heading = 0.0
        self._settle_from: np.ndarray | None = None

    def _closing(self, t: float) -> bool:
        return self.home is not None and t >= self.back_at

    def start(self, crowd: Crowd, i: int) -> np.ndarray:
        return self.inner.start(crowd, i)

    def present(self, crowd: Crowd, i: int, t: float) -> bool:
        return self.inner.present(crowd, i, t)

    def goal(self, crowd: Crowd, i: int, t: float) -> tuple[np.ndarray | None, float]:
        dt = float(crowd.params.time_step)
        if t < dt / 2:  # the loop's first step: where the person starts
            self.home = crowd.pos[i].copy()
            self.home_heading = float(crowd.heading[i])
        if not self._closing(t):
            return self.inner.goal(crowd, i, t)
        if t < self.settle_at:
            return self.home, crowd.people[i].speed
        if self._settle_from is None:
            self._settle_from = crowd.pos[i].copy()
        # Where the person is at the end of this step: onto the spot, smoothly.
        u = min(1.0, (t + dt - self.settle_at) / max((self.end - self.settle_at) / 2, dt))
        crowd.pos[i] = self._settle_from + (self.home - self._settle_from) * (u * u * (3 - 2 * u))
        return None, 0.0

    def facing(self, crowd: Crowd, i: int, t: float) -> float | None:
        if self._closing(t):
            return self.home_heading
        return self.inner.facing(crowd, i, t)

    def anchored(self, crowd: Crowd, i: int, t: float) -> bool:
        if self._closing(t):
            return t >= self.settle_at
        return self.inner.anchored(crowd, i, t)

    def wrists(self, crowd: Crowd, i: int, t: float) -> np.ndarray | None:
        return self.inner.wrists(crowd, i, t)


def close_loop(sim: Simulation) -> Simulation:
    """``sim`` with every person's behaviour closing its loop of ``sim.seconds`` (see the
    module docstring); returns ``sim``."""
    seconds = float(sim.seconds)
    back_at = seconds - min(LOOP_CLOSE["return_s"], LOOP_CLOSE["return_share"] * seconds)
    settle_at = seconds - min(LOOP_CLOSE["settle_s"], LOOP_CLOSE["settle_share"] * seconds)
    for person in sim.crowd.people:
        inner = person.behaviour
        if isinstance(inner, EnterLeave):  # gone before the others turn back
            inner.leave = min(inner.leave, max(inner.enter, back_at - seconds * 0.05))
        person.behaviour = ClosingLoop(inner, back_at, settle_at, seconds)
    return sim


def loop_seam(sim: Simulation) -> dict[str, float]:
    """How far the end of ``sim``'s loop is from its start: the largest distance between
    where a person is at the loop's last step and where they were at its start (m), and
    likewise heading (deg), gait amplitude and speed (m/s); people present at one end
    only count as ``missing``; ``settled_m``: the longest last step onto a spot (what
    the social forces left between a returning person and their spot)."""
    dt = float(sim.crowd.params.time_step)
    first = sim.crowd.state(0.0)
    start = {int(k): j for j, k in enumerate(first.ids)}
    pose0 = first.pose
    end_t = math.floor(sim.seconds / dt - 1e-9) * dt
    sim.crowd.advance(end_t)
    last = sim.crowd.state(end_t)
    end = {int(k): j for j, k in enumerate(last.ids)}
    seam = {"position_m": 0.0, "heading_deg": 0.0, "amplitude": 0.0, "speed_m_s": 0.0}
    for k in set(start) & set(end):
        a, b = start[k], end[k]
        seam["position_m"] = max(
            seam["position_m"], math.hypot(pose0.x[a] - last.pose.x[b], pose0.y[a] - last.pose.y[b])
        )
        turn = (last.pose.heading[b] - pose0.heading[a] + math.pi) % (2 * math.pi) - math.pi
        seam["heading_deg"] = max(seam["heading_deg"], abs(math.degrees(turn)))
        seam["amplitude"] = max(seam["amplitude"], float(last.pose.amplitude[b]))
        i = int(last.index[b])
        seam["speed_m_s"] = max(seam["speed_m_s"], float(np.linalg.norm(sim.crowd.vel[i])))
    seam["missing"] = float(len(set(start) ^ set(end)))
    stepped = [
        float(np.linalg.norm(b.home - b._settle_from))
        for b in (person.behaviour for person in sim.crowd.people)
        if isinstance(b, ClosingLoop) and b.home is not None and b._settle_from is not None
    ]
    seam["settled_m"] = max(stepped, default=0.0)
    return seam
