"""What the likelihood cannot rule out: an arm through the trunk or the head.

The likelihood (eq. 9) scores how well the parts explain the points; it does
not know that a body cannot pass through itself. With two sensors an arm
hanging at the side is seen by few points, most of which the trunk explains
almost as well, while an arm folded up into the head or the chest gets the
head's or the chest's points and fills its areas of interest: the filter and
the limb searches then keep the arm inside the body (the walk clip, 2 sensors:
an elbow 0.6 m above the true one, at full confidence).

:class:`ArmCollision` is a prior on the arms' angles: each of the elbow, the
forearm's middle and the wrist whose scaled distance (eq. 7) to the trunk's or
the head's cylinder is under ``-collision_margin`` (that far inside, in the
part's radii) costs ``collision_weight`` times how much further inside it is.
Against the head the arm's own thickness counts too (the forearm's radius, in
the head's radii, is added to the margin's depth): an arm whose surface enters
the head's costs, so an arm folded at the head's side, taking the points of the
head's edge, is not free (two sensors, the walk: a hanging arm they hardly saw
was moved there in the first second and held there). Against the trunk the
arm's axis is tested: a hanging arm rests against the trunk's side. A hand on
the belly or arms crossed over the chest stay outside the cylinders and cost
nothing.
"""

from __future__ import annotations

import numba
import numpy as np

from optrack.params import Params
from optrack.skeleton.kernels import GROUPS, LANES, fk_lanes, particle_lanes, point_distance
from optrack.skeleton.model import (
    FK_TABLES,
    FRAMES,
    PART_INDEX,
    PARTITIONS,
    POINTS,
    BodyShape,
    D,
    forward_kinematics,
    part_geometry,
)

__all__ = ["ArmCollision", "arm_collision_cost"]

# The parts an arm must stay out of, and the points of each arm that are tested.
_BODY = np.array([PART_INDEX["lower_trunk"], PART_INDEX["upper_trunk"], PART_INDEX["head"]])
_ARMS = {
    "left_arm": (("left_shoulder", "left_elbow"), "left_elbow", "left_wrist"),
    "right_arm": (("right_shoulder", "right_elbow"), "right_elbow", "right_wrist"),
}


@numba.njit(parallel=True, cache=True, fastmath=True)
def _depths(particles, cos, sin, dims, base_rot, base_pts, offsets, frames_on, points_on, ends,
            body, margins, tables):  # fmt: skip
    """For each particle (P, D), the arm's summed depth inside the ``body`` rows (K, G):
    its elbow, its forearm's middle and its wrist (``ends``: the elbow's and the
    wrist's point indices), the arm's angles ``dims`` from the particle (their cosines
    and sines ``cos``, ``sin``, (P, len(dims))), the rest of the pose as in
    ``base_rot``/``base_pts``; ``margins`` (K,): the depth each row lets them reach free.
    The kinematics of ``LANES`` particles at once (:func:`fk_lanes`, only the frames
    ``frames_on`` and their points ``points_on``); threads share groups of them (each
    particle alone: the same numbers with any count of threads)."""
    n = particles.shape[0]
    out = np.zeros(n)
    chunks = (n + LANES - 1) // LANES
    groups = min(chunks, GROUPS)
    for group in numba.prange(groups):  # scratch made once per group of chunks
        xs = np.zeros((D, LANES))
        cs, sn = np.zeros((D, LANES), np.float32), np.zeros((D, LANES), np.float32)
        rot = np.empty(base_rot.shape + (LANES,))
        pts = np.empty(base_pts.shape + (LANES,))
        for lane in range(LANES):
            rot[..., lane] = base_rot
            pts[..., lane] = base_pts
        tested = np.empty((3, LANES, 3))  # the elbow, the forearm's middle, the wrist
        for c in range(group * chunks // groups, (group + 1) * chunks // groups):
            first = c * LANES
            lanes = particle_lanes(particles, dims, cos, sin, first, xs, cs, sn)
            fk_lanes(xs, cs, sn, offsets, frames_on, points_on, rot, pts, tables)
            for lane in range(lanes):
                for r in range(3):
                    elbow, wrist = pts[ends[0], r, lane], pts[ends[1], r, lane]
                    tested[0, lane, r], tested[2, lane, r] = elbow, wrist
                    tested[1, lane, r] = 0.5 * (elbow + wrist)
                total = 0.0
                for q in range(3):
                    deepest = 0.0  # how far inside a part beyond the margin, in its radii
                    for k in range(body.shape[0]):
                        depth = -point_distance(tested[q], lane, body[k])[0] - margins[k]
                        deepest = max(deepest, depth)
                    total += deepest
                out[first + lane] = total
    return out


_HEAD = list(_BODY).index(PART_INDEX["head"])


def _margins(body: np.ndarray, forearm: np.ndarray, margin: float) -> np.ndarray:
    """The depth (in each part's radii) an arm's points may reach inside each of the
    ``body`` rows (``_BODY``'s geometry) before they cost: ``margin``, less, for the
    head, the forearm's radius (``forearm``: its geometry row)."""
    margins = np.full(len(body), margin)
    margins[_HEAD] -= float(forearm[14]) / float(body[_HEAD, 14])
    return margins


class ArmCollision:
    """The collision prior of one arm's particles against a fixed trunk and head (see
    the module docstring): ``prior(particles)`` (P, D) gives each one's cost (P,), to
    subtract from its log-likelihood; no cost for the torso and the legs
    (``active`` is False)."""

    def __init__(self, estimate: np.ndarray, partition: str, shape: BodyShape, params: Params):
        self.weight = float(params.collision_weight)
        self.active = partition in _ARMS and self.weight > 0.0
        if not self.active:
            return
        frames, elbow, wrist = _ARMS[partition]
        pts, rot = forward_kinematics(np.asarray(estimate, dtype=np.float64), shape)
        turned = np.array([name in frames for name in FRAMES])
        frames_on = np.flatnonzero(turned)
        forearm = PART_INDEX[f"{partition.split('_')[0]}_forearm"]
        rows = np.append(_BODY, forearm)  # the body it must stay out of, and its forearm
        geometry = part_geometry(pts[None], rot[None], shape, rows)[0].astype(np.float64)
        body = geometry[: len(_BODY)]
        self._args = (
            np.array(PARTITIONS[partition], dtype=np.int64), rot, pts, shape._offsets,
            frames_on, np.flatnonzero(turned[FK_TABLES[-1]]),  # the frames and their points
            np.array([POINTS.index(elbow), POINTS.index(wrist)], dtype=np.int64), body,
            _margins(body, geometry[-1], float(params.collision_margin)), FK_TABLES,
        )  # fmt: skip

    def __call__(self, particles: np.ndarray) -> np.ndarray:
        if not self.active:
            return np.zeros(len(particles))
        particles = np.ascontiguousarray(particles, dtype=np.float64)
        # Sines and cosines by numpy's float32 vector path, as the kinematics' own.
        turned = particles[:, self._args[0]].astype(np.float32)
        return self.weight * _depths(particles, np.cos(turned), np.sin(turned), *self._args)


def arm_collision_cost(state: np.ndarray, shape: BodyShape, params: Params) -> float:
    """Both arms' collision cost of one pose (D,)."""
    state = np.asarray(state, dtype=np.float64)
    return float(sum(ArmCollision(state, arm, shape, params)(state[None])[0] for arm in _ARMS))
