"""A person's own limb lengths and radii, from their first seconds in view.

MDCA measures each person's body beforehand; we estimate it. Start from the
average body of the person's height (``BodyShape.from_height``), then search
six proportions one at a time (limb radius, trunk radius, arm length, leg
length, trunk length, shoulder and hip width), each over a few factors around
its current value, the current one included: for each candidate body, every
frame's limbs are refitted by a short anneal from the frame's current pose (the
same random numbers for every candidate, so that they are compared on equal
terms), and the candidate scores the sum of the frames' full-body likelihoods
(eq. 9) plus a term that makes a hand pay for reaching past the points. The
best factor is kept with its refitted poses; after each pass every frame's whole
pose is refitted to the body found. A second pass searches finer steps.

Why so (tests/skeleton/test_tracker.py's body, 8 clouds x 2 seeds): compared
against the score the current body had before the poses were refitted, a
candidate won by the refit's noise (200 particles) as often as by its body, and
the arm length came out anywhere in 0.98-1.20 for a true 1.12. A points-to-model
likelihood barely charges a straight arm for being too long (its hand's cap in
empty space costs only the light support term), hence the hands' term; radii
change the score far more than lengths do, hence searched first.
"""

from __future__ import annotations

from collections.abc import Generator, Iterator, Sequence

import numpy as np

from optrack.params import Params
from optrack.skeleton.filter import SkeletonFilter, motion_spread
from optrack.skeleton.init import LIMBS, pose_log_likelihood
from optrack.skeleton.joints import JOINTS
from optrack.skeleton.model import PARTITIONS, PARTS, BodyShape, forward_kinematics
from optrack.skeleton.params import SKELETON_PARAMS

__all__ = ["PROPORTIONS", "ShapeSearch", "estimate_shape"]

# In the order searched: the radii first (they move the score most).
PROPORTIONS = ("limb_radius", "trunk_radius", "arms", "legs", "trunk", "width")
# Relative steps of the two passes (the first coarse, the second fine); 0 is the current
# factor, scored again with the others.
_STEPS = ((-0.16, -0.08, 0.0, 0.08, 0.16), (-0.04, 0.0, 0.04))
# The refit's short anneal searches the arms and legs as wide as a random walk of these
# agilities (rad/s) over _REFIT_DT, whatever tracking's motion model is.
_REFIT_AGILITY = {"agility_arms_rad": 8.0, "agility_legs_rad": 6.0}
# The short anneal that refits a frame's pose to a candidate shape.
_REFIT_PARTICLES = 200
_REFIT_LAYERS = 3
_REFIT_DT = 1.0 / 30.0
# Partitions a step of the search anneals (of one frame's refit): a step costs about
# 1.5 ms of CPU, so that the frames it runs in stay near the others' cost.
_PER_STEP = 2
# Each forearm's far end (its part runs past the wrist over the hand) and the weight of
# the term that charges it for the distance, past its radius, to the nearest point.
_FOREARMS = tuple(
    (JOINTS.index(part.a), JOINTS.index(part.b), part.t1, k)
    for k, part in enumerate(PARTS)
    if part.name.endswith("forearm")
)
_HANDS_WEIGHT = 1.0


def search_score(filt: SkeletonFilter, points: np.ndarray, pose: np.ndarray) -> float:
    """What the body's search maximises for one frame: the full-body likelihood (eq. 9)
    less, for each hand, the squared distance from its forearm's far end to the nearest
    point, beyond the end's radius, over 2 sigma^2."""
    joints = forward_kinematics(np.asarray(pose)[None], filt.shape)[0][0]
    cost = 0.0
    for a, b, t1, k in _FOREARMS:
        end = joints[a] + t1 * (joints[b] - joints[a])
        gap = np.sqrt(np.min(np.sum((points - end) ** 2, axis=1))) if len(points) else 0.0
        cost += max(gap - filt.shape.radii[k][1], 0.0) ** 2
    sigma = float(filt.params.sigma)
    return pose_log_likelihood(filt, points, pose) - _HANDS_WEIGHT * cost / (2.0 * sigma**2)


def _refit(
    filt: SkeletonFilter,
    points: np.ndarray,
    pose: np.ndarray,
    spread: np.ndarray,
    partitions: Sequence[str],
) -> Generator[None, None, tuple[float, np.ndarray]]:
    """One frame's pose refit to the filter's shape by a short anneal of ``partitions``,
    a yield after every ``_PER_STEP`` of them but the last; returns its score and pose
    (the refit may only help: the given pose is kept when it scores higher)."""
    filt.reset(pose, spread)
    for i, name in enumerate(partitions):
        if i and i % _PER_STEP == 0:
            yield
        filt.anneal(points, name, _REFIT_LAYERS, spread)
    best = filt.estimate.copy()
    score = search_score(filt, points, best)
    start = search_score(filt, points, pose)
    if start > score:
        best, score = np.asarray(pose).copy(), start
    return score, best


def _on_the_floor(pose: np.ndarray, old: BodyShape, new: BodyShape) -> np.ndarray:
    """``pose`` for the body ``new`` instead of ``old``: the pelvis raised or lowered in
    proportion to the legs' length, so that the feet stay where they were above the floor."""
    pose = np.asarray(pose, dtype=np.float64).copy()
    ankle = old.ankle_height
    pose[2] = ankle + (pose[2] - ankle) * (new.thigh + new.shin) / (old.thigh + old.shin)
    return pose


class ShapeSearch:
    """:func:`estimate_shape` in small steps, so that it can run across frames: each
    :meth:`advance` refits two partitions of one frame's pose to one candidate body (a
    short anneal of 200 particles; a refit of the four limbs takes two steps, of the whole
    pose three); :attr:`done` once every candidate is scored, then :attr:`shape` is the
    best body and :attr:`poses` each frame's pose refit to it."""

    def __init__(
        self,
        clouds: Sequence[np.ndarray],
        poses: Sequence[np.ndarray],
        shape: BodyShape,
        params: Params | None = None,
        seed: int = 0,
    ) -> None:
        if len(clouds) == 0 or len(clouds) != len(poses):
            raise ValueError("estimate_shape needs one tracked pose per cloud, and at least one.")
        self.params = SKELETON_PARAMS.create(params.as_dict() if params is not None else None)
        self.params.particles = _REFIT_PARTICLES
        # No arms' collision prior: its cost grows with the trunk's radii, searched here.
        self.params.collision_weight = 0.0
        for name, value in _REFIT_AGILITY.items():
            setattr(self.params, name, value)
        self.clouds = [np.asarray(c, dtype=np.float64) for c in clouds]
        self.start = shape
        self.shape = shape
        self.poses = [np.asarray(p, dtype=np.float64).copy() for p in poses]
        self.done = False
        self._seed = seed
        self._spread = motion_spread(self.params, _REFIT_DT)
        self._work = self._search()

    def advance(self) -> bool:
        """Do one step of a frame's refit; returns :attr:`done`."""
        if not self.done:
            self.done = next(self._work, True) is True
        return self.done

    def _score(self, shape: BodyShape, partitions: Sequence[str]) -> Iterator[None]:
        """Score ``shape`` from the current poses frame by frame (yields within and after
        each refit), the same random numbers for every shape; leaves the total and the
        refit poses in ``self._last``."""
        filt = SkeletonFilter(shape, self.params, self._seed)
        total, refit = 0.0, []
        for points, pose in zip(self.clouds, self.poses, strict=True):
            start = _on_the_floor(pose, self.shape, shape)
            score, best = yield from _refit(filt, points, start, self._spread, partitions)
            total += score
            refit.append(best)
            yield
        self._last = (total, refit)

    def _search(self) -> Iterator[bool | None]:
        factors = dict.fromkeys(PROPORTIONS, 1.0)
        for steps in _STEPS:
            for name in PROPORTIONS:
                scored = []
                for step in steps:
                    trial = dict(factors, **{name: factors[name] * (1.0 + step)})
                    yield from self._score(self.start.scaled(**trial), LIMBS)
                    scored.append((self._last[0], trial, self._last[1]))
                _, factors, self.poses = max(scored, key=lambda entry: entry[0])
                self.shape = self.start.scaled(**factors)
            yield from self._score(self.shape, tuple(PARTITIONS))
            self.poses = self._last[1]
        yield True


def estimate_shape(
    clouds: Sequence[np.ndarray],
    poses: Sequence[np.ndarray],
    shape: BodyShape,
    params: Params | None = None,
    seed: int = 0,
) -> tuple[BodyShape, list[np.ndarray]]:
    """The body that best explains a person's clouds (each (N, 3), world frame) given
    their tracked poses (each (D,)), searched from ``shape``; returns it and each frame's
    pose refit to it (:class:`ShapeSearch` run to the end at once)."""
    search = ShapeSearch(clouds, poses, shape, params, seed)
    while not search.advance():
        pass
    return search.shape, search.poses
