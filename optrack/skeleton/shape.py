"""A person's own limb lengths and radii, from their first seconds in view.

MDCA measures each person's body beforehand; we estimate it. Start from the
average body of the person's height (``BodyShape.from_height``), then search
six proportions one at a time (arm length, leg length, trunk length,
shoulder and hip width, limb radius, trunk radius), each over a few factors
around its current value: for each candidate shape, every frame's pose is
refined by a short anneal from its tracked pose, and the candidate scores the
sum of the frames' full-body likelihoods (eq. 9). The best factor of each
proportion is kept; a second pass searches finer steps.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np

from optrack.params import Params
from optrack.skeleton.filter import SkeletonFilter, motion_spread
from optrack.skeleton.init import pose_log_likelihood
from optrack.skeleton.model import PARTITIONS, BodyShape
from optrack.skeleton.params import SKELETON_PARAMS

__all__ = ["PROPORTIONS", "ShapeSearch", "estimate_shape"]

PROPORTIONS = ("arms", "legs", "trunk", "width", "limb_radius", "trunk_radius")
# Relative steps of the two passes (the first coarse, the second fine).
_STEPS = ((-0.16, -0.08, 0.0, 0.08, 0.16), (-0.04, 0.0, 0.04))
# The refit's short anneal searches the arms and legs as wide as a random walk of these
# agilities (rad/s) over _REFIT_DT, whatever tracking's motion model is.
_REFIT_AGILITY = {"agility_arms_rad": 8.0, "agility_legs_rad": 6.0}
# The short anneal that refits a frame's pose to a candidate shape.
_REFIT_PARTICLES = 200
_REFIT_LAYERS = 3
_REFIT_DT = 1.0 / 30.0


def _refit(
    filt: SkeletonFilter, points: np.ndarray, pose: np.ndarray, spread: np.ndarray
) -> tuple[float, np.ndarray]:
    """One frame's pose refit to the filter's shape by a short anneal, and its likelihood
    (the refit may only help: the tracked pose is kept when it scores higher)."""
    filt.reset(pose, spread)
    for name in PARTITIONS:
        filt.anneal(points, name, _REFIT_LAYERS, spread)
    best = filt.estimate.copy()
    score = pose_log_likelihood(filt, points, best)
    start = pose_log_likelihood(filt, points, pose)
    if start > score:
        best, score = np.asarray(pose).copy(), start
    return score, best


def _candidates(factors: dict[str, float]) -> Iterator[tuple[str, dict[str, float]]]:
    """Each proportion's trial factors, pass by pass, around the factors kept so far
    (``factors`` is read as the search updates it)."""
    for steps in _STEPS:
        for name in PROPORTIONS:
            current = factors[name]
            for step in steps:
                if step != 0.0:
                    yield name, dict(factors, **{name: current * (1.0 + step)})


class ShapeSearch:
    """:func:`estimate_shape` in small steps, so that it can run across frames: each
    :meth:`advance` refits one frame's pose to one candidate body (a short anneal of 200
    particles, about a thirtieth of the whole search); :attr:`done` once every candidate
    is scored, then :attr:`shape` is the best body and :attr:`poses` each frame's pose
    refit to it."""

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
        """Do one frame's refit; returns :attr:`done`."""
        if not self.done:
            self.done = next(self._work, True) is True
        return self.done

    def _score(self, shape: BodyShape, poses: list[np.ndarray]) -> Iterator[None]:
        """Score ``shape`` frame by frame (a yield after each); leaves the total and the
        refit poses in ``self._last``."""
        filt = SkeletonFilter(shape, self.params, self._seed)
        total, refit = 0.0, []
        for points, pose in zip(self.clouds, poses, strict=True):
            score, best = _refit(filt, points, pose, self._spread)
            total += score
            refit.append(best)
            yield
        self._last = (total, refit)

    def _search(self) -> Iterator[bool | None]:
        factors = dict.fromkeys(PROPORTIONS, 1.0)
        yield from self._score(self.start, self.poses)
        best_score, self.poses = self._last
        for name, trial in _candidates(factors):
            yield from self._score(self.start.scaled(**trial), self.poses)
            score, refit = self._last
            if score > best_score:
                best_score, self.poses, factors[name] = score, refit, trial[name]
                self.shape = self.start.scaled(**factors)
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
