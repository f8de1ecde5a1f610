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

from collections.abc import Sequence

import numpy as np

from optrack.params import Params
from optrack.skeleton.filter import SkeletonFilter, motion_spread
from optrack.skeleton.init import pose_log_likelihood
from optrack.skeleton.model import PARTITIONS, BodyShape
from optrack.skeleton.params import SKELETON_PARAMS

__all__ = ["PROPORTIONS", "estimate_shape"]

PROPORTIONS = ("arms", "legs", "trunk", "width", "limb_radius", "trunk_radius")
# Relative steps of the two passes (the first coarse, the second fine).
_STEPS = ((-0.16, -0.08, 0.0, 0.08, 0.16), (-0.04, 0.0, 0.04))
# The short anneal that refits a frame's pose to a candidate shape.
_REFIT_PARTICLES = 200
_REFIT_LAYERS = 3
_REFIT_DT = 1.0 / 30.0


def _score(
    shape: BodyShape,
    clouds: Sequence[np.ndarray],
    poses: Sequence[np.ndarray],
    params: Params,
    seed: int,
) -> tuple[float, list[np.ndarray]]:
    """Sum over frames of the likelihood of each frame's pose refit to ``shape``."""
    filt = SkeletonFilter(shape, params, seed)
    spread = motion_spread(params, _REFIT_DT)
    total, refit = 0.0, []
    for points, pose in zip(clouds, poses, strict=True):
        filt.reset(pose, spread)
        for name in PARTITIONS:
            filt.anneal(points, name, _REFIT_LAYERS, spread)
        best = filt.estimate.copy()
        score = pose_log_likelihood(filt, points, best)
        start = pose_log_likelihood(filt, points, pose)
        if start > score:  # the refit may only help
            best, score = np.asarray(pose).copy(), start
        refit.append(best)
        total += score
    return total, refit


def estimate_shape(
    clouds: Sequence[np.ndarray],
    poses: Sequence[np.ndarray],
    shape: BodyShape,
    params: Params | None = None,
    seed: int = 0,
) -> tuple[BodyShape, list[np.ndarray]]:
    """The body that best explains a person's clouds (each (N, 3), world frame) given
    their tracked poses (each (D,)), searched from ``shape``; returns it and each frame's
    pose refit to it."""
    if len(clouds) == 0 or len(clouds) != len(poses):
        raise ValueError("estimate_shape needs one tracked pose per cloud, and at least one.")
    base = SKELETON_PARAMS.create(params.as_dict() if params is not None else None)
    base.particles = _REFIT_PARTICLES
    factors = dict.fromkeys(PROPORTIONS, 1.0)
    best_score, best_poses = _score(shape, clouds, poses, base, seed)
    for steps in _STEPS:
        for name in PROPORTIONS:
            current = factors[name]
            for step in steps:
                if step == 0.0:
                    continue
                trial = dict(factors, **{name: current * (1.0 + step)})
                score, refit = _score(shape.scaled(**trial), clouds, best_poses, base, seed)
                if score > best_score:
                    best_score, best_poses, factors[name] = score, refit, trial[name]
    return shape.scaled(**factors), best_poses
