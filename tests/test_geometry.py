import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from optrack.errors import UserError
from optrack.geometry import (
    Plane,
    backproject,
    backproject_points,
    compose,
    invert,
    make_pose,
    pose_from_quaternion,
    pose_from_rvec_tvec,
    pose_to_quaternion,
    pose_to_rvec_tvec,
    project,
    rotation_angle_deg,
    transform_points,
)
from optrack.types import Intrinsics

RNG = np.random.default_rng(7)


def random_pose(rng=RNG) -> np.ndarray:
    return make_pose(Rotation.random(random_state=rng.integers(1 << 30)), rng.uniform(-3, 3, 3))


def test_pose_composed_with_its_inverse_is_identity():
    for _ in range(20):
        pose = random_pose()
        np.testing.assert_allclose(compose(pose, invert(pose)), np.eye(4), atol=1e-12)
        np.testing.assert_allclose(compose(invert(pose), pose), np.eye(4), atol=1e-12)
        np.testing.assert_allclose(invert(pose), np.linalg.inv(pose), atol=1e-12)


@pytest.mark.parametrize("dtype, atol", [(np.float32, 2e-5), (np.float64, 1e-12)])
def test_transform_points_of_a_whole_organised_cloud_matches_the_matrix_product(dtype, atol):
    # A 480x640x3 cloud (by columns, not BLAS) against the 4x4 product in float64:
    # same values to the dtype's precision, NaNs (no depth) kept, shape and dtype kept.
    pose = random_pose()
    cloud = RNG.uniform(-5, 5, (480, 640, 3)).astype(dtype)
    cloud[::7, ::5] = np.nan
    moved = transform_points(pose, cloud)
    homogeneous = np.concatenate([cloud.reshape(-1, 3), np.ones((480 * 640, 1))], axis=1)
    expected = (homogeneous.astype(np.float64) @ pose.T)[:, :3].reshape(cloud.shape)
    assert moved.shape == cloud.shape and moved.dtype == dtype
    np.testing.assert_allclose(moved, expected, atol=atol, rtol=0)
    assert np.isnan(moved[::7, ::5]).all() and np.isfinite(moved[1::7, 1::5]).all()


def test_compose_chains_frames_left_to_right():
    a_T_b, b_T_c = random_pose(), random_pose()
    point_c = np.array([[0.3, -1.2, 2.5]])
    via_b = transform_points(a_T_b, transform_points(b_T_c, point_c))
    np.testing.assert_allclose(transform_points(compose(a_T_b, b_T_c), point_c), via_b, atol=1e-12)


def test_quaternion_round_trip_and_positive_w():
    for _ in range(20):
        pose = random_pose()
        q, t = pose_to_quaternion(pose)
        assert q[3] >= 0
        assert np.isclose(np.linalg.norm(q), 1.0)
        np.testing.assert_allclose(pose_from_quaternion(q, t), pose, atol=1e-12)


def test_quaternion_convention_is_xyzw():
    quarter_turn_about_z = pose_from_quaternion(
        [0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)], [0, 0, 0]
    )
    np.testing.assert_allclose(
        transform_points(quarter_turn_about_z, np.array([[1.0, 0, 0]])), [[0, 1, 0]], atol=1e-12
    )


def test_rvec_tvec_round_trip_matches_opencv_rodrigues():
    for _ in range(20):
        pose = random_pose()
        rvec, tvec = pose_to_rvec_tvec(pose)
        np.testing.assert_allclose(pose_from_rvec_tvec(rvec, tvec), pose, atol=1e-9)
        np.testing.assert_allclose(Rotation.from_rotvec(rvec).as_matrix(), pose[:3, :3], atol=1e-9)


def test_rotation_angle_between_poses():
    a = make_pose(Rotation.from_euler("z", 10, degrees=True))
    b = make_pose(Rotation.from_euler("z", 35, degrees=True), [1, 2, 3])
    assert rotation_angle_deg(a, b) == pytest.approx(25.0)
    assert rotation_angle_deg(b) == pytest.approx(35.0)


def test_plane_fit_recovers_a_noisy_plane():
    true = Plane(0.1, 0.95, 0.2, -1.3)
    xy = RNG.uniform(-2, 2, (500, 2))
    a, b, c, d = true
    z = -(a * xy[:, 0] + b * xy[:, 1] + d) / c
    points = np.column_stack([xy, z]) + RNG.normal(0, 0.002, (500, 3))
    fitted = Plane.fit(points).oriented_towards(true.normal * 10)
    assert fitted.angle_deg(true) < 0.5
    assert fitted.offset(true) < 0.01


def test_plane_segment_ignores_outliers_with_open3d_ransac():
    floor = np.column_stack([RNG.uniform(-3, 3, (2000, 2)), RNG.normal(0, 0.005, 2000)])
    clutter = RNG.uniform([-3, -3, 0.2], [3, 3, 2.0], (800, 3))
    points = np.vstack([floor, clutter])
    plane, inliers = Plane.segment(points, distance_threshold=0.02)
    plane = plane.oriented_towards([0, 0, 1])
    assert plane.angle_deg(Plane(0, 0, 1, 0)) < 1.0
    assert abs(plane.d) < 0.01
    assert np.count_nonzero(inliers < 2000) > 1900
    assert np.count_nonzero(inliers >= 2000) < 40


def test_plane_distance_is_signed_along_the_normal():
    floor = Plane(0, 0, 2, 0)  # normalised on construction
    np.testing.assert_allclose(floor.distance(np.array([[0, 0, 1.5], [1, 1, -0.5]])), [1.5, -0.5])
    np.testing.assert_allclose(floor.project(np.array([3, 4, 5.0])), [3, 4, 0])


def test_plane_transform_keeps_point_distances():
    plane = Plane(0.2, -0.9, 0.3, 1.1)
    b_T_a = random_pose()
    points_a = RNG.uniform(-2, 2, (50, 3))
    moved = plane.transform(b_T_a)
    np.testing.assert_allclose(
        moved.distance(transform_points(b_T_a, points_a)), plane.distance(points_a), atol=1e-9
    )


def test_plane_angle_and_offset_between_planes():
    floor = Plane(0, 0, 1, 0)
    tilted = Plane.from_point_normal(
        [0, 0, 0.05], Rotation.from_euler("x", 3, degrees=True).apply([0, 0, 1])
    )
    assert floor.angle_deg(tilted) == pytest.approx(3.0)
    assert floor.offset(tilted) == pytest.approx(0.05 * np.cos(np.radians(3)), abs=1e-9)
    assert floor.angle_deg(floor.flipped()) == pytest.approx(180.0)


def test_plane_from_three_points_and_degenerate_inputs():
    plane = Plane.from_points([0, 0, 1], [1, 0, 1], [0, 1, 1])
    np.testing.assert_allclose(plane.to_list(), [0, 0, 1, -1])
    with pytest.raises(ValueError, match="one line"):
        Plane.from_points([0, 0, 0], [1, 1, 1], [2, 2, 2])
    with pytest.raises(ValueError, match="non-zero normal"):
        Plane(0, 0, 0, 1)
    with pytest.raises(UserError, match="four numbers"):
        Plane.parse("1,2,3")


def test_backprojection_follows_pcl_pixel_convention():
    intrinsics = Intrinsics(525, 525, 320, 240, 640, 480)
    depth = np.zeros((480, 640), np.float32)
    depth[240, 320] = 2.0
    depth[0, 0] = 1.0
    cloud = backproject(depth, intrinsics)
    assert cloud.shape == (480, 640, 3)
    np.testing.assert_allclose(cloud[240, 320], [0, 0, 2.0])
    np.testing.assert_allclose(cloud[0, 0], [-320 / 525, -240 / 525, 1.0], rtol=1e-6)
    assert np.isnan(cloud[10, 10]).all()


def test_backprojected_points_project_back_to_their_pixels():
    intrinsics = Intrinsics(400, 410, 159.5, 119.5, 320, 240)
    depth = RNG.uniform(0.5, 6.0, (240, 320)).astype(np.float32)
    depth[RNG.random((240, 320)) < 0.1] = 0
    points, pixels = backproject_points(depth, intrinsics)
    uv, in_front = project(points, intrinsics)
    assert in_front.all()
    np.testing.assert_allclose(uv[:, ::-1], pixels, atol=1e-3)
    organised = backproject(depth, intrinsics)
    np.testing.assert_allclose(organised[pixels[:, 0], pixels[:, 1]], points, atol=1e-6)


def test_backprojection_undoes_lens_distortion():
    intrinsics = Intrinsics(
        535.9, 535.9, 342.3, 235.6, 640, 480, dist=(-0.266, -0.0386, 0.0018, -0.0003, 0.238)
    )
    depth = np.full((480, 640), 2.5, np.float32)
    points, pixels = backproject_points(depth, intrinsics, stride=16)
    uv, _ = project(points, intrinsics)
    np.testing.assert_allclose(uv[:, ::-1], pixels, atol=0.05)


def test_subsampled_backprojection_takes_every_nth_pixel():
    intrinsics = Intrinsics(100, 100, 50, 50, 100, 100)
    depth = np.ones((100, 100), np.float32)
    points, pixels = backproject_points(depth, intrinsics, stride=4)
    assert len(points) == 25 * 25
    assert (pixels % 4 == 0).all()
