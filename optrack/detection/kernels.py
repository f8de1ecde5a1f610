"""Compiled (numba) inner loops of the detector: the voxel grid, the Euclidean
clustering's connected components and the floor split of a stored cloud.

Each is one pass over its points with a hash table of integer cells, where
NumPy needs sorts or several passes and SciPy a KD-tree and a sparse graph.
They give what :func:`optrack.detection.preprocessing.voxel_grid` (Open3D's
voxel grid), :func:`optrack.detection.clustering.euclidean_clusters` (SciPy's
``cKDTree.query_pairs`` and ``connected_components``) and
:func:`optrack.detection.preprocessing.split_at_floor` computed before them
(tests/detection/test_kernels.py compares them). Single-threaded: a detector
runs per sensor, one per core.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["cluster_labels", "column_grid", "ground_columns", "split_stored", "voxel_centroids"]

#: Knuth's multiplicative hash constant (2^64 / golden ratio), as a signed 64-bit integer.
_HASH = np.int64(-7046029254386353131)


@numba.njit(cache=True)
def _table_size(n: int) -> int:
    """A power of two at least twice ``n`` (open addressing stays short; at most 2^24,
    the bits :func:`_slot` takes)."""
    size = 16
    while size < 2 * n:
        size *= 2
    return size


@numba.njit(cache=True)
def _cell_key(i: int, j: int, k: int) -> int:
    """One int64 for a cell's three integer coordinates (each within +-2^20)."""
    return ((i + (1 << 20)) << 42) | ((j + (1 << 20)) << 21) | (k + (1 << 20))


@numba.njit(cache=True)
def _slot(keys: np.ndarray, key: int) -> int:
    """The slot of ``key`` in the open-addressing table ``keys`` (-1 marks a free slot):
    where it is, else the free slot where it goes."""
    mask = len(keys) - 1
    h = (((key ^ (key >> 21) ^ (key >> 42)) * _HASH) >> 40) & mask  # the product's top bits
    while keys[h] != -1 and keys[h] != key:
        h = (h + 1) & mask
    return h


@numba.njit(cache=True)
def _grown(keys: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The table (``keys``, ``values``) rehashed into one twice its size."""
    new_keys = np.full(2 * len(keys), -1, dtype=np.int64)
    new_values = np.empty(2 * len(keys), dtype=np.int64)
    for h in range(len(keys)):
        if keys[h] != -1:
            g = _slot(new_keys, keys[h])
            new_keys[g] = keys[h]
            new_values[g] = values[h]
    return new_keys, new_values


@numba.njit(cache=True)
def voxel_centroids(points: np.ndarray, voxel: float, skip: np.ndarray | None = None) -> np.ndarray:
    """The centroid of the points (Nx3; but those ``skip`` marks) in each occupied voxel
    (Mx3 float64), in the order of each voxel's first point. The voxels are Open3D's
    (``voxel_down_sample``): a grid from half a voxel below the points' minimum.

    The table of voxels grows with the voxels found, not the points (a person's
    voxel holds tens of points): small tables stay in cache, and large fresh
    allocations cost page faults."""
    n = points.shape[0]
    origin = np.empty(3)
    for c in range(3):
        origin[c] = np.inf
    for i in range(n):
        if skip is not None and skip[i]:
            continue
        for c in range(3):
            origin[c] = min(origin[c], np.float64(points[i, c]))
    for c in range(3):
        origin[c] -= voxel * 0.5
    keys = np.full(4096, -1, dtype=np.int64)
    index = np.empty(len(keys), dtype=np.int64)
    owner = np.empty(n, dtype=np.int32)  # each point's voxel (-1: skipped)
    m = 0
    last_key, last = -1, -1  # neighbouring pixels' points often share a voxel
    for i in range(n):
        if skip is not None and skip[i]:
            owner[i] = -1
            continue
        key = _cell_key(
            int(math.floor((np.float64(points[i, 0]) - origin[0]) / voxel)),
            int(math.floor((np.float64(points[i, 1]) - origin[1]) / voxel)),
            int(math.floor((np.float64(points[i, 2]) - origin[2]) / voxel)),
        )
        if key == last_key:
            owner[i] = last
            continue
        h = _slot(keys, key)
        if keys[h] == -1:
            keys[h] = key
            index[h] = m
            m += 1
            if 2 * m > len(keys):
                keys, index = _grown(keys, index)
                h = _slot(keys, key)
        owner[i] = last = index[h]
        last_key = key
    sums = np.zeros((m, 3))
    counts = np.zeros(m, dtype=np.int64)
    for i in range(n):
        v = owner[i]
        if v < 0:
            continue
        for c in range(3):
            sums[v, c] += np.float64(points[i, c])
        counts[v] += 1
    for v in range(m):
        for c in range(3):
            sums[v, c] /= counts[v]
    return sums


@numba.njit(cache=True)
def _root(parent: np.ndarray, i: int) -> int:
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@numba.njit(cache=True)
def _join_close(
    points: np.ndarray, a0: int, a1: int, b0: int, b1: int, limit: float, parent: np.ndarray
) -> None:
    """Join (in ``parent``, a union-find forest over rows of ``points``) the pairs of rows
    a0..a1 and b0..b1 (the same range: each pair once) at most sqrt(limit) apart."""
    for i in range(a0, a1):
        for j in range(i + 1 if b0 == a0 else b0, b1):
            dx = points[i, 0] - points[j, 0]
            dy = points[i, 1] - points[j, 1]
            dz = points[i, 2] - points[j, 2]
            if dx * dx + dy * dy + dz * dz <= limit:
                a, b = _root(parent, i), _root(parent, j)
                if a != b:
                    parent[max(a, b)] = min(a, b)


@numba.njit(cache=True)
def cluster_labels(points: np.ndarray, tolerance: float) -> np.ndarray:
    """Connected components of the points (Nx3 float64) joined when at most
    ``tolerance`` apart: a label per point, numbered in the order of each
    component's first point (as SciPy's ``connected_components``).

    The points are sorted into cells ``tolerance`` wide; each cell is compared with
    itself and the 13 of its 26 neighbours that come after it, so each pair once."""
    n = points.shape[0]
    cell = np.empty((n, 3), dtype=np.int64)
    key = np.empty(n, dtype=np.int64)
    for i in range(n):
        for c in range(3):
            cell[i, c] = int(math.floor(points[i, c] / tolerance))
        key[i] = _cell_key(cell[i, 0], cell[i, 1], cell[i, 2])
    order = np.argsort(key)
    sorted_points = np.empty((n, 3))
    for r in range(n):
        sorted_points[r] = points[order[r]]
    # each cell's rows in the sorted order: [start[h], end[h]) at its key's slot h
    keys = np.full(_table_size(n), -1, dtype=np.int64)
    start = np.empty(len(keys), dtype=np.int64)
    end = np.empty(len(keys), dtype=np.int64)
    for r in range(n):
        h = _slot(keys, key[order[r]])
        if keys[h] == -1:
            keys[h] = key[order[r]]
            start[h] = r
        end[h] = r + 1
    parent = np.arange(n)
    limit = tolerance * tolerance
    for h in range(len(keys)):
        if keys[h] == -1:
            continue
        first = order[start[h]]
        ci, cj, ck = cell[first, 0], cell[first, 1], cell[first, 2]
        _join_close(sorted_points, start[h], end[h], start[h], end[h], limit, parent)
        for di in range(0, 2):
            for dj in range(-1 if di else 0, 2):
                for dk in range(-1 if di or dj else 1, 2):
                    g = _slot(keys, _cell_key(ci + di, cj + dj, ck + dk))
                    if keys[g] != -1:
                        _join_close(
                            sorted_points, start[h], end[h], start[g], end[g], limit, parent
                        )
    # labels in the order of each component's first point (original order)
    root_of = np.empty(n, dtype=np.int64)
    for r in range(n):
        root_of[order[r]] = order[_root(parent, r)]
    labels = np.empty(n, dtype=np.int64)
    label_of = np.full(n, -1, dtype=np.int64)
    count = 0
    for i in range(n):
        r = root_of[i]
        if label_of[r] == -1:
            label_of[r] = count
            count += 1
        labels[i] = label_of[r]
    return labels


@numba.njit(cache=True)
def split_stored(
    points: np.ndarray,
    step: int,
    max_distance: float,
    plane: np.ndarray,
    floor_distance: float,
    top: float,
) -> tuple[np.ndarray, np.ndarray]:
    """One pass over every ``step``-th pixel (rows and columns) of a stored organised
    cloud (HxWx3 float32, NaN invalid): the points with depth in (0, max_distance]
    higher than ``floor_distance`` above ``plane`` (a, b, c, d) and lower than
    ``top`` (Nx3 float32), and the floor points, within ``floor_distance`` of it
    (Nx3 float32), each in the pixels' order."""
    rows, cols = points.shape[0], points.shape[1]
    a, b = np.float32(plane[0]), np.float32(plane[1])
    c, d = np.float32(plane[2]), np.float32(plane[3])
    lower, upper = np.float32(floor_distance), np.float32(top)
    far = np.float32(max_distance)
    count = ((rows + step - 1) // step) * ((cols + step - 1) // step)
    above = np.empty((count, 3), dtype=np.float32)
    floor = np.empty((count, 3), dtype=np.float32)
    n_above = 0
    n_floor = 0
    for r in range(0, rows, step):
        for q in range(0, cols, step):
            z = points[r, q, 2]
            if not (z > 0 and z <= far):
                continue
            x, y = points[r, q, 0], points[r, q, 1]
            h = x * a + y * b + z * c + d
            if h > lower and h < upper:
                above[n_above, 0], above[n_above, 1], above[n_above, 2] = x, y, z
                n_above += 1
            if abs(h) < lower:
                floor[n_floor, 0], floor[n_floor, 1], floor[n_floor, 2] = x, y, z
                n_floor += 1
    return above[:n_above], floor[:n_floor]


@numba.njit(cache=True)
def ground_columns(
    points: np.ndarray, g_T_c: np.ndarray, inverse_cell: np.float32
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Floor columns of camera-frame points (Nx3 float32) in the ground frame (``g_T_c``,
    4x4 float32): each point's column (x and y over the cell, ``inverse_cell`` its
    inverse, rounded down) and its height z, in float32 as NumPy computes them."""
    n = points.shape[0]
    i = np.empty(n, dtype=np.int64)
    j = np.empty(n, dtype=np.int64)
    z = np.empty(n, dtype=np.float32)
    for p in range(n):
        px, py, pz = points[p, 0], points[p, 1], points[p, 2]
        gx = px * g_T_c[0, 0] + py * g_T_c[0, 1] + pz * g_T_c[0, 2] + g_T_c[0, 3]
        gy = px * g_T_c[1, 0] + py * g_T_c[1, 1] + pz * g_T_c[1, 2] + g_T_c[1, 3]
        z[p] = px * g_T_c[2, 0] + py * g_T_c[2, 1] + pz * g_T_c[2, 2] + g_T_c[2, 3]
        i[p] = int(math.floor(gx * inverse_cell))
        j[p] = int(math.floor(gy * inverse_cell))
    return i, j, z


@numba.njit(cache=True)
def column_grid(
    i: np.ndarray, j: np.ndarray, z: np.ndarray, max_height: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int, int, int, int]:
    """The grid of floor columns (i, j) and its tall ones (holding a z above
    ``max_height``): each point's flat column index, whether it stands in a tall
    column, the tall columns (flat), each column's lowest point if tall (else inf),
    and the grid's first row and column and its size (rows, cols)."""
    n = len(i)
    i0, j0, i1, j1 = i[0], j[0], i[0], j[0]
    for p in range(n):
        i0, i1 = min(i0, i[p]), max(i1, i[p])
        j0, j1 = min(j0, j[p]), max(j1, j[p])
    rows, cols = i1 - i0 + 1, j1 - j0 + 1
    column = np.empty(n, dtype=np.int64)
    tall = np.zeros(rows * cols, dtype=np.bool_)
    for p in range(n):
        column[p] = (i[p] - i0) * cols + (j[p] - j0)
        if z[p] > max_height:
            tall[column[p]] = True
    in_tall = np.empty(n, dtype=np.bool_)
    bottom = np.full(rows * cols, np.inf, dtype=z.dtype)
    for p in range(n):
        in_tall[p] = tall[column[p]]
        if in_tall[p]:
            bottom[column[p]] = min(bottom[column[p]], z[p])
    return column, in_tall, tall, bottom, i0, j0, rows, cols
