"""Person candidates in the ground-plane frame (Munaro et al. 2012, sections 3.2-3.3).

The floor-free voxels are grouped by Euclidean clustering (connected
components of the graph joining points closer than a tolerance:
:func:`optrack.detection.kernels.cluster_labels`, as SciPy's KD-tree pairs and
``connected_components``); clusters that are too tall are
dropped, clusters whose heads are close on the floor are merged, and
clusters holding several people are split at the maxima of their height
profile (PCL's ``HeadBasedSubclustering`` and ``HeightMap2D``).

Everything works in the ground frame of
:func:`optrack.detection.ground.ground_T_camera`: z is the height above the
floor, x runs left to right as the camera sees, so tilt is compensated.
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np
from scipy.signal import find_peaks

from optrack.detection.kernels import cluster_labels, column_grid, ground_columns
from optrack.params import Params

__all__ = [
    "Candidate",
    "TallColumns",
    "cluster_point_limits",
    "euclidean_clusters",
    "head_based_subclusters",
    "person_candidates",
    "tall_columns",
]


@dataclasses.dataclass
class Candidate:
    """A cluster that may be a person, in the ground frame.

    ``points`` are its voxels (Nx3, z up); ``height`` is its highest point
    above the floor; ``head`` is the floor position (x, y) of the centroid of
    its top ``head_fraction`` of the height (PCL's head centroid), which is
    where the person stands.
    """

    points: np.ndarray
    height: float
    head: np.ndarray

    @classmethod
    def from_points(cls, points: np.ndarray, head_fraction: float) -> Candidate:
        z = points[:, 2]
        height = float(z.max())
        head = points[z >= height * (1.0 - head_fraction), :2].mean(axis=0)  # PCL: top 1/8
        return cls(points, height, head)

    @property
    def size(self) -> int:
        return len(self.points)

    @property
    def width(self) -> float:
        """Extent across the camera's view (ground-frame x), metres."""
        return float(np.ptp(self.points[:, 0]))

    def head_ratio(self, head_fraction: float) -> float:
        """Floor extent of its top ``head_fraction`` over its whole floor extent (the
        larger side of each bounding box): small for a person (a head on shoulders),
        near 1 for a flat top (a partition, a box, seen from any side)."""
        floor, z = self.points[:, :2], self.points[:, 2]
        whole = float(np.ptp(floor, axis=0).max())
        top = floor[z >= self.height * (1.0 - head_fraction)]
        return float(np.ptp(top, axis=0).max()) / whole if whole > 0 else 1.0

    @property
    def center(self) -> np.ndarray:
        """The person's centre: half their height, above where they stand (PCL's tcenter)."""
        return np.array([self.head[0], self.head[1], self.height / 2.0])


def cluster_point_limits(params: Params) -> tuple[int, int]:
    """(fewest, most) voxels of a person cluster: height x width / voxel area (PCL's
    ``updateMinMaxPoints``)."""
    area = float(params.voxel_size) ** 2
    return (
        int(float(params.min_height) * float(params.min_width) / area),
        int(float(params.max_height) * float(params.max_width) / area),
    )


def euclidean_clusters(
    points: np.ndarray, tolerance: float, min_points: int, max_points: int
) -> list[np.ndarray]:
    """Indices of each cluster of points linked by steps shorter than ``tolerance``
    (PCL's EuclideanClusterExtraction), keeping clusters of min..max points."""
    n = len(points)
    if n == 0:
        return []
    labels = cluster_labels(np.ascontiguousarray(points, dtype=np.float64), float(tolerance))
    counts = np.bincount(labels)
    kept = np.flatnonzero((counts >= min_points) & (counts <= max_points))
    if len(kept) == 0:
        return []
    order = np.argsort(labels, kind="stable")
    starts = np.cumsum(counts) - counts
    return [order[starts[k] : starts[k] + counts[k]] for k in kept]


class TallColumns:
    """The floor columns holding a point higher than ``max_height`` (walls, cupboards).

    The floor (ground-frame x, y) is cut into ``cell``-sized columns; a column
    is tall when one of ``points`` in it is higher than ``max_height``, and it is
    taken as solid from its lowest point up. The points come as their ``x``,
    ``y`` and ``z`` arrays (ground frame, z up; float32 will do: only columns are
    told apart). ``in_tall`` marks the points standing in a tall column;
    :meth:`near` tells which points (these, or others such as the voxel
    centroids of the rest) come within ``tolerance`` of one: a tall column within
    ``tolerance`` on the floor reaches down to ``tolerance`` above the point (a
    minimum filter over the grid of the tall columns' lowest points).
    """

    def __init__(
        self,
        x: np.ndarray,
        y: np.ndarray,
        z: np.ndarray,
        cell: float,
        max_height: float,
        tolerance: float,
    ) -> None:
        inverse = 1.0 / cell
        i = np.floor(x * inverse).astype(np.int64)
        j = np.floor(y * inverse).astype(np.int64)
        self._build(i, j, np.ascontiguousarray(z), cell, max_height, tolerance)

    @classmethod
    def from_camera(
        cls, points: np.ndarray, g_T_c: np.ndarray, cell: float, max_height: float, tolerance: float
    ) -> TallColumns:
        """The columns of camera-frame points (Nx3 float32), ``g_T_c`` taking them to the
        ground frame (in float32: only columns are told apart), in one pass."""
        i, j, z = ground_columns(
            np.ascontiguousarray(points, dtype=np.float32),
            np.ascontiguousarray(g_T_c, dtype=np.float32),
            np.float32(1.0 / cell),
        )
        columns = cls.__new__(cls)
        columns._build(i, j, z, cell, max_height, tolerance)
        return columns

    def _build(
        self,
        i: np.ndarray,
        j: np.ndarray,
        z: np.ndarray,
        cell: float,
        max_height: float,
        tolerance: float,
    ) -> None:
        """The grid from each point's column (``i``, ``j``) and height ``z``."""
        self.cell, self.tolerance = float(cell), float(tolerance)
        self.found = bool(len(z)) and bool(z.max() > max_height)
        self.in_tall = np.zeros(len(z), dtype=bool)
        if not self.found:
            return
        column, self.in_tall, tall, bottom, i0, j0, rows, cols = column_grid(
            i, j, z, float(max_height)
        )
        self.i0, self.j0, self.rows, self.cols = int(i0), int(j0), int(rows), int(cols)
        # The lowest point of any tall column within the tolerance: a minimum filter over
        # a square of columns (OpenCV's grey-scale erosion; beyond the grid nothing is tall).
        size = 2 * int(np.ceil(tolerance / cell)) + 1
        self.reach_down = cv2.erode(
            bottom.reshape(self.rows, self.cols),
            np.ones((size, size), dtype=np.uint8),
            borderType=cv2.BORDER_CONSTANT,
            borderValue=np.inf,
        ).ravel()
        self._tall = tall
        self._column, self._z = column, z

    def near(self, points: np.ndarray | None = None) -> np.ndarray:
        """Which ``points`` (default: the ones the columns were found from) are not in a
        tall column and come within the tolerance of one."""
        if not self.found:
            return np.zeros(len(points) if points is not None else len(self.in_tall), dtype=bool)
        if points is None:
            column, z, outside = self._column, self._z, None
        else:
            i = np.floor(points[:, 0] * (1.0 / self.cell)).astype(np.int64) - self.i0
            j = np.floor(points[:, 1] * (1.0 / self.cell)).astype(np.int64) - self.j0
            outside = (i < 0) | (i >= self.rows) | (j < 0) | (j >= self.cols)
            column = np.clip(i, 0, self.rows - 1) * self.cols + np.clip(j, 0, self.cols - 1)
            z = points[:, 2]
        near = ~self._tall[column] & (self.reach_down[column] <= z + self.tolerance)
        if outside is not None:
            near &= ~outside  # off the grid: no column there is tall
        return near


def tall_columns(
    points: np.ndarray, cell: float, max_height: float, tolerance: float
) -> tuple[np.ndarray, np.ndarray]:
    """Which points stand in a tall column, and which others come within
    ``tolerance`` of one (two boolean masks; see :class:`TallColumns`)."""
    columns = TallColumns(points[:, 0], points[:, 1], points[:, 2], cell, max_height, tolerance)
    return columns.in_tall, columns.near()


def _merge_close(
    candidates: list[Candidate], distance: float, head_fraction: float
) -> list[Candidate]:
    """Merge candidates whose heads are closer than ``distance`` on the floor
    (PCL's ``mergeClustersCloseInFloorCoordinates``, taken transitively)."""
    if len(candidates) < 2 or distance <= 0:
        return candidates
    heads = np.zeros((len(candidates), 3))
    heads[:, :2] = [c.head for c in candidates]
    labels = cluster_labels(heads, float(distance))
    count = int(labels.max()) + 1
    if count == len(candidates):
        return candidates
    merged = []
    for label in range(count):
        members = np.flatnonzero(labels == label)
        if len(members) == 1:
            merged.append(candidates[members[0]])
        else:
            points = np.concatenate([candidates[i].points for i in members])
            merged.append(Candidate.from_points(points, head_fraction))
    return merged


def _head_maxima(
    points: np.ndarray, bin_size: float, min_distance: float, prominence: float
) -> np.ndarray:
    """Indices (into ``points``) of the heads: maxima of the height profile along x,
    highest first, each at least ``min_distance`` on the floor from the higher ones
    (PCL's ``HeightMap2D``: compute, searchLocalMaxima, filterMaxima), and standing
    out by at least ``prominence`` (SciPy's topographic prominence) so that the
    noise on a flat top (a partition, a cupboard) makes no heads."""
    x, z = points[:, 0], points[:, 2]
    bins = ((x - x.min()) / bin_size).astype(np.int64)
    # The profile with an empty (zero-height) bin at each end, so that the ends can be
    # maxima too; empty bins are valleys, as PCL's zeros.
    padded = np.full(int(bins.max()) + 3, -np.inf)
    np.maximum.at(padded, bins + 1, z)
    padded[np.isinf(padded)] = 0.0
    profile = padded[1:-1]
    top_point = np.full(len(profile), -1)
    tops = np.flatnonzero(z == profile[bins])
    top_point[bins[tops]] = tops  # the last (highest index) of a bin's top points
    peaks, _ = find_peaks(padded, prominence=prominence)
    peaks = peaks - 1
    peaks = peaks[np.argsort(-profile[peaks], kind="stable")]
    kept: list[int] = []
    kept_xy: list[tuple[float, float]] = []
    for peak in peaks.tolist():
        top = int(top_point[peak])
        hx, hy = float(points[top, 0]), float(points[top, 1])
        if all(math.hypot(hx - kx, hy - ky) >= min_distance for kx, ky in kept_xy):
            kept.append(top)
            kept_xy.append((hx, hy))
    return np.array(kept, dtype=np.int64)


def head_based_subclusters(
    candidate: Candidate, params: Params, min_points: int
) -> list[Candidate]:
    """Split a cluster holding several people at its heads (PCL's ``createSubClusters``).

    Each point joins the first head (highest first) within
    ``heads_minimum_distance`` of it on the floor; points near no head are
    dropped, and so are sub-clusters of ``min_points`` points or fewer.
    """
    head_fraction = float(params.head_fraction)
    min_distance = float(params.heads_minimum_distance)
    maxima = _head_maxima(
        candidate.points, float(params.voxel_size), min_distance, float(params.head_prominence)
    )
    if len(maxima) <= 1:
        return [candidate]
    floor = candidate.points[:, :2]
    near = np.linalg.norm(floor[:, None, :] - floor[maxima][None, :, :], axis=2) < min_distance
    owner = np.where(near.any(axis=1), np.argmax(near, axis=1), -1)
    parts = []
    for k in range(len(maxima)):
        members = owner == k
        if np.count_nonzero(members) > min_points:
            parts.append(Candidate.from_points(candidate.points[members], head_fraction))
    return parts


def person_candidates(
    points: np.ndarray, params: Params, touching: np.ndarray | None = None
) -> list[Candidate]:
    """Person candidates among floor-free voxels (ground frame, z up).

    PCL's chain: Euclidean clustering (tolerance ``cluster_tolerance`` voxel
    sizes, min..max points from the person limits), drop clusters taller
    than ``max_height``, merge clusters whose heads are close, split
    clusters by heads when large enough; then keep candidates whose height
    and width are within the person limits and that have a head: their top
    ``head_fraction`` is narrower than ``max_head_ratio`` of their extent.

    ``touching`` given, the tall columns are already out of ``points`` and it
    marks the points that come within the tolerance of one (:class:`TallColumns`
    found on the points before the voxel grid, as the detector does).
    """
    head_fraction = float(params.head_fraction)
    min_points, max_points = cluster_point_limits(params)
    tolerance = float(params.cluster_tolerance) * float(params.voxel_size)
    min_height, max_height = float(params.min_height), float(params.max_height)
    # Clusters reaching above max_height are dropped (PCL). Here the columns of floor
    # holding such a point (walls, cupboards: most of the points) are left out of the
    # clustering, and clusters that come within the tolerance of them are dropped, as
    # they would have joined them.
    if touching is None:
        in_tall, touching = tall_columns(points, float(params.voxel_size), max_height, tolerance)
        rest = ~in_tall
        points, touching = points[rest], touching[rest]
    clusters = [
        Candidate.from_points(points[idx], head_fraction)
        for idx in euclidean_clusters(points, tolerance, max(min_points, 1), max_points)
        if not touching[idx].any()
    ]
    clusters = [c for c in clusters if c.height <= max_height]
    clusters = _merge_close(clusters, float(params.merge_distance), head_fraction)
    split_above = int(min_points * float(params.subcluster_min_points_factor))
    people: list[Candidate] = []
    for cluster in clusters:
        if not min_height < cluster.height < max_height:
            continue
        if cluster.size > split_above:
            people.extend(head_based_subclusters(cluster, params, min_points))
        else:
            people.append(cluster)
    min_width, max_width = float(params.min_width), float(params.max_width)
    max_head_ratio = float(params.max_head_ratio)
    return [
        c
        for c in people
        if min_height <= c.height <= max_height
        and min_width <= c.width <= max_width
        and c.head_ratio(head_fraction) <= max_head_ratio
    ]
