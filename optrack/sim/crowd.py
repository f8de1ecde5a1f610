"""People moving through the venue: behaviours and the social force model.

Each person has a behaviour that picks where to go (wander to random goals
with pauses, follow a route, stand, walk with a group, enter through a door
and later leave through it, or carry the calibration board). Collision
avoidance is the social force model of D. Helbing and P. Molnar, "Social
force model for pedestrian dynamics", Phys. Rev. E 51 (1995): a driving
term relaxes the velocity towards the desired one in ``relax_time``, and
people and obstacles repel with exponentially decaying forces; people react
more to what is ahead of them (weight ``lambda + (1 - lambda)(1 + cos phi)/2``).

The state advances in fixed time steps from a seeded generator, so the same
seed gives the same motion in every process that simulates the venue.
"""

from __future__ import annotations

import colorsys
import dataclasses
import math

import numpy as np

from optrack.params import Params
from optrack.sim.behaviours import Behaviour, EnterLeave, Follow, Route, Stand, Wander
from optrack.sim.body import BODY_PARAMS, MATERIALS_PER_PERSON, MAX_GAIT_AMPLITUDE, BodyPose
from optrack.sim.crowd_params import CROWD_PARAMS
from optrack.sim.materials import Material
from optrack.sim.scenario import PeopleSpec
from optrack.sim.venue import Venue

__all__ = ["CROWD_PARAMS", "Behaviour", "Crowd", "CrowdState", "Person"]

CROSSING_TRIES = 50  # random orientations tried for a crossing pair's routes
SKIN_TONES = (
    (0.93, 0.76, 0.64),
    (0.85, 0.64, 0.5),
    (0.72, 0.52, 0.38),
    (0.55, 0.37, 0.25),
    (0.36, 0.24, 0.17),
)
HAIR_COLORS = (
    (0.1, 0.08, 0.06),
    (0.3, 0.2, 0.12),
    (0.55, 0.4, 0.25),
    (0.8, 0.7, 0.45),
    (0.6, 0.6, 0.6),
)
TROUSER_COLORS = (
    (0.15, 0.2, 0.35),
    (0.1, 0.1, 0.1),
    (0.4, 0.4, 0.42),
    (0.7, 0.62, 0.48),
    (0.25, 0.3, 0.2),
)
SHOE_COLOR = (0.12, 0.11, 0.1)
# Near-infrared albedos: skin reflects well at ~850 nm, hair and shoes poorly; fabric varies.
SKIN_INFRARED, HAIR_INFRARED, SHOE_INFRARED = 0.55, 0.25, 0.2
SHIRT_INFRARED, TROUSER_INFRARED = (0.25, 0.85), (0.2, 0.7)
SHIRT_SATURATION, SHIRT_VALUE, TROUSER_SHADE = (0.3, 0.9), (0.25, 0.95), (0.8, 1.2)


@dataclasses.dataclass
class Person:
    id: int
    height: float
    speed: float
    materials: list[Material]
    behaviour: Behaviour
    child: bool = False


@dataclasses.dataclass
class CrowdState:
    """The present people at one instant (arrays over present people, in id order)."""

    t: float
    ids: np.ndarray
    index: np.ndarray  # index of each present person in Crowd.people
    pose: BodyPose


# ------------------------------------------------------------------ the crowd


class Crowd:
    """Everyone in the venue, stepped with the social force model."""

    def __init__(
        self,
        venue: Venue,
        rng: np.random.Generator,
        params: Params | None = None,
        body_params: Params | None = None,
    ) -> None:
        self.venue = venue
        self.rng = rng
        self.params = params if params is not None else CROWD_PARAMS.create()
        self.body_params = body_params if body_params is not None else BODY_PARAMS.create()
        self.people: list[Person] = []
        self.area = np.array([-venue.half[0], -venue.half[1], venue.half[0], venue.half[1]])
        self.t = 0.0
        self.duration = 0.0
        self._started = False

    # ------------------------------------------------------------ building
    def add(self, behaviour: Behaviour, *, child: bool = False, height: float | None = None) -> int:
        """Add a person; returns their index (also their id)."""
        p = self.params
        if height is None:
            if child:
                height = self.rng.uniform(p.child_height_min, p.child_height_max)
            else:
                height = float(
                    np.clip(
                        self.rng.normal(p.adult_height_mean, p.adult_height_std),
                        p.adult_height_min,
                        p.adult_height_max,
                    )
                )
        speed = self.rng.uniform(p.speed_min, p.speed_max) * (
            p.child_speed_factor if child else 1.0
        )
        index = len(self.people)
        self.people.append(
            Person(index, float(height), float(speed), self._clothes(index), behaviour, child)
        )
        return index

    def _clothes(self, index: int) -> list[Material]:
        rng, texture = self.rng, float(self.params.clothes_texture)
        shirt = colorsys.hsv_to_rgb(
            rng.random(), rng.uniform(*SHIRT_SATURATION), rng.uniform(*SHIRT_VALUE)
        )
        trousers = np.clip(
            np.array(TROUSER_COLORS[rng.integers(len(TROUSER_COLORS))])
            * rng.uniform(*TROUSER_SHADE),
            0,
            1,
        )
        skin = SKIN_TONES[rng.integers(len(SKIN_TONES))]
        hair = HAIR_COLORS[rng.integers(len(HAIR_COLORS))]
        materials = [
            Material(f"skin{index}", skin, SKIN_INFRARED, texture / 3),
            Material(f"hair{index}", hair, HAIR_INFRARED, texture),
            Material(f"shirt{index}", tuple(shirt), float(rng.uniform(*SHIRT_INFRARED)), texture),
            Material(
                f"trousers{index}", tuple(trousers), float(rng.uniform(*TROUSER_INFRARED)), texture
            ),
            Material(f"shoes{index}", SHOE_COLOR, SHOE_INFRARED, texture),
        ]
        assert len(materials) == MATERIALS_PER_PERSON
        return materials

    def populate(self, spec: PeopleSpec, count: int, duration: float) -> None:
        """Add ``count`` people with the behaviours a scenario asks for, in the order:
        routes, standing, groups, crossing pairs, enter-and-leave, wanderers."""
        p = self.params
        self.duration = duration
        if spec.area is not None:
            self.area = np.asarray(spec.area, dtype=np.float64)
        rng = self.rng
        base = len(self.people)  # people added before (the board's operator)

        def added() -> int:
            return len(self.people) - base

        left = count

        def child() -> bool:
            return bool(rng.random() < spec.children)

        for route in spec.routes[:left]:
            self.add(Route(np.asarray(route)), child=child())
        left = count - added()
        for _ in range(min(spec.standing, left)):
            self.add(Stand(self.random_free_point(), rng.uniform(-math.pi, math.pi)), child=child())
        left = count - added()
        for size in spec.groups:
            if left < 2:
                break
            size = min(size, left)
            leader = self.add(Wander(), child=child())
            for k in range(1, size):
                side = 1 if k % 2 else -1
                offset = np.array(
                    [-(k // 2) * p.group_spacing, side * p.group_spacing * ((k + 1) // 2)]
                )
                self.add(Follow(leader, offset), child=child())
            left = count - added()
        for _ in range(spec.crossing):
            if left < 2:
                break
            center = np.array(
                [(self.area[0] + self.area[2]) / 2, (self.area[1] + self.area[3]) / 2]
            )
            reach = p.crossing_reach * min(self.area[2] - self.area[0], self.area[3] - self.area[1])
            # Two routes across the centre at about right angles, ends on free floor.
            best, best_clearance = None, -math.inf
            for _ in range(CROSSING_TRIES):
                angle = rng.uniform(0, math.pi)
                spread = math.radians(p.crossing_spread_deg)
                turn = math.pi / 2 + rng.uniform(-spread, spread)
                ends = [
                    reach * np.array([math.cos(angle + a), math.sin(angle + a)])
                    for a in (0.0, turn)
                ]
                points = np.array([center + e for e in ends] + [center - e for e in ends])
                clearance = float(self.venue.clearance(points).min())
                if clearance > best_clearance:
                    best, best_clearance = ends, clearance
                if clearance >= p.goal_clearance:
                    break
            for end in best:
                self.add(Route(np.array([center + end, center - end])), child=child())
            left = count - added()
        doors = self.venue.doors
        for k in range(min(spec.enter_leave, left)):
            door = doors[k % len(doors)]
            enter = rng.uniform(0.0, p.enter_window * duration)
            leave = rng.uniform(p.leave_after, p.leave_before) * duration
            self.add(EnterLeave(door, enter, max(leave, enter + p.min_stay)), child=child())
        left = count - added()
        for _ in range(left):
            self.add(Wander(), child=child())

    def random_free_point(
        self, spacing: float = 0.0, others: np.ndarray | None = None
    ) -> np.ndarray:
        """A random floor point in the area with free space around it and, when
        ``others`` are given, ``spacing`` metres from each of them (the best of a
        few hundred tries when no point qualifies)."""
        p = self.params
        x0, y0, x1, y1 = self.area
        best, best_score = None, -math.inf
        for _ in range(200):
            point = np.array([self.rng.uniform(x0, x1), self.rng.uniform(y0, y1)])
            clearance = float(self.venue.clearance(point[None])[0]) - p.goal_clearance
            apart = (
                float(np.min(np.linalg.norm(others - point, axis=1))) - spacing
                if others is not None and len(others)
                else 0.0
            )
            score = min(clearance, apart)
            if score >= 0:
                return point
            if score > best_score:
                best, best_score = point, score
        return best

    # ------------------------------------------------------------ stepping
    def _start(self) -> None:
        n = len(self.people)
        self.pos = np.zeros((n, 2))
        self.vel = np.zeros((n, 2))
        self.heading = np.zeros(n)
        self.phase = self.rng.uniform(0, 2 * math.pi, n)
        self.amp = np.zeros(n)
        self.present = np.zeros(n, dtype=bool)
        self.sway_phase = self.rng.uniform(0, 2 * math.pi, n)
        for i, person in enumerate(self.people):
            self.pos[i] = person.behaviour.start(self, i)
            self.heading[i] = self.rng.uniform(-math.pi, math.pi)
        for i, person in enumerate(self.people):
            self.present[i] = person.behaviour.present(self, i, 0.0)
            facing = person.behaviour.facing(self, i, 0.0)
            if facing is not None:
                self.heading[i] = facing
        here = np.flatnonzero(self.present)
        self.pos[here] = self._resolve(self.pos[here])
        self._started = True

    def _resolve(self, pos: np.ndarray) -> np.ndarray:
        """Hard constraints after the forces: people never overlap (pairs closer than
        ``min_separation`` are pushed apart equally) and never stand inside furniture or
        walls (pushed out along the nearest obstacle's normal)."""
        p = self.params
        pos = pos.copy()
        if len(pos) > 1:
            delta = pos[:, None, :] - pos[None, :, :]
            d = np.linalg.norm(delta, axis=2)
            np.fill_diagonal(d, np.inf)
            overlap = np.maximum(p.min_separation - d, 0.0)
            if overlap.any():
                away = delta / np.maximum(d, 1e-9)[..., None]
                pos += 0.5 * np.sum(overlap[..., None] * away, axis=1)
        distance, normal = self.venue.distances(pos)
        nearest = np.argmin(distance, axis=1)
        depth = p.body_radius * p.obstacle_overlap - distance[np.arange(len(pos)), nearest]
        inside = depth > 0
        pos[inside] += normal[np.flatnonzero(inside), nearest[inside]] * depth[inside, None]
        return pos

    def advance(self, t: float) -> None:
        """Step the simulation forward to time ``t`` (seconds; never backwards)."""
        if not self._started:
            self._start()
        dt = float(self.params.time_step)
        while self.t + dt <= t + 1e-9:
            self._step(dt)
            self.t += dt

    def _step(self, dt: float) -> None:
        p = self.params
        n = len(self.people)
        if n == 0:
            return
        t = self.t
        goals = np.full((n, 2), np.nan)
        speeds = np.zeros(n)
        for i, person in enumerate(self.people):
            was = self.present[i]
            self.present[i] = person.behaviour.present(self, i, t)
            if self.present[i] and not was:
                self.pos[i] = person.behaviour.start(self, i)
                self.vel[i] = 0.0
            if self.present[i]:
                goal, speed = person.behaviour.goal(self, i, t)
                if goal is not None:
                    goals[i], speeds[i] = goal, speed
        idx = np.flatnonzero(self.present)
        if len(idx) == 0:
            return
        pos, vel = self.pos[idx], self.vel[idx]
        # Driving force towards the goal (or to rest when there is none).
        to_goal = goals[idx] - pos
        dist = np.linalg.norm(to_goal, axis=1)
        has_goal = np.isfinite(dist)
        direction = np.where(
            has_goal[:, None], to_goal / np.maximum(np.nan_to_num(dist), 1e-9)[:, None], 0.0
        )
        wanted = speeds[idx] * np.clip(np.nan_to_num(dist) / p.slow_radius, 0.0, 1.0)
        desired = np.nan_to_num(direction * wanted[:, None])
        force = (desired - vel) / p.relax_time
        # People repel people, more so those ahead.
        if len(idx) > 1:
            delta = pos[:, None, :] - pos[None, :, :]
            d = np.linalg.norm(delta, axis=2)
            np.fill_diagonal(d, np.inf)
            normal = delta / np.maximum(d, 1e-9)[..., None]
            magnitude = p.people_push * np.exp((2 * p.body_radius - d) / p.people_range)
            heading_dir = np.stack([np.cos(self.heading[idx]), np.sin(self.heading[idx])], 1)
            cos_phi = -np.einsum("ijk,ik->ij", normal, heading_dir)
            weight = p.anisotropy + (1 - p.anisotropy) * (1 + cos_phi) / 2
            force += np.sum((magnitude * weight)[..., None] * normal, axis=1)
        # Walls and furniture repel.
        od, on = self.venue.distances(pos)
        force += np.sum(
            (p.obstacle_push * np.exp((p.body_radius - od) / p.obstacle_range))[..., None] * on,
            axis=1,
        )
        vel = vel + force * dt
        top = np.maximum(speeds[idx], p.still_speed) * p.max_speed_factor
        norm = np.linalg.norm(vel, axis=1)
        vel *= np.minimum(1.0, top / np.maximum(norm, 1e-9))[:, None]
        firm = np.array([self.people[i].behaviour.anchored(self, i, t) for i in idx])
        vel[firm] = 0.0
        pos = pos + vel * dt
        pos = np.where(firm[:, None], self.pos[idx], self._resolve(pos))
        self.pos[idx], self.vel[idx] = pos, vel
        # Body heading, gait phase and amplitude.
        speed = np.linalg.norm(vel, axis=1)
        for k, i in enumerate(idx):
            target = None
            if speed[k] > p.still_speed:
                target = math.atan2(vel[k, 1], vel[k, 0])
            else:
                target = self.people[i].behaviour.facing(self, i, t)
            if target is not None:
                error = (target - self.heading[i] + math.pi) % (2 * math.pi) - math.pi
                step = p.turn_rate * dt
                self.heading[i] += float(np.clip(error, -step, step))
        heights = np.array([self.people[i].height for i in idx])
        stride = self.body_params.stride_per_height * heights
        self.phase[idx] = (self.phase[idx] + 2 * math.pi * speed * dt / stride) % (2 * math.pi)
        target_amp = np.clip(speed / self.body_params.full_gait_speed, 0.0, MAX_GAIT_AMPLITUDE)
        self.amp[idx] += (target_amp - self.amp[idx]) * min(1.0, dt / p.relax_time)

    # ------------------------------------------------------------- reading
    def state(self, t: float | None = None) -> CrowdState:
        """The present people at time ``t`` (default: the last step), which must lie within
        one step after the last one: positions and gait phases are carried forward from
        the last step at its velocities, so that states are exact in time although the
        dynamics advance in fixed steps."""
        if not self._started:
            self._start()
        t = self.t if t is None else float(t)
        ahead = t - self.t
        if not -1e-9 <= ahead <= float(self.params.time_step) + 1e-9:
            raise ValueError(
                f"crowd state at t={t:.4f} s asked while the crowd is at {self.t:.4f} s."
            )
        idx = np.flatnonzero(self.present)
        position = self.pos[idx] + self.vel[idx] * ahead
        speed = np.linalg.norm(self.vel[idx], axis=1)
        heights = np.array([self.people[i].height for i in idx])
        stride = self.body_params.stride_per_height * heights
        phase = self.phase[idx] + 2 * math.pi * speed * ahead / np.maximum(stride, 1e-9)
        sway_m = float(self.body_params.sway_m)
        sway = (
            sway_m
            * np.sin(0.5 * math.pi * t + self.sway_phase[idx])
            * np.clip(1.0 - self.amp[idx], 0, 1)
        )
        wrists = np.full((len(idx), 2, 3), np.nan)
        for k, i in enumerate(idx):
            target = self.people[i].behaviour.wrists(self, i, self.t)
            if target is not None:
                wrists[k] = target
        if np.isfinite(wrists).any():
            wrists += np.append(self.vel[idx] * ahead, np.zeros((len(idx), 1)), axis=1)[:, None, :]
        pose = BodyPose(
            x=position[:, 0],
            y=position[:, 1],
            heading=self.heading[idx].copy(),
            height=heights,
            phase=phase,
            amplitude=self.amp[idx].copy(),
            sway=sway,
            wrist_targets=wrists if np.isfinite(wrists).any() else None,
        )
        return CrowdState(t, np.array([self.people[i].id for i in idx], dtype=np.int64), idx, pose)
