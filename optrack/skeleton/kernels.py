"""The filter's hot loop in one pass: for each particle, the pose (the partition's numbers
from the particle, the rest at the estimate), its forward kinematics (only the frames the
partition turns), its parts' geometry and their likelihood (eq. 7-9,
:func:`~optrack.skeleton.likelihood.likelihood_pose`), in one numba kernel parallel over
groups of ``LANES`` particles, with no array per particle in between.

The kinematics and the geometry of a group are computed together, the particle last
in every array, so that each step is one vector operation over the group (a pose's
chain of small rotations, done one pose at a time, is scalar code); the likelihood
then scores the group's poses one by one.

:class:`PartitionScorer` is tested equal to the plain path
(:func:`~optrack.skeleton.model.forward_kinematics`,
:func:`~optrack.skeleton.model.part_geometry` and
:func:`~optrack.skeleton.likelihood.log_likelihood_numpy` on the composed states) in
tests/skeleton/test_likelihood_kernels.py.
"""

from __future__ import annotations

import functools

import numba
import numpy as np

from optrack.skeleton.likelihood import (
    capped_prefix,
    likelihood_within,
    set_threads,
    signed_distance,
)
from optrack.skeleton.model import (
    FK_TABLES,
    FRAMES,
    PART_TABLES,
    BodyShape,
    D,
    G,
    forward_kinematics,
)

__all__ = [
    "PartitionScorer",
    "limb_points",
    "limb_points_numpy",
    "nearest_areas",
    "point_distance",
]

LANES = 32  # poses whose kinematics and geometry are computed together (vector lanes)
GROUPS = 8  # groups of LANES poses that threads share (each makes its scratch once)


@numba.njit(fastmath=True, inline="always")
def fk_lanes(xs, cs, sn, offsets, frames_on, points_on, rot, pts, tables):
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
def particle_lanes(particles, dims, cos, sin, first, xs, cs, sn):
    """Put the numbers ``dims`` of the ``LANES`` particles from ``first`` on (their
    cosines and sines ``cos``, ``sin``, (P, len(dims))) in the lanes :func:`fk_lanes`
    reads (xs, cs, sn: (D, lanes)); returns how many lanes hold a particle."""
    lanes = min(xs.shape[1], particles.shape[0] - first)
    for j in range(dims.shape[0]):
        d = dims[j]
        for lane in range(lanes):
            xs[d, lane] = particles[first + lane, d]
            cs[d, lane], sn[d, lane] = cos[first + lane, j], sin[first + lane, j]
    return lanes


@numba.njit(fastmath=True, inline="always")
def _geometry_lanes(pts, rot, parts, tables, radii, out):
    """:func:`~optrack.skeleton.model.geometry_pose` for a few poses at once: pts
    (Q, 3, lanes), rot (F, 3, 3, lanes), out (len(parts), G, lanes); ``tables``:
    PART_TABLES. The bone is the difference of its ends in float64; the rest in float32
    (what ``out`` holds), its two normalisations by reciprocal square roots."""
    pa, pb, pf, pt, aspect = tables
    lanes = pts.shape[2]
    one, tiny = np.float32(1.0), np.float32(1e-18)
    for j in range(parts.shape[0]):
        k = parts[j]
        a, b, f = pa[k], pb[k], pf[k]
        w, t0, t1 = np.float32(1.0 / aspect[k]), np.float32(pt[k, 0]), np.float32(pt[k, 1])
        r0, dr = np.float32(radii[k, 0]), np.float32(radii[k, 1] - radii[k, 0])
        row = out[j]
        for lane in range(lanes):
            u0 = np.float32(pts[b, 0, lane] - pts[a, 0, lane])
            u1 = np.float32(pts[b, 1, lane] - pts[a, 1, lane])
            u2 = np.float32(pts[b, 2, lane] - pts[a, 2, lane])
            squared = max(u0 * u0 + u1 * u1 + u2 * u2, tiny)  # the length at least 1e-9
            inverse = one / np.sqrt(squared)
            length = squared * inverse
            u0, u1, u2 = u0 * inverse, u1 * inverse, u2 * inverse
            # The forward axis: the frame's x made square to the bone (its y if parallel).
            x0 = np.float32(rot[f, 0, 0, lane])
            x1 = np.float32(rot[f, 1, 0, lane])
            x2 = np.float32(rot[f, 2, 0, lane])
            side = abs(x0 * u0 + x1 * u1 + x2 * u2) >= np.float32(0.999)
            c0 = np.float32(rot[f, 0, 1, lane]) if side else x0
            c1 = np.float32(rot[f, 1, 1, lane]) if side else x1
            c2 = np.float32(rot[f, 2, 1, lane]) if side else x2
            dot = c0 * u0 + c1 * u1 + c2 * u2
            e0, e1, e2 = c0 - dot * u0, c1 - dot * u1, c2 - dot * u2
            inverse_e = one / np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
            e0, e1, e2 = e0 * inverse_e, e1 * inverse_e, e2 * inverse_e
            for r in range(3):
                row[r, lane] = pts[a, r, lane]
            row[3, lane], row[4, lane], row[5, lane] = u0, u1, u2
            row[6, lane], row[7, lane], row[8, lane] = e0, e1, e2
            row[9, lane] = (u1 * e2 - u2 * e1) * w
            row[10, lane] = (u2 * e0 - u0 * e2) * w
            row[11, lane] = (u0 * e1 - u1 * e0) * w
            row[12, lane], row[13, lane] = t0 * length, t1 * length
            row[14, lane], row[15, lane] = r0, dr
            row[16, lane] = inverse


@numba.njit(fastmath=True, inline="always")
def _extents_lanes(geometry, axis, widen, out):
    """:func:`~optrack.skeleton.likelihood._extent` of each part of a few poses at once:
    geometry (K, G, lanes); out (2 K, lanes): each part's low and high along ``axis``
    (its reach: ``widen`` times its largest radius), in float32 (the margin of 1e-4 m
    and 0.1 % covers its rounding)."""
    widen, one = np.float32(widen), np.float32(1.0)
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
            aspect = one / np.sqrt(fx * fx + fy * fy + fz * fz)
            u, e = g[3 + axis, lane], g[6 + axis, lane]
            reach = widen * max(g[14, lane], g[14, lane] + g[15, lane])
            half = reach * np.sqrt(u * u + e * e + (aspect * side) ** 2) * np.float32(1.001)
            half += np.float32(1e-4)
            start, end = g[axis, lane] + g[12, lane] * u, g[axis, lane] + g[13, lane] * u
            out[2 * k, lane] = min(start, end) - half
            out[2 * k + 1, lane] = max(start, end) + half


@numba.njit(parallel=True, fastmath=True, cache=True)
def _score_kernel(
    particles, dims, cos_p, sin_p, fixed, copied, base_rot, base_pts, offsets, frames_on,
    points_on, parts, radii, fk_tables, part_tables, px, py, pz, axis, starts, grid, base,
    expected, consts, out,
):  # fmt: skip
    estimate, cos_e, sin_e = fixed
    copy_dofs, copy_frames, copy_points = copied
    n, k = particles.shape[0], parts.shape[0]
    prefix = capped_prefix(base, consts[1])
    chunks = (n + LANES - 1) // LANES  # of LANES particles, scored together
    groups = min(chunks, GROUPS)
    for group in numba.prange(groups):  # scratch made once per group of chunks
        # Filled in once: what the partition's kinematics and parts read but do not turn
        # (the estimate's numbers, frames and points); zeros elsewhere, so that the
        # lanes past the last particle compute on numbers.
        xs = np.zeros((D, LANES))
        cs, sn = np.zeros((D, LANES), np.float32), np.zeros((D, LANES), np.float32)
        for d in copy_dofs:
            xs[d, :], cs[d, :], sn[d, :] = estimate[d], cos_e[d], sin_e[d]
        rot, pts = np.zeros(base_rot.shape + (LANES,)), np.zeros(base_pts.shape + (LANES,))
        for f in copy_frames:
            for r in range(3):
                for q in range(3):
                    rot[f, r, q, :] = base_rot[f, r, q]
        for q in copy_points:
            for r in range(3):
                pts[q, r, :] = base_pts[q, r]
        geometry = np.empty((k, G, LANES), dtype=np.float32)
        extents = np.empty((2 * k, LANES), dtype=np.float32)
        best, area = np.empty_like(base), np.empty(base.shape[0], dtype=np.int32)
        runs = np.empty(2 * k)
        for c in range(group * chunks // groups, (group + 1) * chunks // groups):
            first = c * LANES
            lanes = particle_lanes(particles, dims, cos_p, sin_p, first, xs, cs, sn)
            fk_lanes(xs, cs, sn, offsets, frames_on, points_on, rot, pts, fk_tables)
            _geometry_lanes(pts, rot, parts, part_tables, radii, geometry)
            _extents_lanes(geometry, axis, 1.0 + consts[1], extents)
            for lane in range(lanes):  # each pose's rows read in place (a copy cost more)
                runs[:] = extents[:, lane]
                out[first + lane] = likelihood_within(
                    px, py, pz, axis, starts, grid, base, prefix, geometry[:, :, lane],
                    expected, consts, best, area, runs,
                )  # fmt: skip


@functools.lru_cache(maxsize=64)
def _layout(frames: tuple[str, ...], parts: tuple[int, ...], dims: tuple[int, ...]) -> tuple:
    """A partition's index arrays, made once: its ``dims``, ``parts``, the frames it
    turns, the points on those frames, and what its kernel reads but does not compute:
    the estimate's numbers (the root's position and the angles of the frames it turns,
    less its own ``dims``), the frames and the points (parents of those it turns, and
    the parts' ends and frames). Shared: read, never written."""
    turned = np.array([name in frames for name in FRAMES])
    frames_on = np.flatnonzero(turned)
    points_on = np.flatnonzero(turned[FK_TABLES[-1]])  # the points on those frames
    fparent, fdof, _, _, pparent, pframe = FK_TABLES
    pa, pb, pf = PART_TABLES[:3]
    rows = {0, 1, 2} | {int(d) for d in fdof[frames_on].ravel() if d >= 0}
    read = {int(fparent[f]) for f in frames_on} | {int(pframe[q]) for q in points_on}
    read |= {int(pf[k]) for k in parts}
    points = {int(pparent[q]) for q in points_on} | {int(pa[k]) for k in parts}
    points |= {int(pb[k]) for k in parts}
    copied = tuple(
        np.array(sorted(chosen - set(own) - {-1}), dtype=np.int64)
        for chosen, own in ((rows, dims), (read, frames_on), (points, points_on))
    )
    index = np.array(dims, dtype=np.int64), np.array(parts, dtype=np.int64)
    return (*index, frames_on, points_on, copied)


class PartitionScorer:
    """Log-likelihood (eq. 9) of particles of a partition: ``scorer(particles)`` (P, D)
    gives (P,).

    A particle's pose is ``estimate`` with the numbers ``dims`` taken from the particle;
    ``frames`` are the frames those numbers turn (the rest are the estimate's); scored
    are the ``parts`` (indices) against ``cloud``
    (:func:`~optrack.skeleton.likelihood.sorted_points`), with ``expected`` (K, 2) points
    per area of interest and ``consts`` (sigma, alpha, support_weight). Everything that
    does not depend on the particles is made once: an anneal scores the same partition
    against the same estimate and cloud in every layer (``base``: the estimate's
    :func:`~optrack.skeleton.model.forward_kinematics`, where the caller has it)."""

    def __init__(
        self,
        estimate: np.ndarray,
        dims: tuple[int, ...],
        frames: tuple[str, ...],
        parts: np.ndarray,
        shape: BodyShape,
        cloud: tuple,
        expected: np.ndarray,
        consts: tuple[float, float, float],
        threads: int = 1,
        base: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> None:
        estimate = np.asarray(estimate, dtype=np.float64)
        base_pts, base_rot = forward_kinematics(estimate, shape) if base is None else base
        self.dims, parts, frames_on, points_on, copied = _layout(
            tuple(frames), tuple(int(k) for k in np.asarray(parts)), tuple(int(d) for d in dims)
        )
        # Sines and cosines in float32 by numpy's vector path, as forward_kinematics does.
        fixed = estimate.astype(np.float32)
        sigma, alpha, weight = consts
        self.threads = int(threads)
        self._args = (
            (estimate, np.cos(fixed), np.sin(fixed)),
            copied, base_rot, base_pts,
            shape._offsets, frames_on, points_on, parts, shape.radii_array, FK_TABLES,
            PART_TABLES, *cloud, np.asarray(expected, dtype=np.float64).reshape(-1),
            np.array([1.0 / (2.0 * sigma * sigma), alpha, weight]),
        )  # fmt: skip

    def __call__(self, particles: np.ndarray) -> np.ndarray:
        """Log-likelihood (eq. 9) of each particle (P, D), (P,)."""
        particles = np.ascontiguousarray(particles, dtype=np.float64)
        turned = particles[:, self.dims].astype(np.float32)
        out = np.empty(len(particles))
        set_threads(self.threads)
        _score_kernel(particles, self.dims, np.cos(turned), np.sin(turned), *self._args, out)
        return out


@numba.njit(cache=True, inline="always")
def point_distance(points, n, g):
    """d of eq. 7 of point n to the part of row g (float64), signed (negative inside the
    part), and its coordinate along the bone in bone lengths."""
    v0, v1, v2 = points[n, 0] - g[0], points[n, 1] - g[1], points[n, 2] - g[2]
    s = v0 * g[3] + v1 * g[4] + v2 * g[5]
    e = v0 * g[6] + v1 * g[7] + v2 * g[8]
    f = v0 * g[9] + v1 * g[10] + v2 * g[11]
    over = max(max(g[12] - s, s - g[13]), 0.0)
    t = s * g[16]
    r = g[14] + g[15] * min(max(t, 0.0), 1.0)
    return np.sqrt(e * e + f * f + over * over) / r - 1.0, t


@numba.njit(cache=True, inline="always")
def _distance(points, n, g):
    """|d| of eq. 7 of point n to the part of row g, and its coordinate along the bone."""
    d, t = point_distance(points, n, g)
    return abs(d), t


@numba.njit(cache=True)
def nearest_areas(points: np.ndarray, geometry: np.ndarray, alpha: float) -> np.ndarray:
    """Eq. 8 for one pose, geometry (K, G): each point's (N, 3) area of interest, 2 k +
    half (1 from the middle of the bone on), of the part k nearest it in |d| if that is
    under ``alpha``, else -1, (N,): the areas
    :func:`~optrack.skeleton.likelihood.associate` gives (no baseline), to the bit."""
    best = np.full(points.shape[0], np.inf)
    area = np.full(points.shape[0], -1, dtype=np.int64)
    for k in range(geometry.shape[0]):
        g = geometry[k].astype(np.float64)
        for n in range(points.shape[0]):
            d, t = _distance(points, n, g)
            if d < best[n]:  # the first nearest, as argmin
                best[n] = d
                area[n] = 2 * k + (1 if t >= 0.5 else 0)
    for n in range(points.shape[0]):
        if not best[n] < alpha:
            area[n] = -1
    return area


@numba.njit(cache=True)
def limb_points(points, geometry, fixed, own, alpha, gate, root, reach):
    """What a limb is scored on, in one pass over the points (N, 3) and the parts of one
    pose, geometry (K, G): each point's baseline, its |d| of eq. 7 to the nearest part
    ``fixed`` (K,) marks (the rest of the body), capped at ``alpha``; and whether it is
    near the limb: with ``gate`` > 0 (tracking), within ``gate`` of the axis of one of
    the parts ``own`` or farther than ``alpha`` from every part; else within ``reach``
    of the point ``root`` (3,). Returns (baseline (N,), near (N,) bool), as
    :func:`limb_points_numpy` (the reference) gives them."""
    n, k = points.shape[0], geometry.shape[0]
    rows = geometry.astype(np.float64)
    baseline = np.empty(n)
    near = np.empty(n, dtype=np.bool_)
    for i in range(n):
        nearest, base = np.inf, np.inf
        for j in range(k):
            d = _distance(points, i, rows[j])[0]
            nearest = min(nearest, d)
            if fixed[j]:
                base = min(base, d)
        baseline[i] = min(base, alpha)
        if gate > 0.0:
            close = nearest >= alpha
            for j in own:
                g = rows[j]
                v0, v1, v2 = points[i, 0] - g[0], points[i, 1] - g[1], points[i, 2] - g[2]
                s = min(max(v0 * g[3] + v1 * g[4] + v2 * g[5], g[12]), g[13])
                w0, w1, w2 = v0 - s * g[3], v1 - s * g[4], v2 - s * g[5]
                close |= np.sqrt(w0 * w0 + w1 * w1 + w2 * w2) < gate
            near[i] = close
        else:
            v0, v1, v2 = points[i, 0] - root[0], points[i, 1] - root[1], points[i, 2] - root[2]
            near[i] = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2) < reach
    return baseline, near


def limb_points_numpy(points, geometry, fixed, own, alpha, gate, root, reach):
    """:func:`limb_points` in plain numpy: the reference it is tested against."""
    g = np.asarray(geometry, dtype=np.float64)
    distance = np.abs(signed_distance(points, g[None])[0][0])  # (N, K)
    baseline = np.minimum(distance[:, np.asarray(fixed, dtype=bool)].min(axis=1), alpha)
    if gate > 0.0:
        mine = g[np.asarray(own)]
        v = points[:, None, :] - mine[None, :, 0:3]
        s = np.clip(np.sum(v * mine[None, :, 3:6], axis=2), mine[:, 12], mine[:, 13])
        segment = np.linalg.norm(v - s[..., None] * mine[None, :, 3:6], axis=2)
        near = (segment.min(axis=1) < gate) | (distance.min(axis=1) >= alpha)
    else:
        near = np.linalg.norm(points - np.asarray(root), axis=1) < reach
    return baseline, near
