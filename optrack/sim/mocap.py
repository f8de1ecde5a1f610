"""People performing motions: BVH clips retargeted onto each person, looped, placed.

:func:`retarget` turns a BVH clip into a :class:`Motion`: per frame, the local
rotation of every joint of our skeleton (:mod:`optrack.sim.articulated`) and the
path of the hips. Each of our bones takes the direction of the BVH bone it maps to,
and its twist from the BVH joint that drives it: with ``W`` that joint's global
rotation, ``B`` the BVH rest pose's body frame and ``A`` the rotation from our rest
bone to the BVH rest bone, the bone's rotation is ``swing(W B A o -> d) W B A``
(``o`` our rest direction, ``d`` the BVH bone now). Only directions cross over: the
person keeps their own bone lengths, and the hips' path scales by the ratio of their
leg length to the clip's. CMU takes start with a reference pose: frame 0 is skipped.

A :class:`Performance` is a crowd behaviour that plays a motion: placed and turned
in the venue (:func:`add_performers` picks where each person starts and, at each
leg of about ``LEG_SECONDS`` of the clip, how far to turn so that the path stays
clear of walls, furniture and the other performers). A clip shorter than the scene
plays again from where it ended: the next play starts at the last frame's position
and heading, and the pose eases from the last frame into the first over ``blend``
seconds. A turn eases in over a leg's first ``TURN_SECONDS``: the heading turns and
the hips go on at the clip's own pace along the turned direction, as a person turning
while they move (the path already run is not swung round).
"""

from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path

import numpy as np

from optrack.errors import UserError
from optrack.sim.articulated import (
    BODY_JOINTS,
    BODY_PARENTS,
    ArticulatedPose,
    blend,
    forward_kinematics,
    frame_from,
    matrices,
    quaternions,
    swing,
)
from optrack.sim.body import BodyModel, BodyShape, BodyState, ground
from optrack.sim.bvh import BVH_TO_WORLD, BvhClip, map_joints, metres_per_unit, read_bvh
from optrack.sim.crowd import Behaviour, Crowd, CrowdState
from optrack.sim.scenario import PeopleSpec
from optrack.sim.venue import Venue

__all__ = [
    "Motion",
    "Performance",
    "add_performers",
    "load_motion",
    "pose_people",
    "retarget",
]

BLEND_SECONDS = 0.3  # the pose eases from a loop's last frame into the next loop's first
TURN_SECONDS = 0.5  # a turn between legs eases in over this long (at most the leg)
LEG_SECONDS = 0.6  # a clip's play is cut into legs of about this long, each may turn
PLAN_STEP = 0.1  # s between the path samples that placement checks
LOOKAHEAD = 2  # legs a placement looks at: the one it plans and the next
PLACEMENT_TRIES = 100
LOOP_TURNS_DEG = (0, 45, -45, 90, -90, 135, -135, 180)
GROUND_PERCENTILE = 90  # of per-frame lifts: frames standing on the floor, not jumping
BODY_CLEARANCE = 0.3  # m kept between a performer's pelvis and walls or furniture
SEPARATION = 0.7  # m kept between two performers' pelvises
WALL_FIRST = 100.0  # a path too near a wall scores this far below any other


@dataclasses.dataclass
class Motion:
    """A motion on our skeleton. ``local`` (F, len(BODY_JOINTS), 4): quaternions of each
    joint's rotation relative to its parent (the pelvis's: in the motion's own world,
    z up); ``hips`` (F, 3): the point between the hip joints, metres; ``leg_length``:
    hip to knee to ankle of the performer recorded, metres. ``grounded`` motions have
    their feet put on the floor at every instant (procedural ones); recorded ones keep
    their own heights, on a floor found once. ``cyclic`` ones end in their first pose."""

    name: str
    frame_time: float
    local: np.ndarray
    hips: np.ndarray
    leg_length: float
    grounded: bool = False
    cyclic: bool = False

    @property
    def period(self) -> float:
        """Seconds from the first frame to the last (a loop's length)."""
        return (len(self.local) - 1) * self.frame_time

    def _frames(self, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The frame before each of the times ``tau`` (n,) and how far past it, 0-1."""
        f = np.clip(np.asarray(tau, dtype=np.float64) / self.frame_time, 0.0, len(self.hips) - 1)
        i = np.minimum(np.floor(f).astype(int), len(self.hips) - 2)
        return i, f - i

    def sample(self, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Local quaternions (n, J, 4) and hips (n, 3) at ``tau`` (n,) seconds into the
        motion (interpolated)."""
        i, w = self._frames(tau)
        return blend(self.local[i], self.local[i + 1], w[:, None]), self.hips_at(tau)

    def hips_at(self, tau: np.ndarray) -> np.ndarray:
        """The hips (n, 3) at ``tau`` (n,) seconds into the motion (interpolated)."""
        i, w = self._frames(tau)
        return self.hips[i] + (self.hips[i + 1] - self.hips[i]) * w[:, None]

    def headings(self, tau: np.ndarray) -> np.ndarray:
        """Yaw (radians) of the pelvis's forward axis at ``tau`` seconds."""
        local, _ = self.sample(tau)
        forward = matrices(local[..., 0, :])[..., :, 0]
        return np.arctan2(forward[..., 1], forward[..., 0])


# ------------------------------------------------------------------ retargeting


def _segments(clip: BvhClip) -> dict[str, tuple[int, str | int, str | int, np.ndarray]]:
    """For each of our joints whose rotation the clip drives: the BVH joint driving it,
    where its bone starts and ends (BVH joint indices, or "head_end"), and our rest
    direction of that bone."""
    mapped = map_joints(clip)
    b = mapped.joints
    parents = [j.parent for j in clip.joints]
    down = np.array([0.0, 0.0, -1.0])
    lateral = np.array([0.0, 1.0, 0.0])
    foot = np.array([0.11, 0.0, -0.02])
    out: dict[str, tuple[int, str | int, str | int, np.ndarray]] = {
        "pelvis": (b["pelvis"], b["right_hip"], b["left_hip"], lateral),
        "spine": (b["spine"], b["spine"], b["neck"], -down),
        "neck": (parents[b["neck"]], b["right_shoulder"], b["left_shoulder"], lateral),
    }
    if clip.joints[b["head"]].end_site is not None:
        out["head"] = (b["head"], b["head"], "head_end", -down)
    for side in ("left", "right"):
        chain = [b[f"{side}_{n}"] for n in ("shoulder", "elbow", "wrist")]
        out[f"{side}_shoulder"] = (chain[0], chain[0], chain[1], down)
        out[f"{side}_elbow"] = (chain[1], chain[1], chain[2], down)
        if mapped.hand_tips[side] >= 0:
            out[f"{side}_wrist"] = (chain[2], chain[2], mapped.hand_tips[side], down)
        leg = [b[f"{side}_{n}"] for n in ("hip", "knee", "ankle")]
        out[f"{side}_hip"] = (leg[0], leg[0], leg[1], down)
        out[f"{side}_knee"] = (leg[1], leg[1], leg[2], down)
        if mapped.toe_tips[side] >= 0:
            out[f"{side}_ankle"] = (leg[2], leg[2], mapped.toe_tips[side], foot)
    return out


def retarget(clip: BvhClip) -> Motion:
    """The clip on our skeleton (see the module docstring); its reference frame skipped."""
    mapped = map_joints(clip).joints
    segments = _segments(clip)
    unit = metres_per_unit(clip)
    first = 1 if clip.starts_with_reference_pose() else 0
    positions, rotations = clip.forward_kinematics(slice(first, None))
    rest_positions = clip.rest_positions()[None]
    rest_rotations = np.broadcast_to(np.eye(3), (1, len(clip.joints), 3, 3))
    head = segments.get("head", (0, 0, 0))[0]

    def where(source: str | int, pos: np.ndarray, rot: np.ndarray) -> np.ndarray:
        if source == "head_end":
            return pos[:, head] + rot[:, head] @ clip.joints[head].end_site
        return pos[:, source]

    c = BVH_TO_WORLD
    world_rot = c @ rotations @ c.T  # (F, J, 3, 3)
    rest_world = rest_positions[0] @ c.T
    body = frame_from(
        rest_world[mapped["left_hip"]] - rest_world[mapped["right_hip"]],
        rest_world[mapped["head"]] - rest_world[mapped["pelvis"]],
        1,
        2,
    )
    count = len(positions)
    globals_ = np.broadcast_to(np.eye(3), (count, len(BODY_JOINTS), 3, 3)).copy()
    for j, name in enumerate(BODY_JOINTS):
        if name not in segments:
            globals_[:, j] = globals_[:, BODY_PARENTS[j]] if j else np.eye(3)
            continue
        driver, start, end, ours = segments[name]
        rest_dir = (
            where(end, rest_positions, rest_rotations)
            - where(start, rest_positions, rest_rotations)
        )[0] @ c.T
        now = (where(end, positions, rotations) - where(start, positions, rotations)) @ c.T
        if np.linalg.norm(rest_dir) < 1e-6 or np.any(np.linalg.norm(now, axis=1) < 1e-9):
            globals_[:, j] = globals_[:, BODY_PARENTS[j]]
            continue
        align = body @ swing(ours, body.T @ rest_dir)
        rough = world_rot[:, driver] @ align
        globals_[:, j] = swing(rough @ ours, now) @ rough
    local = globals_.copy()
    local[:, 1:] = np.swapaxes(globals_[:, BODY_PARENTS[1:]], -1, -2) @ globals_[:, 1:]
    hips_bvh = (positions[:, mapped["left_hip"]] + positions[:, mapped["right_hip"]]) / 2
    legs = [
        np.linalg.norm(rest_world[mapped[f"{s}_knee"]] - rest_world[mapped[f"{s}_hip"]])
        + np.linalg.norm(rest_world[mapped[f"{s}_ankle"]] - rest_world[mapped[f"{s}_knee"]])
        for s in ("left", "right")
    ]
    return Motion(
        name=Path(clip.path).name,
        frame_time=clip.frame_time,
        local=quaternions(local),
        hips=hips_bvh @ c.T * unit,
        leg_length=float(np.mean(legs)) * unit,
    )


_MOTIONS: dict[str, Motion] = {}


def load_motion(name: str, base: str | os.PathLike[str] | None = None) -> Motion:
    """A procedural motion by name (walk, wave, crouch, turn), or a BVH file retargeted
    (a relative path is taken from ``base`` when given); read once per process."""
    from optrack.sim.gestures import PROCEDURAL, procedural_motion

    if name in PROCEDURAL:
        key = name
    else:
        path = Path(name)
        if not path.is_absolute() and base is not None and not path.exists():
            path = Path(base) / path
        if path.suffix.lower() != ".bvh":
            raise UserError(
                f"clip '{name}' is neither a BVH file (.bvh) nor a procedural motion "
                f"({', '.join(PROCEDURAL)}); give one of those."
            )
        key = str(path.resolve())
    if key not in _MOTIONS:
        _MOTIONS[key] = procedural_motion(name) if name in PROCEDURAL else retarget(read_bvh(key))
    return _MOTIONS[key]


# ------------------------------------------------------------------ performing


def _rot2(angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def _ease(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


@dataclasses.dataclass
class _Loop:
    """The plan of one leg of a performance (see :class:`Performance`)."""

    start: np.ndarray  # world xy of the hips when the leg starts
    heading: float  # world heading when the leg starts
    turn: float  # extra turn eased in over the leg's first TURN_SECONDS (at most the leg)
    # While the turn eases in: its times (n,) and the hips' world path from ``start``
    # (n, 2), built when first needed.
    turning: tuple[np.ndarray, np.ndarray] | None = dataclasses.field(default=None, repr=False)


class Performance(Behaviour):
    """A person playing ``motion`` from ``offset`` seconds into it, looped; placed by
    :func:`add_performers`. The crowd keeps them where they start (anchored).

    Each play of the clip is cut into legs of about ``LEG_SECONDS``; ``loops`` holds one
    plan per leg (where it starts, the heading there, the turn it eases in), so that a
    performer who travels (a runner) can turn often enough to stay in the room."""

    def __init__(self, motion: Motion, offset: float = 0.0) -> None:
        self.motion = motion
        self.offset = float(offset)
        self.scale = 1.0
        self.lift = 0.0
        self.loops: list[_Loop] = []
        period = motion.period
        self.legs = max(1, round(period / LEG_SECONDS))  # legs a play of the clip
        self.leg = period / self.legs  # seconds a leg
        self._turn_s = min(TURN_SECONDS, self.leg)  # a turn eases in within its leg
        bounds = np.arange(self.legs + 1) * self.leg
        self._leg_xy = motion.hips_at(bounds)[:, :2]  # the clip's hips where legs start/end
        self._leg_heading = motion.headings(bounds)

    def start(self, crowd: Crowd, i: int) -> np.ndarray:
        return self.path(np.array([0.0]))[0]

    def anchored(self, crowd: Crowd, i: int, t: float) -> bool:
        return True

    # -------------------------------------------------------------- placement
    def fit(self, shape: BodyShape) -> None:
        """Scale the motion's path to the person's legs and find their floor."""
        self.scale = shape.leg_length / self.motion.leg_length
        if self.motion.grounded:
            return
        taus = np.arange(0.0, self.motion.period, max(self.motion.frame_time, 1 / 30))
        local, hips = self.motion.sample(taus)
        pose = ArticulatedPose(hips * self.scale, matrices(local))
        offsets = np.broadcast_to(shape.offsets, (len(taus), *shape.offsets.shape))
        positions, _ = forward_kinematics(offsets, pose)
        self.lift = float(np.percentile(ground(positions, [shape] * len(taus)), GROUND_PERCENTILE))

    def _clip_time(self, loop: int, tau: np.ndarray) -> np.ndarray:
        """Seconds into the clip at ``tau`` seconds into leg ``loop``."""
        return (loop % self.legs) * self.leg + np.asarray(tau, dtype=np.float64)

    def _yaw(self, loop: int, tau: np.ndarray) -> np.ndarray:
        plan = self.loops[loop]
        turned = plan.turn * _ease(np.asarray(tau) / self._turn_s)
        return plan.heading + turned - self._leg_heading[loop % self.legs]

    def _transform(self, loop: int, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The world yaw (n,) and translation (n, 2) that place the motion's points at
        ``tau`` seconds into leg ``loop``: the hips' world position is ``start`` plus
        their steps in the clip, each turned by the yaw of its time (a turn changes where
        the hips go next, not where they have been)."""
        plan = self.loops[loop]
        tau = np.asarray(tau, dtype=np.float64)
        yaw = self._yaw(loop, tau)
        local = self.motion.hips_at(self._clip_time(loop, tau))[:, :2] * self.scale
        if plan.turn == 0.0:
            first = self._leg_xy[loop % self.legs] * self.scale
            world = plan.start + np.einsum("ij,nj->ni", _rot2(yaw[0]), local - first)
        else:
            if plan.turning is None:
                plan.turning = self._turning(loop)
            grid, path = plan.turning
            done = np.minimum(tau, grid[-1])  # the part of tau spent turning
            world = np.stack([np.interp(done, grid, path[:, k]) for k in range(2)], axis=-1)
            turned = self.motion.hips_at(self._clip_time(loop, done))[:, :2] * self.scale
            world += np.einsum("nij,nj->ni", _rot2(yaw), local - turned)  # yaw is constant
        shift = world - np.einsum("nij,nj->ni", _rot2(yaw), local)
        return yaw, shift

    def _turning(self, loop: int) -> tuple[np.ndarray, np.ndarray]:
        """The hips' world path (n, 2) at times (n,) 0.._turn_s into a turning leg: each
        of the clip's steps turned by the yaw at its middle."""
        step = min(self.motion.frame_time, 1.0 / 120.0)
        grid = np.linspace(0.0, self._turn_s, int(math.ceil(self._turn_s / step)) + 1)
        local = self.motion.hips_at(self._clip_time(loop, grid))[:, :2] * self.scale
        middle = self._yaw(loop, 0.5 * (grid[1:] + grid[:-1]))
        turned = np.einsum("nij,nj->ni", _rot2(middle), np.diff(local, axis=0))
        start = self.loops[loop].start
        return grid, start + np.concatenate([np.zeros((1, 2)), np.cumsum(turned, axis=0)])

    def _split(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The leg (n,) and seconds into it (n,) at scene times ``t``."""
        u = np.asarray(t, dtype=np.float64) + self.offset
        loop = np.minimum(np.floor(u / self.leg).astype(int), len(self.loops) - 1)
        return loop, u - loop * self.leg

    def path(self, t: np.ndarray) -> np.ndarray:
        """World xy (n, 2) of the hips at scene times ``t`` (n,)."""
        loops, taus = self._split(t)
        out = np.empty((len(loops), 2))
        for loop in np.unique(loops):
            here = loops == loop
            yaw, shift = self._transform(int(loop), taus[here])
            hips = self.motion.hips_at(self._clip_time(int(loop), taus[here]))
            out[here] = np.einsum("nij,nj->ni", _rot2(yaw), hips[:, :2] * self.scale) + shift
        return out

    def next_loop(self, turn: float) -> _Loop:
        """The leg after the last planned one, with ``turn`` radians eased in."""
        index = len(self.loops) - 1
        last, j = self.loops[index], index % self.legs
        yaw, shift = self._transform(index, np.array([self.leg]))
        start = _rot2(yaw)[0] @ (self._leg_xy[j + 1] * self.scale) + shift[0]
        heading = last.heading + last.turn + self._leg_heading[j + 1] - self._leg_heading[j]
        return _Loop(start, heading, turn)

    # --------------------------------------------------------------- posing
    def articulated(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """The pelvis's world position (3,) and local rotations (J, 3, 3) at scene time t."""
        while t + self.offset >= len(self.loops) * self.leg:
            self.loops.append(self.next_loop(0.0))  # past the planned scene: straight on
        loops, taus = self._split(np.array([t]))
        loop, tau = int(loops[0]), float(taus[0])
        root, local = self._at(loop, tau)
        first_leg = loop % self.legs == 0  # the clip starts again here
        if loop > 0 and first_leg and tau < BLEND_SECONDS and not self.motion.cyclic:
            before_root, before = self._at(loop - 1, self.leg)
            weight = float(_ease(np.array(tau / BLEND_SECONDS)))
            local = blend(before, local, weight)
            root[2] = before_root[2] + (root[2] - before_root[2]) * weight
        return root, matrices(local)

    def _at(self, loop: int, tau: float) -> tuple[np.ndarray, np.ndarray]:
        local, hips = self.motion.sample(self._clip_time(loop, np.array([tau])))
        yaw, shift = self._transform(loop, np.array([tau]))
        turn = np.array([0.0, 0.0, math.sin(yaw[0] / 2), math.cos(yaw[0] / 2)])
        local = local[0].copy()
        local[0] = _quat_mul(turn, local[0])
        xy = _rot2(yaw)[0] @ (hips[0, :2] * self.scale) + shift[0]
        return np.array([xy[0], xy[1], hips[0, 2] * self.scale + self.lift]), local


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternions (x, y, z, w)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ]
    )


# ------------------------------------------------------------------ placing


def _score(venue: Venue, area: np.ndarray, points: np.ndarray, others: list[np.ndarray]) -> float:
    """How far the path ``points`` (n, 2) stays inside ``area`` (x0, y0, x1, y1), clear
    of the venue and of the others' paths at the same instants (negative: too close).
    Walls and furniture come first: a path that comes too close to them scores below
    every path that keeps clear of them (a runner boxed in by the others goes near them
    rather than through a wall)."""
    walls = float(venue.clearance(points).min()) - BODY_CLEARANCE
    if walls < 0.0:
        return walls - WALL_FIRST
    score = min(walls, float(np.minimum(points - area[:2], area[2:] - points).min()))
    for other in others:
        score = min(score, float(np.linalg.norm(points - other, axis=1).min()) - SEPARATION)
    return score


class _Planner:
    """Chooses where a performer starts and how far it turns at each loop, looking one
    loop ahead (a turn that keeps this loop clear but leaves no way on is not taken)."""

    def __init__(
        self,
        performer: Performance,
        venue: Venue,
        area: np.ndarray,
        times: np.ndarray,
        others: list[np.ndarray],
    ) -> None:
        self.performer, self.venue, self.area = performer, venue, area
        self.times, self.others = times, others
        self.loop_of = np.floor((times + performer.offset) / performer.leg).astype(int)

    def score(self, loop: int, depth: int = LOOKAHEAD) -> float:
        """How clear the planned ``loop`` (the last one) and the best next one stay."""
        inside = self.loop_of == loop
        if not inside.any():
            return math.inf
        points = self.performer.path(self.times[inside])
        score = _score(self.venue, self.area, points, [o[inside] for o in self.others])
        if depth > 1 and loop < self.loop_of[-1]:
            score = min(score, max(self.score_turn(t, loop + 1, depth - 1) for t in self.turns))
        return score

    turns = tuple(math.radians(d) for d in LOOP_TURNS_DEG)

    def score_turn(self, turn: float, loop: int, depth: int = LOOKAHEAD) -> float:
        self.performer.loops.append(self.performer.next_loop(turn))
        try:
            return self.score(loop, depth)
        finally:
            self.performer.loops.pop()

    def place(self, rng: np.random.Generator) -> None:
        performer = self.performer
        # The leg playing at the scene's start (a performer who starts into the clip may
        # start past its first legs): placed at the point drawn; the legs before it are
        # never played (the same plan stands in for them).
        first = int(self.loop_of[0])
        best, best_score = None, -math.inf
        for _ in range(PLACEMENT_TRIES):
            point = rng.uniform(self.area[:2], self.area[2:])
            plan = _Loop(point, float(rng.uniform(-math.pi, math.pi)), 0.0)
            performer.loops = [plan] * (first + 1)
            score = self.score(first)
            if score > best_score:
                best, best_score = plan, score
            if score >= 0:
                break
        performer.loops = [best] * (first + 1)
        for loop in range(first + 1, self.loop_of[-1] + 1):
            scores = []
            for turn in self.turns:
                scores.append(self.score_turn(turn, loop))
                if scores[-1] >= 0:
                    break
            performer.loops.append(performer.next_loop(self.turns[int(np.argmax(scores))]))


def add_performers(
    crowd: Crowd,
    body: BodyModel,
    spec: PeopleSpec,
    clips: list[str],
    count: int,
    seconds: float,
    base: str | None = None,
) -> list[int]:
    """Add ``count`` people performing ``clips`` (person k plays clip k modulo their
    number; people sharing a clip start at different points of it), each placed and
    turned in the venue, in ``spec.area`` when it gives one; returns their indices."""
    if not clips:
        return []
    area = np.asarray(spec.area if spec.area is not None else crowd.area, dtype=np.float64)
    motions = [load_motion(clip, base) for clip in clips]
    times = np.arange(0.0, max(seconds, PLAN_STEP), PLAN_STEP)
    added, paths = [], []
    for k in range(count):
        motion = motions[k % len(motions)]
        sharing = len(range(k % len(motions), count, len(motions)))
        performer = Performance(motion, motion.period * (k // len(motions)) / sharing)
        index = crowd.add(performer)
        performer.fit(body.shape(index, crowd.people[index].height))
        _Planner(performer, crowd.venue, area, times, paths).place(crowd.rng)
        paths.append(performer.path(times))
        added.append(index)
    return added


def pose_people(
    body: BodyModel, crowd: Crowd, state: CrowdState
) -> tuple[BodyState, list[BodyShape]]:
    """The bodies of the people present in ``state``: walkers from their gait,
    performers from their motion; each with their own shape."""
    shapes = [body.shape(int(i), crowd.people[int(i)].height) for i in state.index]
    pose = body.walk(state.pose)
    grounded = np.ones(len(shapes), dtype=bool)
    for k, i in enumerate(state.index):
        behaviour = crowd.people[int(i)].behaviour
        if isinstance(behaviour, Performance):
            pose.root[k], pose.local[k] = behaviour.articulated(state.t)
            grounded[k] = behaviour.motion.grounded
    posed = body.posed(pose, shapes, grounded)
    if state.pose.wrist_targets is not None:
        posed = body.reach(posed, np.asarray(state.pose.wrist_targets, dtype=np.float64), shapes)
    return posed, shapes
