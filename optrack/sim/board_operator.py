"""The simulated person who carries the checkerboard through its planned placements.

Between placements the board is carried in front of the chest; at each one
the operator stops, turns, raises the board (or lays it on the floor), holds
it still with a slight hand tremor, and moves on (:mod:`optrack.sim.board_plan`
plans the placements; :data:`~optrack.sim.board.BOARD_PARAMS` times them).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from optrack.geometry import make_pose, transform_points
from optrack.sim.board import PhysicalBoard
from optrack.sim.board_plan import BoardStep, board_pose_facing
from optrack.sim.crowd import Behaviour, Crowd

__all__ = ["Operator"]

PROGRESS = 0.1  # m: walking nearer by less than this is no progress
TREMOR = ((3.1, 0.0), (2.3, 1.0), (1.7, 2.0))  # rad/s and phase of the hand tremor per axis
TURN_SECONDS = 1.5  # planning allowance for starting, stopping and turning at a spot


class Operator(Behaviour):
    """The person carrying the board through its :class:`BoardStep` placements."""

    def __init__(self, steps: list[BoardStep], board: PhysicalBoard, start: np.ndarray) -> None:
        self.steps = steps
        self.board = board
        self.params = board.params
        self.start_point = np.asarray(start, dtype=np.float64)
        self.index = 0
        self.phase = "walk"
        self.phase_start = 0.0
        self.from_pose: np.ndarray | None = None
        self.pose_now: np.ndarray | None = None
        self.on_floor = False
        self.best, self.best_t = math.inf, 0.0

    def start(self, crowd: Crowd, i: int) -> np.ndarray:
        return self.start_point.copy()

    @property
    def done(self) -> bool:
        return self.index >= len(self.steps)

    def _carry_pose(self, crowd: Crowd, i: int) -> np.ndarray:
        heading = crowd.heading[i]
        forward = np.array([math.cos(heading), math.sin(heading), 0.0])
        center = (
            np.append(crowd.pos[i], self.params.carry_height) + self.params.carry_distance * forward
        )
        return board_pose_facing(center, forward, self.board)

    def goal(self, crowd: Crowd, i: int, t: float) -> tuple[np.ndarray | None, float]:
        p = self.params
        speed = float(p.operator_speed)
        if self.done:
            self.pose_now = self._carry_pose(crowd, i) if not self.on_floor else self.pose_now
            return None, 0.0
        step = self.steps[self.index]
        elapsed = t - self.phase_start
        if self.phase == "walk":
            self.pose_now = self._carry_pose(crowd, i)
            distance = float(np.linalg.norm(crowd.pos[i] - step.operator_spot))
            if distance < self.best - PROGRESS:
                self.best, self.best_t = distance, t
            stuck = t - self.best_t > crowd.params.stuck_seconds
            if distance < crowd.params.arrive_radius or stuck:
                self._enter("lay" if step.kind == "floor" else "raise", t, self.pose_now)
                return None, 0.0
            return step.operator_spot, speed
        if self.phase in ("raise", "lay"):
            duration = p.raise_seconds if self.phase == "raise" else p.lay_seconds
            self.pose_now = _interpolate(
                self.from_pose, step.world_T_board, min(elapsed / duration, 1.0)
            )
            if elapsed >= duration:
                self.on_floor = step.kind == "floor"
                self._enter("hold", t, step.world_T_board)
            return None, 0.0
        if self.phase == "hold":
            sway = p.sway_m * np.array([math.sin(rate * t + phase) for rate, phase in TREMOR])
            self.pose_now = step.world_T_board.copy()
            if not self.on_floor:
                self.pose_now[:3, 3] += sway
            if elapsed >= p.hold_seconds:
                if step.kind == "floor":
                    self._enter("pickup", t, step.world_T_board)
                else:
                    self._next(t)
            return None, 0.0
        if self.phase == "pickup":
            self.on_floor = False
            target = self._carry_pose(crowd, i)
            self.pose_now = _interpolate(self.from_pose, target, min(elapsed / p.lay_seconds, 1.0))
            if elapsed >= p.lay_seconds:
                self._next(t)
            return None, 0.0
        return None, 0.0

    def _enter(self, phase: str, t: float, pose: np.ndarray | None) -> None:
        self.best, self.best_t = math.inf, t
        self.phase, self.phase_start, self.from_pose = (
            phase,
            t,
            None if pose is None else pose.copy(),
        )

    def _next(self, t: float) -> None:
        self.index += 1
        self._enter("walk", t, None)

    def anchored(self, crowd: Crowd, i: int, t: float) -> bool:
        """Standing firm while raising, holding, laying or picking up the board."""
        return not self.done and self.phase != "walk"

    def facing(self, crowd: Crowd, i: int, t: float) -> float | None:
        if self.done:
            return None
        return self.steps[self.index].operator_heading if self.phase != "walk" else None

    def wrists(self, crowd: Crowd, i: int, t: float) -> np.ndarray | None:
        if self.pose_now is None or self.on_floor or self.phase in ("lay", "pickup"):
            return None
        # Hands grip the side edges from behind the board, clear of the printed face.
        mid = (self.board.lo[1] + self.board.hi[1]) / 2
        behind = float(self.params.thickness + self.params.grip_depth)
        edges = np.array([[self.board.hi[0], mid, behind], [self.board.lo[0], mid, behind]])
        return transform_points(self.pose_now, edges)

    def board_pose(self, crowd: Crowd, i: int) -> np.ndarray:
        """``world_T_board`` now (in the operator's hands before the first step)."""
        if self.pose_now is None:
            self.pose_now = self._carry_pose(crowd, i)
        return self.pose_now

    def planned_seconds(self, start: np.ndarray) -> float:
        """A rough duration of the whole procedure (walking plus every phase)."""
        p, total, here = self.params, 0.0, np.asarray(start)
        for step in self.steps:
            total += np.linalg.norm(step.operator_spot - here) / p.operator_speed + TURN_SECONDS
            here = step.operator_spot
            total += p.hold_seconds + (
                p.raise_seconds if step.kind == "hold" else 2 * p.lay_seconds
            )
        return float(total)


def _interpolate(a: np.ndarray | None, b: np.ndarray, s: float) -> np.ndarray:
    if a is None:
        return b.copy()
    s = float(np.clip(s, 0.0, 1.0))
    slerp = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([a[:3, :3], b[:3, :3]])))
    return make_pose(slerp([s])[0], (1 - s) * a[:3, 3] + s * b[:3, 3])
