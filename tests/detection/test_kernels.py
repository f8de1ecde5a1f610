"""The compiled kernels give what the libraries they replace gave: Open3D's voxel grid,
SciPy's KD-tree pairs and connected components, NumPy's floor split of a stored cloud."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from optrack.detection.clustering import TallColumns
from optrack.detection.ground import check_ground, ground_T_camera
from optrack.detection.kernels import cluster_labels, split_stored, voxel_centroids
from optrack.detection.preprocessing import (
    OrganisedCloud,
    select_points,
    split_at_floor,
    voxel_grid,
)
from optrack.io.pcd import read_pcd
from optrack.types import Intrinsics

PCL_INTRINSICS = Intrinsics(525.0, 525.0, 319.5, 239.5, 640, 480)
PCL_GROUND = (-0.0103586, 0.997011, 0.0765573, -1.26614)
#: The same floor with its normal up (towards the camera), as the detector keeps it.
FLOOR = check_ground(PCL_GROUND).coefficients


def _blobs(seed: int, n: int = 4000) -> np.ndarray:
    """People-like clumps, a wall and scattered points (metres)."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform([-3, 0, 1], [3, 1, 8], size=(12, 3))
    clumps = centres[rng.integers(0, 12, n)] + rng.normal(0, [0.15, 0.5, 0.15], (n, 3))
    wall = np.column_stack(
        [rng.uniform(-3, 3, n // 2), rng.uniform(0, 2.5, n // 2), np.full(n // 2, 9.0)]
    )
    scattered = rng.uniform([-4, 0, 0.5], [4, 2.5, 10], size=(n // 4, 3))
    return np.concatenate([clumps, wall, scattered])


def _open3d_voxels(points: np.ndarray, voxel: float) -> np.ndarray:
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points.astype(np.float64)))
    return np.asarray(cloud.voxel_down_sample(voxel).points)


def _sorted_rows(a: np.ndarray) -> np.ndarray:
    return a[np.lexsort(a.T[::-1])]


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_voxel_centroids_are_open3ds(seed, dtype):
    points = _blobs(seed).astype(dtype)
    for voxel in (0.06, 0.2):
        ours = voxel_centroids(points, voxel)
        assert ours.dtype == np.float64
        np.testing.assert_array_equal(
            _sorted_rows(ours), _sorted_rows(_open3d_voxels(points, voxel))
        )


def test_voxel_centroids_keep_the_order_of_each_voxels_first_point():
    points = np.array([[1.0, 0, 0], [0.0, 0, 0], [1.01, 0, 0], [5.0, 0, 0]])
    np.testing.assert_allclose(voxel_centroids(points, 0.1), [[1.005, 0, 0], [0, 0, 0], [5, 0, 0]])


def _scipy_labels(points: np.ndarray, tolerance: float) -> np.ndarray:
    pairs = cKDTree(points).query_pairs(tolerance, output_type="ndarray")
    n = len(points)
    graph = csr_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    return connected_components(graph, directed=False)[1]


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_cluster_labels_are_scipys_connected_components(seed):
    points = voxel_centroids(_blobs(seed), 0.06)
    for tolerance in (0.05, 0.12, 0.3):
        ours = cluster_labels(points, tolerance)
        np.testing.assert_array_equal(ours, _scipy_labels(points, tolerance))
    # negative coordinates and a chain across cells: one component
    chain = np.column_stack([np.arange(-50, 50) * 0.11, np.zeros(100), np.full(100, -2.0)])
    assert set(cluster_labels(chain, 0.12).tolist()) == {0}
    assert len(set(cluster_labels(chain, 0.1).tolist())) == 100


def test_split_stored_is_the_numpy_split(shared_data):
    five = read_pcd(shared_data / "pcl" / "five_people.pcd")
    cloud = OrganisedCloud(PCL_INTRINSICS, points=five.points)
    for step in (1, 3):
        above, floor = split_stored(five.points, step, 4.0, np.array(FLOOR), 0.06, 2.42)
        points, _ = select_points(cloud, step, 4.0)
        assert len(above) > len(points) / 2 and len(floor) > 1000
        a, b, c, d = (np.float32(v) for v in FLOOR)
        heights = points[:, 0] * a + points[:, 1] * b + points[:, 2] * c + d
        np.testing.assert_array_equal(above, points[(heights > 0.06) & (heights < 2.42)])
        np.testing.assert_array_equal(floor, points[np.abs(heights) < 0.06])
        kept, fit, count = split_at_floor(cloud, step, 4.0, FLOOR, 0.06, 2.42, 500)
        np.testing.assert_array_equal(kept, above)
        assert count == len(floor) and len(fit) <= 2 * 500
        np.testing.assert_array_equal(fit, floor[:: max(1, count // 500)])


def test_tall_columns_from_camera_points_are_those_of_the_transformed_points(shared_data):
    five = read_pcd(shared_data / "pcl" / "five_people.pcd")
    cloud = OrganisedCloud(PCL_INTRINSICS, points=five.points)
    points, _, _ = split_at_floor(cloud, 1, 50.0, FLOOR, 0.06, 2.42, 500)
    g_T_c = ground_T_camera(check_ground(PCL_GROUND)).astype(np.float32)
    # NumPy's float32 x * r0 + y * r1 + z * r2 + t, as the kernel computes it
    x, y, z = (
        points[:, 0] * g_T_c[k, 0] + points[:, 1] * g_T_c[k, 1] + points[:, 2] * g_T_c[k, 2]
        + g_T_c[k, 3]
        for k in range(3)
    )  # fmt: skip
    reference = TallColumns(x, y, z, 0.06, 2.3, 0.12)
    columns = TallColumns.from_camera(points, g_T_c, 0.06, 2.3, 0.12)
    assert columns.in_tall.any() and not columns.in_tall.all()
    np.testing.assert_array_equal(columns.in_tall, reference.in_tall)
    np.testing.assert_array_equal(columns.near(), reference.near())
    voxels = voxel_grid(points, 0.06, skip=columns.in_tall)
    np.testing.assert_array_equal(voxels, voxel_grid(points[~columns.in_tall], 0.06))
    voxels = voxels @ g_T_c[:3, :3].T.astype(np.float64) + g_T_c[:3, 3]
    np.testing.assert_array_equal(columns.near(voxels), reference.near(voxels))
