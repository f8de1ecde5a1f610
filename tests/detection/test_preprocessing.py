"""Preprocessing: valid and in-range pixels, subsampling, confidence, voxel grid, denoising."""

from __future__ import annotations

import numpy as np
import pytest

from optrack.detection.preprocessing import (
    OrganisedCloud,
    denoise,
    select_points,
    split_at_floor,
    voxel_grid,
)
from optrack.geometry import backproject, backproject_points
from optrack.io.images import read_depth_image
from optrack.io.pcd import read_pcd
from optrack.types import Intrinsics

GRABBER = Intrinsics(525.0, 525.0, 320.0, 240.0, 640, 480)


@pytest.fixture(scope="module")
def grabber(shared_data):
    stem = "frame_20121214T142255.814212"
    root = shared_data / "pcl" / "grabber_sequences"
    depth = read_depth_image(root / "tiff" / f"{stem}_depth.tiff")
    return depth, read_pcd(root / "pcd" / f"{stem}.pcd").points


def test_depth_image_points_match_pcls_cloud_of_the_same_frame(grabber):
    depth, reference = grabber
    cloud = OrganisedCloud(GRABBER, depth=depth, depth_scale=0.001)
    grid = cloud.grid(slice(None), slice(None))
    valid = np.isfinite(reference[..., 2])
    assert np.array_equal(np.isfinite(grid[..., 2]), valid)
    np.testing.assert_allclose(grid[valid], reference[valid], atol=1e-5)
    window = cloud.grid(slice(100, 300, 4), slice(50, 500, 4))
    np.testing.assert_allclose(window, grid[100:300:4, 50:500:4], atol=1e-12, equal_nan=True)


@pytest.mark.parametrize("stored", [False, True])
def test_floor_split_in_one_pass_keeps_the_points_between_floor_and_top(grabber, stored):
    depth, reference = grabber
    cloud = (
        OrganisedCloud(GRABBER, points=reference)
        if stored
        else OrganisedCloud(GRABBER, depth=depth, depth_scale=0.001)
    )
    plane = (0.065, -0.691, -0.720, 0.712)  # this frame's floor, normal up (camera frame)
    points, _ = select_points(cloud, 2, 15.0)
    heights = points.astype(np.float64) @ np.array(plane[:3]) + plane[3]
    above, floor, count = split_at_floor(cloud, 2, 15.0, plane, 0.05, 0.5, 100)
    expected = points[(heights > 0.05) & (heights < 0.5)]
    assert 0 < len(above) < len(points)
    assert abs(len(above) - len(expected)) <= 2  # float32 rounding at the two bounds
    assert count == pytest.approx(np.count_nonzero(np.abs(heights) < 0.05), abs=2)
    assert 50 <= len(floor) <= 200
    floor_heights = floor.astype(np.float64) @ np.array(plane[:3]) + plane[3]
    assert np.all(np.abs(floor_heights) < 0.05 + 1e-4)


def test_selected_points_are_the_subsampled_valid_pixels_within_range(grabber):
    depth, _ = grabber
    cloud = OrganisedCloud(GRABBER, depth=depth, depth_scale=0.001)
    points, looked_at = select_points(cloud, 4, 15.0)
    expected, _ = backproject_points(depth * 0.001, GRABBER, stride=4)
    assert looked_at == 120 * 160
    np.testing.assert_allclose(points, expected, atol=1e-5)
    near, _ = select_points(cloud, 4, 1.0)
    assert 0 < len(near) < len(points) and near[:, 2].max() <= 1.0


def test_stored_cloud_and_depth_image_select_the_same_points(grabber):
    depth, _ = grabber
    organised = backproject(depth * 0.001, GRABBER)
    from_cloud, _ = select_points(OrganisedCloud(GRABBER, points=organised), 2, 15.0)
    from_depth, _ = select_points(OrganisedCloud(GRABBER, depth=depth, depth_scale=0.001), 2, 15.0)
    np.testing.assert_allclose(from_cloud, from_depth, atol=1e-5)


def test_low_confidence_pixels_are_dropped():
    depth = np.full((4, 6), 2000, np.uint16)
    confidence = np.full((4, 6), 255, np.uint8)
    confidence[:, :3] = 100
    cloud = OrganisedCloud(Intrinsics(5, 5, 3, 2), depth=depth, depth_scale=0.001)
    points, _ = select_points(cloud, 1, 10.0, confidence, 200)
    assert len(points) == 12 and np.all(points[:, 0] >= 0)


def test_voxel_grid_keeps_one_centroid_per_occupied_voxel():
    rng = np.random.default_rng(0)
    points = rng.uniform(0.0, 0.01, (500, 3)) + [[0, 0, 1]]  # well inside one voxel
    far = points + [1.0, 0, 0]
    out = voxel_grid(np.concatenate([points, far]), 0.06)
    assert len(out) == 2
    np.testing.assert_allclose(sorted(out[:, 0]), [points[:, 0].mean(), far[:, 0].mean()])
    assert voxel_grid(np.empty((0, 3)), 0.06).shape == (0, 3)


def test_denoising_removes_a_lone_outlier():
    rng = np.random.default_rng(1)
    points = np.concatenate([rng.normal(0, 0.01, (300, 3)), [[1.0, 1.0, 1.0]]])
    kept = denoise(points, 5, 0.3)
    assert len(kept) < len(points) and not np.any(np.all(kept == [1.0, 1.0, 1.0], axis=1))
