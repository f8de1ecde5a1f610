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

from optrack.skeleton.cores import auto_threads
from optrack.skeleton.model import G

W = 16  # points per block of the distance loop (one AVX-512 vector of float32)
BUCKETS = 128  # slices of the sorted cloud along its axis (where a part's points start)
_FAR = 1.0e4  # the baseline of a point no fixed part explains (far beyond any alpha)

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


@numba.njit(cache=True, fastmath=True)
def _extent(g, axis: int, reach: float) -> tuple[float, float]:
    """The interval along ``axis`` outside which every point is at least ``alpha`` radii
    from the part (``reach``: (1 + alpha) times its largest forward radius): its axis
    segment widened by the half-extent of the ellipsoid of radii reach, reach * aspect."""
    ux, uy, uz, ex, ey, ez = g[3], g[4], g[5], g[6], g[7], g[8]
    side = (uy * ez - uz * ey, uz * ex - ux * ez, ux * ey - uy * ex)[axis]  # u x e: the side axis
    aspect = 1.0 / np.sqrt(g[9] * g[9] + g[10] * g[10] + g[11] * g[11])
    u, e = g[3 + axis], g[6 + axis]
    half = reach * np.sqrt(u * u + e * e + (aspect * side) ** 2) * 1.001 + 1e-4
    start, end = g[axis] + g[12] * u, g[axis] + g[13] * u
    return min(start, end) - half, max(start, end) + half


@numba.njit(cache=True, fastmath=True)
def _bucket(value: float, grid, buckets: int) -> int:
    """The bucket of the sorted cloud's axis holding ``value`` (clamped to the ends)."""
    return min(max(int(np.floor((value - grid[0]) * grid[1])), 0), buckets - 1)


@numba.njit(fastmath=True, inline="always")
def _part_run(qx, qy, qz, qb, qa, g, near, far):
    """Eq. 7-8 for one part, geometry row ``g``, on a run of points (views): each point's
    best distance to the parts so far and its area of interest (``near`` or ``far``)."""
    ax, ay, az, ux, uy, uz = g[0], g[1], g[2], g[3], g[4], g[5]
    ex, ey, ez, fx, fy, fz = g[6], g[7], g[8], g[9], g[10], g[11]
    s0, s1, r0, dr, inv_length = g[12], g[13], g[14], g[15], g[16]
    half = np.float32(0.5) / inv_length
    for i in range(qx.shape[0]):  # no branches: it vectorises
        vx, vy, vz = qx[i] - ax, qy[i] - ay, qz[i] - az
        s = vx * ux + vy * uy + vz * uz
        e = vx * ex + vy * ey + vz * ez
        f = vx * fx + vy * fy + vz * fz
        o = max(max(s0 - s, s - s1), np.float32(0.0))
        r = r0 + dr * min(max(s * inv_length, np.float32(0.0)), np.float32(1.0))
        d = abs(np.sqrt(e * e + f * f + o * o) / r - np.float32(1.0))
        better = d < qb[i]
        qb[i] = d if better else qb[i]
        qa[i] = (far if s >= half else near) if better else qa[i]


@numba.njit(fastmath=True, inline="always")
def likelihood_pose(
    px, py, pz, axis, starts, grid, baseline, prefix, geometry, expected, consts, best, area,
    runs,
):  # fmt: skip
    """Eq. 9 for one pose, geometry (K, G), of a cloud from :func:`sorted_points`
    (sorted along ``axis``): each part visits only the run of points that can lie within
    alpha of it, and its areas of interest count their points in that run only (a
    point outside it is not the part's); every sum is a loop without branches. consts:
    1 / (2 sigma^2), alpha, support_weight; ``prefix``: :func:`capped_prefix` of the
    baseline; scratch: best, area (N,), runs (2 K,). Inlined where it is called, where its arrays are known apart: so its loops
    vectorise."""
    for k in range(geometry.shape[0]):
        g = geometry[k]
        reach = (1.0 + consts[1]) * max(g[14], g[14] + g[15])
        runs[2 * k], runs[2 * k + 1] = _extent(g, axis, reach)
    return likelihood_within(
        px, py, pz, axis, starts, grid, baseline, prefix, geometry, expected, consts, best,
        area, runs,
    )  # fmt: skip


@numba.njit(cache=True, fastmath=True)
def capped_prefix(baseline, alpha):
    """The running sums of each point's cost when no part explains it, min(baseline,
    alpha)^2 (float32, as the likelihood squares it), (N + 1,): a pose's points outside
    its parts' runs cost their sum without a pass over them."""
    cap = np.float32(alpha)
    prefix = np.empty(baseline.shape[0] + 1)
    prefix[0] = 0.0
    for i in range(baseline.shape[0]):
        c = min(baseline[i], cap)
        prefix[i + 1] = prefix[i] + c * c
    return prefix


@numba.njit(fastmath=True, inline="always")
def likelihood_within(
    px, py, pz, axis, starts, grid, baseline, prefix, geometry, expected, consts, best, area,
    runs,
):  # fmt: skip
    """:func:`likelihood_pose` given each part's interval along ``axis`` outside which
    every point is at least alpha from it (``runs``: low, high of each part; the part's
    run of points replaces them). Only the span from the first run's start to the last
    one's end is visited; the points outside it cost what ``prefix`` says (a limb's
    parts span a third to two thirds of its points)."""
    alpha = np.float32(consts[1])
    n = px.shape[0]
    span_lo, span_hi = n, 0
    for k in range(geometry.shape[0]):
        low, high = runs[2 * k], runs[2 * k + 1]
        # Whole blocks of W from 0 on views: no remainder, no wraparound; it vectorises.
        lo = starts[_bucket(low, grid, starts.shape[0] - 1)] // W * W
        hi = min(-(-starts[_bucket(high, grid, starts.shape[0] - 1) + 1] // W) * W, n)
        runs[2 * k], runs[2 * k + 1] = lo, hi
        span_lo, span_hi = min(span_lo, lo), max(span_hi, hi)
    span_hi = max(span_hi, span_lo)
    # Capped at alpha from the start: a part takes only the points it explains (within
    # alpha, better than the baseline), so a point has an area exactly when explained.
    # On views from 0 (as the runs): these loops vectorise.
    sb, sc, sa = best[span_lo:span_hi], baseline[span_lo:span_hi], area[span_lo:span_hi]
    for i in range(sb.shape[0]):
        sb[i] = min(sc[i], alpha)
        sa[i] = -1
    for k in range(geometry.shape[0]):
        g = geometry[k]
        lo, hi = int(runs[2 * k]), int(runs[2 * k + 1])
        near, far = np.int32(2 * k), np.int32(2 * k + 1)
        _part_run(px[lo:hi], py[lo:hi], pz[lo:hi], best[lo:hi], area[lo:hi], g, near, far)
    total = prefix[n] - (prefix[span_hi] - prefix[span_lo])
    for i in range(sb.shape[0]):
        total += sb[i] * sb[i]
    deficit = 0.0
    for k in range(geometry.shape[0]):
        lo, hi = int(runs[2 * k]), int(runs[2 * k + 1])
        qa = area[lo:hi]
        near, far = 0, 0
        for i in range(hi - lo):
            near += qa[i] == 2 * k
            far += qa[i] == 2 * k + 1
        if expected[2 * k] > 0.0:
            deficit += max(0.0, 1.0 - near / expected[2 * k])
        if expected[2 * k + 1] > 0.0:
            deficit += max(0.0, 1.0 - far / expected[2 * k + 1])
    return -total * consts[0] / max(n, 1) - consts[2] * deficit


@numba.njit(parallel=True, fastmath=True, cache=True)
def _kernel(px, py, pz, axis, starts, grid, baseline, geometry, expected, consts, out):
    n, chunks = geometry.shape[0], min(geometry.shape[0], 64)
    prefix = capped_prefix(baseline, consts[1])
    for c in numba.prange(chunks):  # scratch once per chunk of poses
        best, area = np.empty_like(baseline), np.empty(baseline.shape[0], dtype=np.int32)
        runs = np.empty(2 * geometry.shape[1])
        for p in range(c * n // chunks, (c + 1) * n // chunks):
            out[p] = likelihood_pose(
                px, py, pz, axis, starts, grid, baseline, prefix, geometry[p], expected,
                consts, best, area, runs,
            )  # fmt: skip


def sorted_points(points: np.ndarray, baseline: np.ndarray | None) -> tuple:
    """The kernels' view of a cloud: (x, y, z, axis, starts, grid, baseline). The points
    (float32, one contiguous array per coordinate) are sorted along the axis of their
    largest extent, cut into BUCKETS equal slices along it: ``starts`` (BUCKETS + 1,)
    is the first point of each, ``grid`` (the axis's first value, buckets per metre)
    finds a value's slice. The baseline (none: a distance far beyond alpha) is in the
    same order. :func:`sorted_points_numpy` is the reference it is tested equal to."""
    pts = np.ascontiguousarray(points, dtype=np.float32).reshape(-1, 3)
    if baseline is None:
        base = np.full(len(pts), _FAR, dtype=np.float32)
    else:
        base = np.asarray(baseline, dtype=np.float32)
    return _sorted_points(pts, base, BUCKETS)


@numba.njit(cache=True)
def _sorted_points(pts, base, buckets):
    """:func:`sorted_points` in one compiled pass (numpy's calls cost 50 us a cloud, a
    frame sorts five to seven): the same numbers to the bit (no fast-math)."""
    n = pts.shape[0]
    axis = 2
    if n:
        widest = -1.0
        for j in range(3):  # np.argmax(np.ptp(pts, axis=0)): the first widest
            low, high = pts[0, j], pts[0, j]
            for i in range(n):
                low, high = min(low, pts[i, j]), max(high, pts[i, j])
            if high - low > widest:
                widest, axis = high - low, j
    order = np.argsort(pts[:, axis], kind="mergesort")  # stable, as numpy's
    x, y, z = np.empty(n, np.float32), np.empty(n, np.float32), np.empty(n, np.float32)
    sorted_base = np.empty(n, np.float32)
    for i in range(n):
        o = order[i]
        x[i], y[i], z[i], sorted_base[i] = pts[o, 0], pts[o, 1], pts[o, 2], base[o]
    key = x if axis == 0 else (y if axis == 1 else z)
    first, last = (float(key[0]), float(key[n - 1])) if n else (0.0, 1.0)
    grid = np.array([first, buckets / max(last - first, 1e-6)])
    starts = np.empty(buckets + 1, np.int64)
    i = 0
    for b in range(buckets + 1):  # np.searchsorted(key, edges, side="left")
        edge = first + b / grid[1]
        while i < n and float(key[i]) < edge:
            i += 1
        starts[b] = i
    starts[buckets] = n  # the last slice holds the last point
    return x, y, z, axis, starts, grid, sorted_base


def sorted_points_numpy(points: np.ndarray, baseline: np.ndarray | None) -> tuple:
    """:func:`sorted_points` in plain numpy: the reference it is tested against."""
    pts = np.asarray(points, dtype=np.float32).reshape(-1, 3)
    axis = int(np.argmax(np.ptp(pts, axis=0))) if len(pts) else 2
    order = np.argsort(pts[:, axis], kind="stable")
    pts = pts[order]
    if baseline is None:
        base = np.full(len(pts), _FAR, dtype=np.float32)
    else:
        base = np.asarray(baseline, dtype=np.float32)[order]
    x, y, z = (np.ascontiguousarray(pts[:, j]) for j in range(3))
    key = (x, y, z)[axis]
    first, last = (float(key[0]), float(key[-1])) if len(key) else (0.0, 1.0)
    grid = np.array([first, BUCKETS / max(last - first, 1e-6)])
    edges = first + np.arange(BUCKETS + 1) / grid[1]
    starts = np.searchsorted(key, edges, side="left").astype(np.int64)
    starts[-1] = len(key)  # the last slice holds the last point
    return x, y, z, axis, starts, grid, base


def set_threads(threads: int) -> None:
    """How many CPU threads numba's parallel loops share their poses among (0: as many as
    :func:`~optrack.skeleton.cores.auto_threads` says are spare now)."""
    count = auto_threads() if int(threads) == 0 else int(threads)
    numba.set_num_threads(max(1, min(count, numba.config.NUMBA_NUM_THREADS)))


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
    geometry = np.ascontiguousarray(geometry, dtype=np.float32)
    if geometry.shape[2] != G:
        raise ValueError(f"part geometry must have {G} fields per part; got {geometry.shape[2]}.")
    out = np.empty(len(geometry), dtype=np.float64)
    consts = np.array([1.0 / (2.0 * sigma * sigma), alpha, support_weight])
    expected = np.asarray(expected, dtype=np.float64).reshape(-1)
    set_threads(threads)
    _kernel(*sorted_points(points, baseline), geometry, expected, consts, out)
    return out
