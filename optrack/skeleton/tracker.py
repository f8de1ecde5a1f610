"""One person's skeleton over time: initialise, track, notice a loss, start again.

:class:`SkeletonTracker` takes the person's fused cloud (world frame, metres,
floor at z = 0) each frame and returns a :class:`SkeletonEstimate`: the
joints of optrack/skeleton/joints.py, a confidence per joint, and a state:

- ``initialising``: no pose yet, or one that explains less than
  ``track_fraction`` of the cloud; the first frame runs the coarse-to-fine
  search (optrack/skeleton/init.py), the next ones refine it as tracking does
  and, for ``limb_research_s``, search one limb again a frame, in turn (after both
  legs, the legs are also tried the other way round: init.py's ``swap_legs``, which
  tracking also tries every fourth update; after the second and third rounds, the
  whole body turned round: ``turn_around``, where the start's two headings explained
  the cloud about as well: ``_TURN_DOUBT``);
- ``tracking``: the estimate explains at least ``track_fraction``; with
  ``limb_check_s`` (off by default) each limb, in turn, is checked about that often by
  a short search again, kept only where the whole body explains the cloud better (a
  limb held on points another part explains, an arm raised along the head while it
  hangs, is found again); and every ``arm_rest_frames`` updates one arm in turn is tried
  hanging at rest, kept where the body with it there is clearly likelier and the data
  like it as well (init.py's ``rest_arm_again``: an arm folded through the chest or
  along the head, where no sensor sees it, hangs again);
- ``lost``: the likelihood collapsed (under ``lost_fraction`` explained, or
  fewer than ``min_points`` points) for ``lost_frames`` frames in a row; the
  next frame with enough points initialises again.

While tracking, a skeleton moving over the floor against where it faces
(``facing_speed``) initialises again facing the motion: it was started facing
backwards, left and right swapped (one that does not travel is turned round by
``turn_around`` in its first second, where the data prefer it).

A joint's confidence is the support of the areas of interest next to it
(how many of the points they should hold they hold, capped at 1), times the
share of the cloud the pose explains.

A tracker not given the person's body starts from the average body of the
height their first cloud shows; once tracking, it keeps ``shape_frames``
clouds and poses spread over ``shape_seconds`` and then estimates the
person's own limb lengths and radii from them (optrack/skeleton/shape.py),
once, and tracks on with that body (kept through a loss: it is the same
person).
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import numpy as np

from optrack.params import Params
from optrack.skeleton.filter import PARTITION_PARTS, SkeletonFilter
from optrack.skeleton.init import (
    LIMBS,
    height_from_cloud,
    initialise_both_ways,
    initialise_facing,
    pose_log_likelihood,
    rest_arm_again,
    search_limb_again,
    swap_legs,
    turn_around,
)
from optrack.skeleton.joints import JOINTS
from optrack.skeleton.model import PARTS, BodyShape, forward_kinematics
from optrack.skeleton.params import SKELETON_PARAMS
from optrack.skeleton.shape import ShapeSearch

__all__ = ["SkeletonEstimate", "SkeletonTracker", "State"]

State = Literal["initialising", "tracking", "lost"]


def _areas_of_joints() -> list[list[tuple[int, int]]]:
    """For each joint, the (part, half) areas of interest that touch it."""
    areas: list[list[tuple[int, int]]] = [[] for _ in JOINTS]
    for k, part in enumerate(PARTS):
        for half, joint in ((0, part.a), (1, part.b)):
            if joint in JOINTS:
                areas[JOINTS.index(joint)].append((k, half))
    return areas


_JOINT_AREAS = _areas_of_joints()
# Turning faster than this (rad/s), a person's path swings ahead of their heading (a
# runner's U-turn put it 130 degrees away): the facing is not checked.
_FACING_TURN = 1.0
# The share of the particles a limb's search again anneals (its 12 layers from uniform
# angles cost as much as a frame's whole filter at every particle), and the fewest it
# anneals (all of them when the filter has fewer): a search from uniform angles over a
# limb's four angles needs about that many (with 150 of 300, the skeleton node's test lost the
# body's height in 2 of 6 runs).
_RESEARCH_SHARE = 0.5
_RESEARCH_MIN = 1000
# The periodic check of a limb while tracking (limb_check_s): a short search (these
# particles over these layers, about a fifth of the search above's cost) from angles drawn
# anywhere within the limb's limits, kept only where the whole body's likelihood rose. A
# limb held on points it does not own (a walker's hanging arm put overhead, along the head,
# its bones' support 0.5-1 where a found limb's is 0.3-1) is not noticed by its support,
# but the whole body explains the cloud better with the limb found (by 0.3-1.3 in log
# likelihood on the walk clip): the likelihood decides, not a support threshold. Off by
# default: over six clips x tracker seeds 0-5 at limb_check_s 0.5 it helped three sensors
# (0.059 -> 0.053 m, 2.7 -> 1.9 % lost) and hurt two (0.079 -> 0.086 m: where neither
# sensor sees a limb, a pose on other parts' points scores higher than its true one).
_CHECK_PARTICLES = 400
_CHECK_LAYERS = 6
# How much more the data (the likelihood without the arms' collision prior) must like the
# check's pose. With two sensors an unseen arm that tracking had pushed into the trunk
# (prior 1.17) was moved by the check onto the head's and chest's points, folded overhead
# (prior 0.05, wrist 0.3 -> 0.8 m off): the prior paid for the move, the data gained 0.04.
# The walk's arm found again gained 0.28 in the data; moves of a limb already found gained
# 0-0.09 (walk, squat).
_CHECK_MARGIN = 0.1
# While tracking, the legs are tried the other way round (swap_legs) every this many
# updates (a try, where the knees are crossed or close, solves two legs by least squares
# and anneals them: several times a frame's limb step).
_SWAP_EVERY = 4
# In the first limb_research_s, the body is tried turned round (turn_around) after these
# rounds of the limbs' searches again (a round: each limb once), counted from the start:
# about 0.25 s and 0.4 s after it at 30 Hz, once the limbs have been found again (a try
# costs about 0.2 s of CPU, so not at every round).
_TURN_CYCLES = (2, 3)
# ... and only after a start whose two headings were this close (the difference of their
# full-body log-likelihoods at initialisation, init.py's initialise_both_ways): every turn
# kept over six clips x seeds 0-23 with two sensors and 0-11 with three followed a start
# whose headings were within 0.085 (median 0.40); a refused try leaves the filter
# exactly as it was, so skipping the tries there changes nothing on those runs.
_TURN_DOUBT = 0.2
# ... and kept where the data's log-likelihood of the body turned round beats the body as
# found by more than this (both refined alike), not limb_research_margin's 0.2: the jumps'
# start facing backwards (two sensors, seed 5) was turned round by 0.087 and then refused,
# and stayed backwards for 2.5 s (0.25 m over the run; seed 33 alike). Two sensors, six clips:
# seeds 0-23 0.0669 -> 0.0657 m, held-out seeds 24-47 0.0659 -> 0.0647 m; 5 runs of 288
# changed, each for the better (docs/skeleton.md, "Why the defaults: the turn's margin").
_TURN_MARGIN = 0.05
# While tracking, every arm_rest_frames updates one arm in turn is tried at rest (init.py's
# rest_arm_again), kept where the whole body's log-likelihood rises by more than _REST_GAIN
# and the data's falls by no more than _REST_SLACK. With two sensors an arm the limbs'
# searches folded along the head or through the chest stayed there for the rest of the
# clip (the walk, seeds 2 and 8: a wrist 0.8 m off). The figures come from tries logged,
# and undone, over six clips x seeds 0-7 with two sensors: of 1440 tries, the 29 where rest
# was more than 0.2 m nearer the truth gained 0.68 in the median (the prior's cost of the
# folded arm), 19 of them over 0.3 with the data within 0.05; of the 254 where rest was
# more than 0.2 m further off (arms raised in the jumping jacks), 15 passed both.
_REST_GAIN = 0.3
_REST_SLACK = 0.05
# The arm is annealed from rest over this many particles and layers: half the
# initialisation's 500 x 12, a quarter of the cost. At 500 x 12 the tries cost about 3 % of
# the frame rate (30.3 fps against 31.3, one person, three sensors) for the same accuracy
# (two sensors, six clips x seeds 0-23: 0.0650 m at 500 x 12, 0.0655 m at 250 x 6).
_REST_PARTICLES = 250
_REST_LAYERS = 6
# The parts whose support tells whether a limb is lost: its bones (the feet, cut by the
# fusion's floor margin, hold few points even when found).
_LIMB_PARTS = {
    limb: np.array([k for k in PARTITION_PARTS[limb] if not PARTS[k].name.endswith("foot")])
    for limb in LIMBS
}


@dataclasses.dataclass(frozen=True)
class SkeletonEstimate:
    """One person's skeleton at one instant."""

    stamp: float
    joints: np.ndarray  # (len(JOINTS), 3) world metres, in the order of JOINTS
    confidence: np.ndarray  # (len(JOINTS),) 0..1
    state: State
    explained: float  # share of the cloud within alpha of the model
    pose: np.ndarray  # (D,) the model's state (optrack/skeleton/model.py)


class SkeletonTracker:
    """Tracks one person's skeleton (see the module docstring)."""

    def __init__(
        self, params: Params | None = None, shape: BodyShape | None = None, seed: int | None = None
    ) -> None:
        self.params = params if params is not None else SKELETON_PARAMS.create()
        self.shape = shape
        # The body is estimated once when not given: the clouds and poses it is fitted to.
        self.shape_estimated = shape is not None
        self._samples: list[tuple[float, np.ndarray, np.ndarray]] = []
        self._search: ShapeSearch | None = None
        self._seed = seed
        self.filter: SkeletonFilter | None = None
        self.state: State = "initialising"
        self._stamp: float | None = None
        self._started = -np.inf  # when the skeleton last initialised
        self._turn = 0  # the limbs searched again (or checked) since the skeleton started
        self._updates = 0  # updates with a pose (swap_legs's turn)
        self._checked = -np.inf  # when a limb was last checked while tracking
        self._backwards = 0  # frames in a row moving against where the pelvis faces
        # How much better the heading chosen at the last start explained the cloud than the
        # other one (0 after a start facing the motion: it is tried turned round as ever).
        self._heading_margin = 0.0
        self._misses = 0
        self._last: SkeletonEstimate | None = None  # the last update's estimate

    def update(self, points_world: np.ndarray, stamp: float) -> SkeletonEstimate:
        """Take the person's cloud (N, 3) at time ``stamp`` (s); return the estimate. A
        cloud stamped at or before the last one is not a new instant (a second sensor's
        cloud of the same frame, or a late one): the last estimate is returned as it was
        (stepped over no time, the filter would resample its particles without motion
        and could jump; the skeleton node's test saw the head move 0.3 m)."""
        if self._last is not None and float(stamp) <= self._last.stamp:
            return self._last
        self._last = self._update(points_world, float(stamp))
        return self._last

    def _update(self, points_world: np.ndarray, stamp: float) -> SkeletonEstimate:
        p = self.params
        points = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
        points = points[np.all(np.isfinite(points), axis=1)]
        dt = 0.0 if self._stamp is None else float(stamp) - self._stamp
        if len(points) < int(p.min_points):
            return self._miss(float(stamp))
        self._stamp = float(stamp)
        if self.filter is None or self.state == "lost":
            self._start(points)
            self._started, self._turn = float(stamp), 0
        else:
            self.filter.step(points, dt)
        if self.state == "tracking" and self._face_the_motion(points):
            self._started, self._turn, self._heading_margin = float(stamp), 0, 0.0
        explained, support = self.filter.fit(points)
        if self._search_limbs(points, support, float(stamp)):
            explained, support = self.filter.fit(points)
        if explained < float(p.lost_fraction):
            return self._miss(float(stamp), explained)
        self._misses = 0
        if explained >= float(p.track_fraction):
            self.state = "tracking"
            self._sample_shape(points, float(stamp))
        elif self.state != "tracking":
            self.state = "initialising"
        self._advance_shape()
        return self._estimate(float(stamp), explained, support)

    def _face_the_motion(self, points: np.ndarray) -> bool:
        """Front and back: a person who moves over the floor faster than ``facing_speed``
        for ``facing_frames`` frames in a row, more than 120 degrees away from where the
        pelvis faces and not turning, is walking backwards or, far more often, was initialised facing
        backwards (left and right swapped), which tracking does not undo: initialise
        again facing the motion. Returns whether it did."""
        filt, p = self.filter, self.params
        velocity = filt.velocity[:2]
        speed = float(np.hypot(*velocity))
        facing = np.array([np.cos(filt.estimate[3]), np.sin(filt.estimate[3])])
        if (
            float(p.facing_speed) <= 0.0
            or speed < float(p.facing_speed)
            or abs(filt.velocity[2]) > _FACING_TURN  # turning: the path swings ahead
            or (velocity @ facing > -0.5 * speed)
        ):
            self._backwards = 0
            return False
        self._backwards += 1
        if self._backwards < int(p.facing_frames):
            return False
        self._backwards = 0
        before, kept = filt.estimate.copy(), filt.velocity.copy()
        turned = initialise_facing(filt, points, float(np.arctan2(velocity[1], velocity[0])))
        if pose_log_likelihood(filt, points, turned) < pose_log_likelihood(filt, points, before):
            turned = before  # the data say otherwise: a pelvis's heading wrongly estimated
        filt.reset(turned)
        filt.velocity = kept
        return turned is not before

    def _search_limbs(self, points: np.ndarray, support: np.ndarray, stamp: float) -> bool:
        """Search limbs again, as initialisation does: for ``limb_research_s`` after the
        skeleton started, one limb a frame in turn (a limb hidden at the first frame, or
        lying on points it does not own, is found once the data show it); once tracking,
        each limb one of whose bones (upper arm, forearm, thigh, shin) holds under
        ``limb_lost_support`` of the points its areas of interest should hold; else, once
        tracking, one limb in turn each ``limb_check_s`` / 4 s, by a shorter search. A new
        pose is kept where the whole body's likelihood rose and the data's (without the
        arms' prior) by more than ``limb_research_margin`` (the check's: ``_CHECK_MARGIN``).
        The legs are also tried the other way round (``swap_legs``, the same margin; only
        where the knees are crossed or close): at every update of the first
        ``limb_research_s`` (a runner's knees pass each other for a frame or two, and
        only then is a try made), and while tracking every ``_SWAP_EVERY`` updates. In
        the first ``limb_research_s`` only, after the second and the third round of the
        limbs' searches (``_TURN_CYCLES``), the whole body is also tried turned round
        (``turn_around``, by ``_TURN_MARGIN``: several frames' work, so only while a start's
        front and back are in doubt, and only after a start whose two headings scored within
        ``_TURN_DOUBT`` of each other). While tracking, every ``arm_rest_frames`` updates, one
        arm in turn is tried at rest (``rest_arm_again``). Returns whether a limb moved."""
        chosen = []
        researching = stamp - self._started < float(self.params.limb_research_s)
        if researching:
            chosen.append(LIMBS[self._turn % len(LIMBS)])
            self._turn += 1
        if self.state == "tracking":
            threshold = float(self.params.limb_lost_support)
            chosen += [
                limb
                for limb in LIMBS
                if limb not in chosen and support[_LIMB_PARTS[limb]].mean(axis=1).min() < threshold
            ]
        moved = False
        # The search keeps only its estimate (every particle takes it): it anneals a share
        # of the particles.
        share = max(int(len(self.filter.particles) * _RESEARCH_SHARE), _RESEARCH_MIN)
        margin = float(self.params.limb_research_margin)
        for limb in chosen:
            moved |= search_limb_again(self.filter, points, limb, share, None, margin)
        self._updates += 1
        if researching or (self.state == "tracking" and self._updates % _SWAP_EVERY == 0):
            moved |= swap_legs(self.filter, points, margin)
        # Each limb has been searched again once more: after some rounds, the body turned.
        if (
            researching
            and chosen[0] == "right_leg"
            and self._turn // len(LIMBS) in _TURN_CYCLES
            and self._heading_margin < _TURN_DOUBT
        ):
            moved |= turn_around(self.filter, points, _TURN_MARGIN)
        every = int(self.params.arm_rest_frames)
        if self.state == "tracking" and every > 0 and self._updates % every == 0:
            arm = LIMBS[(self._updates // every) % 2]
            moved |= rest_arm_again(
                self.filter, points, arm, _REST_GAIN, _REST_SLACK, _REST_PARTICLES, _REST_LAYERS
            )
        check = self._limb_to_check(stamp, chosen)
        if check is not None:
            particles = min(_CHECK_PARTICLES, len(self.filter.particles))
            moved |= search_limb_again(
                self.filter, points, check, particles, _CHECK_LAYERS, _CHECK_MARGIN
            )
        return moved

    def _limb_to_check(self, stamp: float, searched: list[str]) -> str | None:
        """While tracking, after ``limb_research_s``: the limb whose turn it is to be
        checked (a short search again), each limb about every ``limb_check_s``."""
        period = float(self.params.limb_check_s)
        if period <= 0.0 or self.state != "tracking" or searched:
            return None
        if stamp - self._checked < period / len(LIMBS) * 0.999:
            return None
        self._checked = stamp
        self._turn += 1
        return LIMBS[self._turn % len(LIMBS)]

    def _sample_shape(self, points: np.ndarray, stamp: float) -> None:
        """Keep a tracked frame for the body's estimate; estimate it once there are enough."""
        p = self.params
        seconds, frames = float(p.shape_seconds), int(p.shape_frames)
        if self.shape_estimated or self._search is not None or seconds <= 0.0:
            return
        spacing = seconds / max(frames - 1, 1)
        if self._samples and stamp - self._samples[-1][0] < spacing * 0.999:
            return
        self._samples.append((stamp, points, self.filter.estimate.copy()))
        if len(self._samples) < frames:
            return
        clouds = [cloud for _, cloud, _ in self._samples]
        poses = [pose for _, _, pose in self._samples]
        self._search = ShapeSearch(clouds, poses, self.shape, p, self._seed or 0)
        self._samples = []

    def _advance_shape(self) -> None:
        """One step of the body's estimate, if one runs; once it is done, track on with
        the body found, from the current pose."""
        if self._search is None:
            return
        for _ in range(int(self.params.shape_steps)):
            if self._search.advance():
                break
        if not self._search.done:
            return
        self.shape, self.shape_estimated = self._search.shape, True
        self._search = None
        pose = self.filter.estimate.copy()
        velocity, limbs = self.filter.velocity, self.filter.limb_velocity
        self.filter = SkeletonFilter(self.shape, self.params, self._seed)
        self.filter.reset(pose)
        self.filter.velocity, self.filter.limb_velocity = velocity, limbs

    def _start(self, points: np.ndarray) -> None:
        if self.shape is None:
            self.shape = BodyShape.from_height(height_from_cloud(points))
        self.filter = SkeletonFilter(self.shape, self.params, self._seed)
        _, self._heading_margin = initialise_both_ways(self.filter, points)
        self.state = "initialising"
        self._misses = 0

    def _miss(self, stamp: float, explained: float = 0.0) -> SkeletonEstimate:
        self._misses += 1
        if self._misses >= int(self.params.lost_frames):
            self.state = "lost"
        return self._estimate(stamp, explained, None)

    def _estimate(self, stamp: float, explained: float, support) -> SkeletonEstimate:
        if self.filter is None:
            joints = np.full((len(JOINTS), 3), np.nan)
            pose = np.full(0, np.nan)
        else:
            pose = self.filter.estimate.copy()
            joints = forward_kinematics(pose, self.filter.shape)[0][: len(JOINTS)]
        confidence = np.zeros(len(JOINTS))
        if support is not None and self.state != "lost":
            for j, areas in enumerate(_JOINT_AREAS):
                confidence[j] = explained * np.mean([support[k, h] for k, h in areas])
        return SkeletonEstimate(stamp, joints, confidence, self.state, explained, pose)
