"""Ground plane: automatic, manual, semi-automatic, from calibration, OpenPTrack's rule,
per-frame refit with lock, and planes saved per sensor."""

from __future__ import annotations

import numpy as np
import pytest

from optrack.bench.detection import PCL_GROUND
from optrack.detection import detection_params
from optrack.detection.ground import (
    GroundError,
    GroundEstimator,
    GroundStore,
    automatic_ground,
    check_ground,
    combine_with_calibration,
    ground_from_calibration,
    ground_from_pixels,
    ground_from_points,
    ground_T_camera,
    parse_ground,
    semi_automatic_ground,
)
from optrack.detection.preprocessing import OrganisedCloud, select_points, voxel_grid
from optrack.geometry import Plane, make_pose, transform_points

from .conftest import KINECT1

PARAMS = detection_params()


def floor_cloud(height=1.5, tilt_deg=0.0, n=4000, noise=0.005, seed=1):
    """Floor points seen by a camera ``height`` m above it, pitched down by ``tilt_deg``."""
    rng = np.random.default_rng(seed)
    world = np.stack([rng.uniform(-2, 2, n), rng.uniform(1, 6, n), rng.normal(0, noise, n)], axis=1)
    pitch = np.radians(tilt_deg)
    # camera_T_world for a camera at (0, 0, height) looking along world +y, pitched down.
    down = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], dtype=float)  # world y -> camera z
    pitch_rot = np.array(
        [[1, 0, 0], [0, np.cos(pitch), -np.sin(pitch)], [0, np.sin(pitch), np.cos(pitch)]]
    )
    rotation = pitch_rot @ down
    world_T_camera = make_pose(rotation.T, (0, 0, height))
    camera = transform_points(np.linalg.inv(world_T_camera), world)
    return camera, world_T_camera


@pytest.fixture(scope="module")
def five_voxels(five_people):
    points, _ = select_points(OrganisedCloud(KINECT1, points=five_people.points), 1, 50.0)
    return voxel_grid(points, 0.06)


def test_pcls_sign_and_ours_are_the_same_floor_with_the_normal_up():
    plane = check_ground(PCL_GROUND)
    assert plane.d == pytest.approx(1.2661, abs=1e-3)  # the camera's height above it
    assert plane.normal[1] < 0  # up is the camera's -y
    assert check_ground([-v for v in PCL_GROUND]).to_list() == pytest.approx(plane.to_list())


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("0,0,0,1", "is not a plane"),
        ("1,2,3", "four finite numbers"),
        ("0,1,0,nan", "four finite numbers"),
        ("0,-1,0,0", "passes through the camera"),
        ("a,b,c,d", "four numbers"),
    ],
)
def test_a_ground_that_is_not_a_plane_is_refused_in_one_sentence(text, says):
    with pytest.raises(GroundError) as error:
        parse_ground(text)
    message = str(error.value)
    assert says in message and message.endswith(".") and "\n" not in message


def test_ground_frame_puts_the_camera_above_the_origin_and_z_up():
    plane = check_ground(PCL_GROUND)
    g_T_c = ground_T_camera(plane)
    camera = transform_points(g_T_c, np.zeros((1, 3)))[0]
    np.testing.assert_allclose(camera, [0, 0, plane.d], atol=1e-12)
    np.testing.assert_allclose(g_T_c[:3, :3] @ plane.normal, [0, 0, 1], atol=1e-12)
    foot = plane.project(np.array([0.3, 1.0, 2.0]))
    assert transform_points(g_T_c, foot[None])[0, 2] == pytest.approx(0, abs=1e-12)
    # x runs left to right as the camera sees.
    assert (g_T_c[:3, :3] @ np.array([1.0, 0, 0]))[0] > 0.99


def test_manual_ground_from_three_points_and_from_pixels(five_people):
    camera, world_T_camera = floor_cloud(height=1.4, tilt_deg=20, noise=0)
    plane = ground_from_points(camera[0], camera[1], camera[2])
    assert plane.d == pytest.approx(1.4, abs=1e-9)
    # Floor pixels of the real corridor, between the people's feet.
    cloud = OrganisedCloud(KINECT1, points=five_people.points)
    from_pixels = ground_from_pixels(cloud, [(120, 470), (600, 470), (300, 380)])
    assert from_pixels.angle_deg(check_ground(PCL_GROUND)) < 5
    assert abs(from_pixels.d - check_ground(PCL_GROUND).d) < 0.1


def test_manual_ground_refuses_collinear_points_and_pixels_without_depth(five_people):
    with pytest.raises(GroundError, match="on one line"):
        ground_from_points((0, 1, 1), (0, 1, 2), (0, 1, 3))
    cloud = OrganisedCloud(KINECT1, points=five_people.points)
    hole = np.argwhere(~np.isfinite(five_people.points[..., 2]))[0]
    with pytest.raises(GroundError, match="no depth"):
        ground_from_pixels(cloud, [(int(hole[1]), int(hole[0])), (330, 400), (300, 440)])
    with pytest.raises(GroundError, match="outside"):
        ground_from_pixels(cloud, [(700, 10), (330, 400), (300, 440)])


def test_automatic_ground_finds_pcls_floor_and_a_tilted_one(five_voxels):
    plane = automatic_ground(five_voxels, PARAMS)
    assert plane is not None and plane.angle_deg(check_ground(PCL_GROUND)) < 3
    camera, world_T_camera = floor_cloud(height=2.6, tilt_deg=30)
    tilted = automatic_ground(camera, PARAMS)
    truth = ground_from_calibration(world_T_camera)
    assert tilted.angle_deg(truth) < 1 and abs(tilted.d - 2.6) < 0.02


def test_automatic_ground_ignores_a_floor_steeper_than_the_tilt_limit():
    camera, _ = floor_cloud(height=1.0, tilt_deg=60)
    assert automatic_ground(camera, PARAMS) is None
    steep = detection_params(overrides={"ground_max_tilt": 70})
    assert automatic_ground(camera, steep).d == pytest.approx(1.0, abs=0.02)


def test_semi_automatic_ground_takes_the_plane_nearest_the_picked_point(five_voxels):
    floor_point = (0.0, 1.1, 2.5)  # on the corridor's floor
    plane = semi_automatic_ground(five_voxels, floor_point, PARAMS)
    assert plane.angle_deg(check_ground(PCL_GROUND)) < 3
    wall_point = (-1.83, -1.3, 4.7)  # on the corridor's left wall
    wall = semi_automatic_ground(five_voxels, wall_point, PARAMS)
    assert abs(wall.normal[0]) > 0.9


def test_calibration_floor_is_the_worlds_z0_seen_from_the_camera():
    camera, world_T_camera = floor_cloud(height=2.2, tilt_deg=25, noise=0)
    plane = ground_from_calibration(world_T_camera)
    assert plane.d == pytest.approx(2.2)
    np.testing.assert_allclose(plane.distance(camera), 0, atol=1e-9)


def test_openptrack_rule_keeps_the_cloud_floor_only_when_it_agrees_with_calibration():
    camera, world_T_camera = floor_cloud(height=2.0, tilt_deg=20, noise=0.003)
    calibration = ground_from_calibration(world_T_camera)
    near = Plane(*calibration.coefficients[:3], calibration.d + 0.1)
    plane, source = combine_with_calibration(near, calibration, camera, PARAMS)
    assert source == "cloud" and plane is near
    far = Plane(*calibration.coefficients[:3], calibration.d + 0.5)  # e.g. a table top
    plane, source = combine_with_calibration(far, calibration, camera, PARAMS)
    assert source == "calibration" and plane.d == pytest.approx(2.0, abs=0.01)
    plane, source = combine_with_calibration(None, calibration, camera, PARAMS)
    assert source == "calibration"


def test_floor_is_refitted_each_frame_unless_locked():
    camera, world_T_camera = floor_cloud(height=2.0, tilt_deg=20)
    start = ground_from_calibration(world_T_camera)
    moved_floor = camera + start.normal * 0.03  # the floor seen 3 cm higher (camera bumped)
    estimator = GroundEstimator(PARAMS, plane=start)
    estimator.update(moved_floor)
    assert estimator.plane.d == pytest.approx(1.97, abs=0.005)
    locked = GroundEstimator(detection_params(overrides={"lock_ground": True}), plane=start)
    locked.update(moved_floor)
    assert locked.plane.d == pytest.approx(2.0, abs=1e-9)


def test_the_per_frame_refit_is_the_total_least_squares_plane():
    camera, _ = floor_cloud(height=2.0, tilt_deg=25, noise=0.01)
    camera = camera[np.all(np.isfinite(camera), axis=1)]
    fitted = Plane.fit(camera.astype(np.float32))
    # the reference: the SVD of the centred points (the least singular vector is the normal)
    centroid = camera.mean(axis=0)
    normal = np.linalg.svd(camera - centroid, full_matrices=False)[2][2]
    reference = Plane.from_point_normal(centroid, normal)
    assert fitted.angle_deg(reference) < 1e-6 or fitted.angle_deg(reference) > 180 - 1e-6
    assert abs(fitted.distance(np.zeros(3))) == pytest.approx(abs(reference.d), abs=1e-6)
    line = np.outer(np.linspace(0.0, 1.0, 10), [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="one line"):
        Plane.fit(line)
    with pytest.raises(ValueError, match="at least 3"):
        Plane.fit(camera[:2])


def test_estimator_waits_for_a_frame_with_enough_depth():
    camera, _ = floor_cloud()
    estimator = GroundEstimator(PARAMS)
    assert not estimator.initialise(camera, valid_fraction=0.1)
    assert estimator.initialise(camera, valid_fraction=0.9) and estimator.source == "cloud"


def test_planes_are_saved_and_loaded_per_sensor(tmp_path):
    store = GroundStore(tmp_path)
    a = check_ground(PCL_GROUND)
    b = check_ground((0, -1, 0, 2.5))
    store.save("kinect_a", a, "cloud")
    store.save("kinect_b", b, "manual")
    assert store.load("kinect_a").to_list() == pytest.approx(a.to_list())
    assert store.load("kinect_b").to_list() == pytest.approx(b.to_list())
    assert store.load("kinect_c") is None
    params = detection_params(overrides={"read_ground_from_file": True})
    estimator = GroundEstimator(params, store=store, sensor_id="kinect_b")
    assert estimator.initialise(np.empty((0, 3))) and estimator.source == "file"
    saved = GroundEstimator(PARAMS, plane=b, store=store, sensor_id="kinect_d").save()
    assert saved == store.path("kinect_d") and store.load("kinect_d") is not None
    store.path("kinect_a").write_text("{not json")
    with pytest.raises(GroundError, match="damaged"):
        store.load("kinect_a")


def test_ground_estimator_with_calibration_combines_by_the_rule(five_voxels):
    # A calibration whose floor is 0.5 m off (a wrong height): the rule keeps the
    # calibration's floor and refines it only with points near it (none here), so it stays.
    wrong = check_ground((PCL_GROUND[0], PCL_GROUND[1], PCL_GROUND[2], PCL_GROUND[3] - 0.5))
    estimator = GroundEstimator(PARAMS, calibration=wrong)
    assert estimator.initialise(five_voxels)
    assert estimator.source == "calibration"
    assert estimator.plane.d == pytest.approx(wrong.d, abs=0.02)
    right = GroundEstimator(PARAMS, calibration=check_ground(PCL_GROUND))
    assert right.initialise(five_voxels) and right.source == "cloud"
