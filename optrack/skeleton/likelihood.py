"""The likelihood of a fused cloud given body poses (MDCA eq. 7-9), for many poses at once.

Eq. 7, the signed scaled distance of a point ``p`` to a part (an extended
cylinder, see optrack/skeleton/model.py): with ``s`` the point's coordinate
along the bone, ``(e, f)`` its coordinates across it (``f`` already divided by
the part's aspect), ``o`` how far ``s`` overshoots the cylinder's extent
``[s0, s1]`` and ``r(s)`` the forward radius there,

    d = sqrt(e^2 + f^2 + o^2) / r(s) - 1

so ``d = 0`` on the surface, ``-1`` on the axis, ``1`` one radius outside.

Eq. 8, data association: each point belongs to the part it is nearest to in
``|d|``, if that is under the threshold ``alpha``; otherwise it is clutter and
costs ``alpha``.

Eq. 9, the likelihood: ``log L = -sum_i min(|d_i|, alpha)^2 / (2 sigma^2) / N``
(a Gaussian on the scaled distance, averaged over the N points), minus
``support_weight`` for each area of interest left without data. A part has
two areas of interest, its halves near each of its joints; an area is
expected to hold ``expected[k, half]`` associated points and pays
``max(0, 1 - n / expected)``. This term (ours; the paper's points-to-model
distance alone lets a limb float in empty space) keeps limbs on the data.

Two implementations: :func:`log_likelihood_numpy` (the reference, plain
numpy) and :func:`log_likelihood` (numba, parallel over poses), tested equal.
"""

from __future__ import annotations

import numba
import numpy as np

from optrack.skeleton.model import G

__all__ = [
    "associate",
    "log_likelihood",
    "log_likelihood_numpy",
    "signed_distance",
]


def signed_distance(points: np.ndarray, geometry: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 7 for every pose, point and part: d (P, N, K), and the area of interest
    each point falls in along each part (0 near the start joint, 1 near the end).

    ``points`` (N, 3) world metres; ``geometry`` (P, K, G) from
    :func:`optrack.skeleton.model.part_geometry`.
    """
    g = np.asarray(geometry, dtype=np.float64)
    v = np.asarray(points, dtype=np.float64)[None, :, None, :] - g[:, None, :, 0:3]
    s = np.sum(v * g[:, None, :, 3:6], axis=-1)
    e = np.sum(v * g[:, None, :, 6:9], axis=-1)
    f = np.sum(v * g[:, None, :, 9:12], axis=-1)
    s0, s1 = g[:, None, :, 12], g[:, None, :, 13]
    over = np.maximum(np.maximum(s0 - s, s - s1), 0.0)
    t = s * g[:, None, :, 16]
    r = g[:, None, :, 14] + g[:, None, :, 15] * np.clip(t, 0.0, 1.0)
    d = np.sqrt(e * e + f * f + over * over) / r - 1.0
    return d, (t >= 0.5).astype(np.int64)


def associate(
    points: np.ndarray,
    geometry: np.ndarray,
    alpha: float,
    baseline: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 8: each point's distance to its part, min(|d|, alpha) (P, N), and its area of
    interest ``2 k + half`` (-1: clutter, or better explained by the ``baseline``)."""
    d, half = signed_distance(points, geometry)
    d = np.abs(d)
    k = np.argmin(d, axis=2)
    best = np.take_along_axis(d, k[..., None], axis=2)[..., 0]
    area = 2 * k + np.take_along_axis(half, k[..., None], axis=2)[..., 0]
    limit = np.full(best.shape[1], alpha) if baseline is None else np.minimum(baseline, alpha)
    explained = best < limit[None, :]
    return np.where(explained, best, limit[None, :]), np.where(explained, area, -1)


def log_likelihood_numpy(
    points: np.ndarray,
    geometry: np.ndarray,
    expected: np.ndarray,
    sigma: float,
    alpha: float,
    support_weight: float,
    baseline: np.ndarray | None = None,
) -> np.ndarray:
    """Eq. 9 for each pose, (P,): the reference implementation.

    ``expected`` (K, 2): points each area of interest should hold; ``baseline``
    (N,): each point's distance to parts already fixed (it caps the point's
    cost, and such a point supports none of these parts)."""
    best, area = associate(points, geometry, alpha, baseline)
    data = np.sum(best * best, axis=1) / (2.0 * sigma * sigma) / max(best.shape[1], 1)
    k2 = 2 * geometry.shape[1]
    counts = np.stack([np.bincount(a[a >= 0], minlength=k2) for a in area])
    exp = np.asarray(expected, dtype=np.float64).reshape(-1)
    deficit = np.where(exp > 0, np.maximum(0.0, 1.0 - counts / np.maximum(exp, 1e-9)), 0.0)
    return -data - support_weight * deficit.sum(axis=1)


@numba.njit(parallel=True, fastmath=True, cache=True)
def _kernel(px, py, pz, baseline, geometry, expected, consts, out):
    """consts: 1 / (2 sigma^2), alpha, support_weight."""
    inv_two_sigma2, alpha, weight = consts[0], np.float32(consts[1]), consts[2]
    n = px.shape[0]
    parts = geometry.shape[1]
    for p in numba.prange(geometry.shape[0]):
        best = baseline.copy()
        area = np.full(n, -1, dtype=np.int32)
        for k in range(parts):
            g = geometry[p, k]
            ax, ay, az, ux, uy, uz = g[0], g[1], g[2], g[3], g[4], g[5]
            ex, ey, ez, fx, fy, fz = g[6], g[7], g[8], g[9], g[10], g[11]
            s0, s1, r0, dr, inv_length = g[12], g[13], g[14], g[15], g[16]
            half = np.float32(0.5) / inv_length
            near, far = np.int32(2 * k), np.int32(2 * k + 1)
            for i in range(n):  # no branches, so that it vectorises
                vx, vy, vz = px[i] - ax, py[i] - ay, pz[i] - az
                s = vx * ux + vy * uy + vz * uz
                e = vx * ex + vy * ey + vz * ez
                f = vx * fx + vy * fy + vz * fz
                o = max(max(s0 - s, s - s1), np.float32(0.0))
                r = r0 + dr * min(max(s * inv_length, np.float32(0.0)), np.float32(1.0))
                d = abs(np.sqrt(e * e + f * f + o * o) / r - np.float32(1.0))
                better = d < best[i]
                best[i] = d if better else best[i]
                area[i] = (far if s >= half else near) if better else area[i]
        total = 0.0
        counts = np.zeros(2 * parts, dtype=np.float64)
        for i in range(n):
            b = min(best[i], alpha)
            total += b * b
            if area[i] >= 0 and best[i] < alpha:
                counts[area[i]] += 1.0
        deficit = 0.0
        for j in range(2 * parts):
            if expected[j] > 0.0:
                deficit += max(0.0, 1.0 - counts[j] / expected[j])
        out[p] = -total * inv_two_sigma2 / max(n, 1) - weight * deficit


def log_likelihood(
    points: np.ndarray,
    geometry: np.ndarray,
    expected: np.ndarray,
    sigma: float,
    alpha: float,
    support_weight: float,
    baseline: np.ndarray | None = None,
    threads: int = 1,
) -> np.ndarray:
    """Eq. 9 for each pose, (P,): the fast path (numba, float32 distances).

    Same arguments and result as :func:`log_likelihood_numpy`; ``threads``: how many
    CPU threads share the poses (more helps only where cores are idle: a thread that
    has to wait for a busy core holds every other one up)."""
    numba.set_num_threads(max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS)))
    pts = np.asarray(points, dtype=np.float32)
    geometry = np.ascontiguousarray(geometry, dtype=np.float32)
    if geometry.shape[2] != G:
        raise ValueError(f"part geometry must have {G} fields per part; got {geometry.shape[2]}.")
    if baseline is None:
        base = np.full(len(pts), np.inf, dtype=np.float32)
    else:
        base = np.asarray(baseline, dtype=np.float32).copy()
    out = np.empty(len(geometry), dtype=np.float64)
    _kernel(
        np.ascontiguousarray(pts[:, 0]),
        np.ascontiguousarray(pts[:, 1]),
        np.ascontiguousarray(pts[:, 2]),
        base,
        geometry,
        np.asarray(expected, dtype=np.float64).reshape(-1),
        np.array([1.0 / (2.0 * sigma * sigma), alpha, support_weight]),
        out,
    )
    return out
