"""The filter's hot loop in one pass: for each particle, the pose (the partition's numbers
from the particle, the rest at the estimate), its forward kinematics (only the frames the
partition turns), its parts' geometry and their likelihood (eq. 7-9), in one numba kernel
parallel over particles, with no array per particle in between.

:func:`score_particles` is tested equal to the plain path it replaces
(:func:`~optrack.skeleton.model.forward_kinematics`,
:func:`~optrack.skeleton.model.part_geometry` and
:func:`~optrack.skeleton.likelihood.log_likelihood_numpy` on the composed states).
"""

from __future__ import annotations

import numba
import numpy as np

from optrack.skeleton.likelihood import likelihood_pose, set_threads
from optrack.skeleton.model import (
    FK_TABLES,
    FRAMES,
    PART_TABLES,
    BodyShape,
    G,
    fk_pose,
    forward_kinematics,
    geometry_pose,
)

__all__ = ["score_particles"]


@numba.njit(parallel=True, fastmath=True, cache=True)
def _score_kernel(
    particles, estimate, dims, cos_p, sin_p, cos_e, sin_e, base_rot, base_pts, offsets, chosen, parts,
    radii, fk_tables, part_tables, px, py, pz, axis, starts, grid, baseline, expected, consts,
    out,
):  # fmt: skip
    n, chunks = particles.shape[0], min(particles.shape[0], 64)
    for c in numba.prange(chunks):  # scratch once per chunk of particles
        x, cos_x, sin_x = estimate.copy(), cos_e.copy(), sin_e.copy()
        rot, pts = base_rot.copy(), base_pts.copy()
        geometry = np.empty((parts.shape[0], G), dtype=np.float32)
        best, area = np.empty_like(baseline), np.empty(baseline.shape[0], dtype=np.int32)
        counts = np.empty(2 * parts.shape[0])
        for p in range(c * n // chunks, (c + 1) * n // chunks):
            for j in range(dims.shape[0]):
                d = dims[j]
                x[d], cos_x[d], sin_x[d] = particles[p, d], cos_p[p, j], sin_p[p, j]
            fk_pose(x, cos_x, sin_x, offsets, chosen, rot, pts, *fk_tables)
            geometry_pose(pts, rot, parts, *part_tables, radii, geometry)
            out[p] = likelihood_pose(
                px, py, pz, axis, starts, grid, baseline, geometry, expected, consts, best,
                area, counts,
            )  # fmt: skip


def score_particles(
    particles: np.ndarray,
    estimate: np.ndarray,
    dims: tuple[int, ...],
    frames: tuple[str, ...],
    parts: np.ndarray,
    shape: BodyShape,
    cloud: tuple,
    expected: np.ndarray,
    consts: tuple[float, float, float],
    threads: int = 1,
) -> np.ndarray:
    """Log-likelihood (eq. 9) of each particle (P, D) of a partition, (P,).

    A particle's pose is ``estimate`` with the numbers ``dims`` taken from the particle;
    ``frames`` are the frames those numbers turn (the rest are the estimate's); scored
    are the ``parts`` (indices) against ``cloud``, the points and the fixed parts'
    baseline as :func:`~optrack.skeleton.likelihood.sorted_points` gives them (made
    once for all the layers of an anneal), with ``expected`` (K, 2) points per area of
    interest and ``consts`` (sigma, alpha, support_weight)."""
    estimate = np.asarray(estimate, dtype=np.float64)
    base_pts, base_rot = forward_kinematics(estimate, shape)
    dims = np.asarray(dims, dtype=np.int64)
    particles = np.ascontiguousarray(particles, dtype=np.float64)
    # Sines and cosines in float32 by numpy's vector path, as forward_kinematics does.
    turned, fixed = particles[:, dims].astype(np.float32), estimate.astype(np.float32)
    chosen = np.array([name in frames for name in FRAMES])
    sigma, alpha, weight = consts
    out = np.empty(len(particles))
    set_threads(threads)
    _score_kernel(
        particles, estimate, dims, np.cos(turned), np.sin(turned), np.cos(fixed),
        np.sin(fixed), base_rot, base_pts, shape._offsets, chosen,
        np.asarray(parts, dtype=np.int64), shape.radii_array, FK_TABLES, PART_TABLES,
        *cloud, np.asarray(expected, dtype=np.float64).reshape(-1),
        np.array([1.0 / (2.0 * sigma * sigma), alpha, weight]), out,
    )  # fmt: skip
    return out
