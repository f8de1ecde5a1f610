"""The filter's hot loop in one pass: for each particle, the pose (the partition's numbers
from the particle, the rest at the estimate), its forward kinematics (only the frames the
partition turns), its parts' geometry and their likelihood (eq. 7-9,
:func:`~optrack.skeleton.likelihood.likelihood_pose`), in one numba kernel parallel over
groups of ``LANES`` particles, with no array per particle in between.

The kinematics and the geometry of a group are computed together, the particle last
in every array, so that each step is one vector operation over the group (a pose's
chain of small rotations, done one pose at a time, is scalar code); the likelihood
then scores the group's poses one by one.

:func:`score_particles` is tested equal to the plain path
(:func:`~optrack.skeleton.model.forward_kinematics`,
:func:`~optrack.skeleton.model.part_geometry` and
:func:`~optrack.skeleton.likelihood.log_likelihood_numpy` on the composed states) in
tests/skeleton/test_likelihood_kernels.py.
"""

from __future__ import annotations

import numba
import numpy as np

from optrack.skeleton.likelihood import likelihood_within, set_threads
from optrack.skeleton.model import (
    FK_TABLES,
    FRAMES,
    PART_TABLES,
    BodyShape,
    D,
    G,
    forward_kinematics,
)

__all__ = ["part_distances", "score_particles", "segment_distances"]

LANES = 32  # poses whose kinematics and geometry are computed together (vector lanes)


@numba.njit(fastmath=True, inline="always")
def _fk_lanes(xs, cs, sn, offsets, frames_on, points_on, rot, pts, tables):
    """:func:`~optrack.skeleton.model.fk_pose` for a few poses at once, the pose last in
    every array (so that each step is a vector op): xs, cs, sn (D, lanes); rot
    (F, 3, 3, lanes), pts (Q, 3, lanes); only the frames ``frames_on`` and the points
    ``points_on`` (those that hang on them) are computed; ``tables``: FK_TABLES."""
    fparent, fdof, faxis, fsign, pparent, pframe = tables
    lanes = xs.shape[1]
    for f in frames_on:
        q = fparent[f]
        for r in range(3):
            for c in range(3):
                if q >= 0:
                    rot[f, r, c, :] = rot[q, r, c, :]
                else:
                    rot[f, r, c, :] = 1.0 if r == c else 0.0
        for j in range(3):  # R <- R @ (rotation about axis k by the dof's angle)
            d = fdof[f, j]
            if d < 0:
                break
            k = faxis[f, j]
            i, m, sign = (k + 1) % 3, (k + 2) % 3, fsign[f, j]
            cd, sd = cs[d], sn[d]
            for r in range(3):
                ri, rm = rot[f, r, i], rot[f, r, m]
                for lane in range(lanes):
                    cos, sin = cd[lane], sd[lane] * sign
                    a, b = ri[lane], rm[lane]
                    ri[lane] = cos * a + sin * b
                    rm[lane] = cos * b - sin * a
    for n in points_on:
        f, q = pframe[n], pparent[n]
        o0, o1, o2 = offsets[n, 0], offsets[n, 1], offsets[n, 2]
        for r in range(3):
            dst = pts[n, r]
            if q < 0:
                dst[:] = xs[r]
                continue
            src, r0, r1, r2 = pts[q, r], rot[f, r, 0], rot[f, r, 1], rot[f, r, 2]
            for lane in range(lanes):
                dst[lane] = src[lane] + (r0[lane] * o0 + r1[lane] * o1 + r2[lane] * o2)


@numba.njit(fastmath=True, inline="always")
def _geometry_lanes(pts, rot, parts, tables, radii, out):
    """:func:`~optrack.skeleton.model.geometry_pose` for a few poses at once: pts
    (Q, 3, lanes), rot (F, 3, 3, lanes), out (len(parts), G, lanes); ``tables``:
    PART_TABLES."""
    pa, pb, pf, pt, aspect = tables
    lanes = pts.shape[2]
    for j in range(parts.shape[0]):
        k = parts[j]
        a, b, f = pa[k], pb[k], pf[k]
        w, t0, t1 = 1.0 / aspect[k], pt[k, 0], pt[k, 1]
        row = out[j]
        for lane in range(lanes):
            u0 = pts[b, 0, lane] - pts[a, 0, lane]
            u1 = pts[b, 1, lane] - pts[a, 1, lane]
            u2 = pts[b, 2, lane] - pts[a, 2, lane]
            length = max(np.sqrt(u0 * u0 + u1 * u1 + u2 * u2), 1e-9)
            u0, u1, u2 = u0 / length, u1 / length, u2 / length
            # The forward axis: the frame's x made square to the bone (its y if parallel).
            x0, x1, x2 = rot[f, 0, 0, lane], rot[f, 1, 0, lane], rot[f, 2, 0, lane]
            side = abs(x0 * u0 + x1 * u1 + x2 * u2) >= 0.999
            c0 = rot[f, 0, 1, lane] if side else x0
            c1 = rot[f, 1, 1, lane] if side else x1
            c2 = rot[f, 2, 1, lane] if side else x2
            dot = c0 * u0 + c1 * u1 + c2 * u2
            e0, e1, e2 = c0 - dot * u0, c1 - dot * u1, c2 - dot * u2
            en = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
            e0, e1, e2 = e0 / en, e1 / en, e2 / en
            for r in range(3):
                row[r, lane] = pts[a, r, lane]
            row[3, lane], row[4, lane], row[5, lane] = u0, u1, u2
            row[6, lane], row[7, lane], row[8, lane] = e0, e1, e2
            row[9, lane] = (u1 * e2 - u2 * e1) * w
            row[10, lane] = (u2 * e0 - u0 * e2) * w
            row[11, lane] = (u0 * e1 - u1 * e0) * w
            row[12, lane], row[13, lane] = t0 * length, t1 * length
            row[14, lane], row[15, lane] = radii[k, 0], radii[k, 1] - radii[k, 0]
            row[16, lane] = 1.0 / length


@numba.njit(fastmath=True, inline="always")
def _extents_lanes(geometry, axis, widen, out):
    """:func:`~optrack.skeleton.likelihood._extent` of each part of a few poses at once:
    geometry (K, G, lanes); out (2 K, lanes): each part's low and high along ``axis``
    (its reach: ``widen`` times its largest radius)."""
    for k in range(geometry.shape[0]):
        g = geometry[k]
        for lane in range(geometry.shape[2]):
            ux, uy, uz = g[3, lane], g[4, lane], g[5, lane]
            ex, ey, ez = g[6, lane], g[7, lane], g[8, lane]
            side = uy * ez - uz * ey
            if axis == 1:
                side = uz * ex - ux * ez
            elif axis == 2:
                side = ux * ey - uy * ex
            fx, fy, fz = g[9, lane], g[10, lane], g[11, lane]
            aspect = 1.0 / np.sqrt(fx * fx + fy * fy + fz * fz)
            u, e = g[3 + axis, lane], g[6 + axis, lane]
            reach = widen * max(g[14, lane], g[14, lane] + g[15, lane])
            half = reach * np.sqrt(u * u + e * e + (aspect * side) ** 2) * 1.001 + 1e-4
            start, end = g[axis, lane] + g[12, lane] * u, g[axis, lane] + g[13, lane] * u
            out[2 * k, lane] = min(start, end) - half
            out[2 * k + 1, lane] = max(start, end) + half


@numba.njit(parallel=True, fastmath=True, cache=True)
def _score_kernel(
    particles, estimate, dims, cos_p, sin_p, cos_e, sin_e, base_rot, base_pts, offsets, frames_on,
    points_on, parts, radii, fk_tables, part_tables, px, py, pz, axis, starts, grid, base,
    expected, consts, out,
):  # fmt: skip
    n = particles.shape[0]
    for c in numba.prange((n + LANES - 1) // LANES):  # LANES particles at a time
        first = c * LANES
        lanes = min(LANES, n - first)
        xs = np.empty((D, lanes))
        cs, sn = np.empty((D, lanes), np.float32), np.empty((D, lanes), np.float32)
        for d in range(D):
            xs[d, :], cs[d, :], sn[d, :] = estimate[d], cos_e[d], sin_e[d]
        for j in range(dims.shape[0]):
            d = dims[j]
            for lane in range(lanes):
                xs[d, lane] = particles[first + lane, d]
                cs[d, lane], sn[d, lane] = cos_p[first + lane, j], sin_p[first + lane, j]
        rot = np.empty(base_rot.shape + (lanes,))
        pts = np.empty(base_pts.shape + (lanes,))
        for f in range(base_rot.shape[0]):
            for r in range(3):
                for q in range(3):
                    rot[f, r, q, :] = base_rot[f, r, q]
        for q in range(base_pts.shape[0]):
            for r in range(3):
                pts[q, r, :] = base_pts[q, r]
        _fk_lanes(xs, cs, sn, offsets, frames_on, points_on, rot, pts, fk_tables)
        geometry = np.empty((parts.shape[0], G, lanes), dtype=np.float32)
        _geometry_lanes(pts, rot, parts, part_tables, radii, geometry)
        best, area = np.empty_like(base), np.empty(base.shape[0], dtype=np.int32)
        extents = np.empty((2 * parts.shape[0], lanes), dtype=np.float32)
        _extents_lanes(geometry, axis, 1.0 + consts[1], extents)
        runs = np.empty(2 * parts.shape[0])
        pose = np.empty((parts.shape[0], G), dtype=np.float32)  # one pose's, contiguous
        for lane in range(lanes):
            pose[:, :] = geometry[:, :, lane]
            runs[:] = extents[:, lane]
            out[first + lane] = likelihood_within(
                px, py, pz, axis, starts, grid, base, pose, expected, consts, best, area, runs
            )


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
    are the ``parts`` (indices) against ``cloud``
    (:func:`~optrack.skeleton.likelihood.sorted_points`, made once for all the layers of
    an anneal), with ``expected`` (K, 2) points
    per area of interest and ``consts`` (sigma, alpha, support_weight)."""
    estimate = np.asarray(estimate, dtype=np.float64)
    base_pts, base_rot = forward_kinematics(estimate, shape)
    dims = np.asarray(dims, dtype=np.int64)
    particles = np.ascontiguousarray(particles, dtype=np.float64)
    # Sines and cosines in float32 by numpy's vector path, as forward_kinematics does.
    turned, fixed = particles[:, dims].astype(np.float32), estimate.astype(np.float32)
    chosen = np.array([name in frames for name in FRAMES])
    frames_on = np.flatnonzero(chosen)
    points_on = np.flatnonzero(chosen[FK_TABLES[-1]])  # the points on those frames
    sigma, alpha, weight = consts
    out = np.empty(len(particles))
    set_threads(threads)
    _score_kernel(
        particles, estimate, dims, np.cos(turned), np.sin(turned), np.cos(fixed),
        np.sin(fixed), base_rot, base_pts, shape._offsets, frames_on, points_on,
        np.asarray(parts, dtype=np.int64), shape.radii_array, FK_TABLES, PART_TABLES,
        *cloud, np.asarray(expected, dtype=np.float64).reshape(-1),
        np.array([1.0 / (2.0 * sigma * sigma), alpha, weight]), out,
    )  # fmt: skip
    return out


@numba.njit(cache=True)
def part_distances(points: np.ndarray, geometry: np.ndarray) -> np.ndarray:
    """|d| of eq. 7 of each point (N, 3) to each part of one pose, geometry (K, G): (N, K),
    as :func:`~optrack.skeleton.likelihood.signed_distance` computes it (float64)."""
    out = np.empty((points.shape[0], geometry.shape[0]))
    for k in range(geometry.shape[0]):
        g = geometry[k].astype(np.float64)
        for n in range(points.shape[0]):
            v0, v1, v2 = points[n, 0] - g[0], points[n, 1] - g[1], points[n, 2] - g[2]
            s = v0 * g[3] + v1 * g[4] + v2 * g[5]
            e = v0 * g[6] + v1 * g[7] + v2 * g[8]
            f = v0 * g[9] + v1 * g[10] + v2 * g[11]
            over = max(max(g[12] - s, s - g[13]), 0.0)
            r = g[14] + g[15] * min(max(s * g[16], 0.0), 1.0)
            out[n, k] = abs(np.sqrt(e * e + f * f + over * over) / r - 1.0)
    return out


@numba.njit(cache=True)
def segment_distances(points: np.ndarray, geometry: np.ndarray) -> np.ndarray:
    """Distance (m) of each point (N, 3) to each part's axis segment (from s0 to s1 along
    it), geometry (K, G) of one pose: (N, K)."""
    out = np.empty((points.shape[0], geometry.shape[0]))
    for k in range(geometry.shape[0]):
        g = geometry[k].astype(np.float64)
        for n in range(points.shape[0]):
            v0, v1, v2 = points[n, 0] - g[0], points[n, 1] - g[1], points[n, 2] - g[2]
            s = min(max(v0 * g[3] + v1 * g[4] + v2 * g[5], g[12]), g[13])
            w0, w1, w2 = v0 - s * g[3], v1 - s * g[4], v2 - s * g[5]
            out[n, k] = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    return out
