"""What each simulated person does: the behaviours that pick where they go.

A behaviour returns the person's next goal (or None to stand) and may face a
direction; the crowd (optrack/sim/crowd.py) moves people towards their goals
with the social force model.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from optrack.sim.crowd import Crowd

__all__ = ["Behaviour", "EnterLeave", "Follow", "Route", "Stand", "Wander"]


class Behaviour:
    """Decides where one person goes. ``goal`` returns (goal xy or None, speed m/s);
    None means stand where you are. Behaviours may face a direction and hold things."""

    def start(self, crowd: Crowd, i: int) -> np.ndarray:
        """Start position of person i (people before i are already placed)."""
        return crowd.random_free_point(crowd.params.start_spacing, crowd.pos[:i])

    def present(self, crowd: Crowd, i: int, t: float) -> bool:
        return True

    def goal(self, crowd: Crowd, i: int, t: float) -> tuple[np.ndarray | None, float]:
        return None, 0.0

    def facing(self, crowd: Crowd, i: int, t: float) -> float | None:
        """A heading to turn to while standing (None: keep the current one)."""
        return None

    def anchored(self, crowd: Crowd, i: int, t: float) -> bool:
        """True while the person stands firm where they are (handling something): no
        social force moves them. Standing people otherwise drift away from walls."""
        return False

    def wrists(self, crowd: Crowd, i: int, t: float) -> np.ndarray | None:
        """(2, 3) world points the wrists should reach, or None for a free gait."""
        return None


class Wander(Behaviour):
    """Random goals in the area, with pauses; picks a new goal when stuck."""

    def __init__(self) -> None:
        self.target: np.ndarray | None = None
        self.pause_until = -1.0
        self.best = math.inf
        self.best_t = 0.0

    def goal(self, crowd: Crowd, i: int, t: float) -> tuple[np.ndarray | None, float]:
        p = crowd.params
        if t < self.pause_until:
            return None, 0.0
        position = crowd.pos[i]
        if self.target is None:
            self._new(crowd, t)
        dist = float(np.linalg.norm(self.target - position))
        if dist < p.arrive_radius:
            if crowd.rng.random() < p.pause_probability:
                self.pause_until = t + crowd.rng.uniform(p.pause_min, p.pause_max)
            self._new(crowd, t)
            return None, 0.0
        if dist < self.best - p.progress:
            self.best, self.best_t = dist, t
        elif t - self.best_t > p.stuck_seconds:
            self._new(crowd, t)
        return self.target, crowd.people[i].speed

    def _new(self, crowd: Crowd, t: float) -> None:
        self.target = crowd.random_free_point()
        self.best, self.best_t = math.inf, t


class Route(Behaviour):
    """Walk through waypoints in a loop (or back and forth)."""

    def __init__(self, points: np.ndarray, start_at: int = 0) -> None:
        self.points = np.asarray(points, dtype=np.float64)
        self.next = (start_at + 1) % len(self.points)
        self.start_at = start_at
        self.best = math.inf
        self.best_t = 0.0

    def start(self, crowd: Crowd, i: int) -> np.ndarray:
        return self.points[self.start_at].copy()

    def goal(self, crowd: Crowd, i: int, t: float) -> tuple[np.ndarray | None, float]:
        p = crowd.params
        target = self.points[self.next]
        dist = float(np.linalg.norm(target - crowd.pos[i]))
        stuck = dist >= self.best - p.progress and t - self.best_t > p.stuck_seconds
        if dist < self.best - p.progress:
            self.best, self.best_t = dist, t
        if dist < p.arrive_radius or stuck:
            self.next = (self.next + 1) % len(self.points)
            self.best, self.best_t = math.inf, t
            target = self.points[self.next]
        return target, crowd.people[i].speed


class Stand(Behaviour):
    """Stand at a spot, facing a direction (people standing still, talking)."""

    def __init__(self, spot: np.ndarray, heading: float) -> None:
        self.spot = np.asarray(spot, dtype=np.float64)
        self.heading = heading

    def start(self, crowd: Crowd, i: int) -> np.ndarray:
        return self.spot.copy()

    def goal(self, crowd: Crowd, i: int, t: float) -> tuple[np.ndarray | None, float]:
        if np.linalg.norm(crowd.pos[i] - self.spot) > crowd.params.arrive_radius:
            return self.spot, crowd.people[i].speed * crowd.params.return_speed_factor
        return None, 0.0

    def facing(self, crowd: Crowd, i: int, t: float) -> float | None:
        return self.heading


class Follow(Behaviour):
    """Walk beside a group's leader, at an offset in the leader's frame."""

    def __init__(self, leader: int, offset: np.ndarray) -> None:
        self.leader = leader
        self.offset = np.asarray(offset, dtype=np.float64)

    def start(self, crowd: Crowd, i: int) -> np.ndarray:
        point = crowd.pos[self.leader] + self.offset
        return (
            point
            if crowd.venue.is_free(point[None], crowd.params.body_radius)[0]
            else crowd.pos[self.leader] + 0.5 * self.offset
        )

    def present(self, crowd: Crowd, i: int, t: float) -> bool:
        return bool(crowd.present[self.leader])

    def goal(self, crowd: Crowd, i: int, t: float) -> tuple[np.ndarray | None, float]:
        heading = crowd.heading[self.leader]
        c, s = math.cos(heading), math.sin(heading)
        target = crowd.pos[self.leader] + np.array(
            [c * self.offset[0] - s * self.offset[1], s * self.offset[0] + c * self.offset[1]]
        )
        dist = float(np.linalg.norm(target - crowd.pos[i]))
        leader_speed = float(np.linalg.norm(crowd.vel[self.leader]))
        if dist < crowd.params.arrive_radius and leader_speed < crowd.params.still_speed:
            return None, 0.0
        speed = max(leader_speed, crowd.people[i].speed * min(1.0, dist))
        return target, speed

    def facing(self, crowd: Crowd, i: int, t: float) -> float | None:
        return float(crowd.heading[self.leader])


class EnterLeave(Behaviour):
    """Come in through a door at ``enter``, wander, leave through a door after ``leave``."""

    def __init__(self, door: np.ndarray, enter: float, leave: float) -> None:
        self.door = np.asarray(door, dtype=np.float64)
        self.enter, self.leave = enter, leave
        self.gone = False
        self.wander = Wander()

    def start(self, crowd: Crowd, i: int) -> np.ndarray:
        return self.door.copy()

    def present(self, crowd: Crowd, i: int, t: float) -> bool:
        return self.enter <= t and not self.gone

    def goal(self, crowd: Crowd, i: int, t: float) -> tuple[np.ndarray | None, float]:
        if t < self.leave:
            return self.wander.goal(crowd, i, t)
        if np.linalg.norm(crowd.pos[i] - self.door) < crowd.params.arrive_radius:
            self.gone = True
            return None, 0.0
        return self.door, crowd.people[i].speed
