"""Camera viewing pyramids and the floor each camera sees (the GUI's coverage footprints)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from optrack.geometry import (
    Plane,
    camera_frustum,
    floor_footprint,
    invert,
    make_pose,
    project,
    transform_points,
)
from optrack.types import Intrinsics

KINECT = Intrinsics(525.0, 525.0, 319.5, 239.5, width=640, height=480)
# Camera looking straight down from 3 m: camera x = world x, camera y = world -y.
LOOKING_DOWN = make_pose(np.diag([1.0, -1.0, -1.0]), [0.0, 0.0, 3.0])


def looking_along_x(height: float, tilt_down_deg: float) -> np.ndarray:
    """A camera at (0, 0, height) looking along world +x, tilted down."""
    level = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # columns: x, y, z
    tilt = Rotation.from_euler("y", tilt_down_deg, degrees=True).as_matrix()
    return make_pose(tilt @ level, [0.0, 0.0, height])


def polygon_area(xy: np.ndarray) -> float:
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def test_frustum_corners_project_to_the_image_corners():
    pose = looking_along_x(2.5, 20.0)
    frustum = camera_frustum(KINECT, pose, 4.0)
    np.testing.assert_allclose(frustum[0], pose[:3, 3])
    in_camera = transform_points(invert(pose), frustum[1:])
    np.testing.assert_allclose(in_camera[:, 2], 4.0)
    pixels, in_front = project(in_camera, KINECT)
    assert in_front.all()
    np.testing.assert_allclose(
        pixels, [[-0.5, -0.5], [639.5, -0.5], [639.5, 479.5], [-0.5, 479.5]], atol=1e-9
    )


def test_camera_looking_down_sees_a_rectangle_of_floor():
    footprint = floor_footprint(KINECT, LOOKING_DOWN, max_depth=5.0)
    assert footprint.shape == (4, 3)
    np.testing.assert_allclose(footprint[:, 2], 0.0, atol=1e-12)
    half_width, half_depth = 320 / 525 * 3.0, 240 / 525 * 3.0
    np.testing.assert_allclose(np.abs(footprint[:, 0]), half_width)
    np.testing.assert_allclose(np.abs(footprint[:, 1]), half_depth)
    assert polygon_area(footprint[:, :2]) == pytest.approx(4 * half_width * half_depth)


def test_floor_beyond_the_range_is_not_covered():
    assert floor_footprint(KINECT, LOOKING_DOWN, max_depth=2.9).shape == (0, 3)
    looking_up = looking_along_x(2.0, -40.0)
    assert floor_footprint(KINECT, looking_up, max_depth=10.0).shape == (0, 3)


def test_footprint_of_a_tilted_camera_matches_the_floor_it_sees():
    pose, max_depth = looking_along_x(2.2, 25.0), 6.0
    footprint = floor_footprint(KINECT, pose, max_depth)
    area = polygon_area(footprint[:, :2])
    assert area > 0  # counter-clockwise seen from above
    # Count the floor points that project into the image within the range.
    xs, ys = np.meshgrid(np.linspace(-1, 8, 900), np.linspace(-6, 6, 1200))
    floor = np.column_stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)])
    in_camera = transform_points(invert(pose), floor)
    pixels, in_front = project(in_camera, KINECT)
    seen = (
        in_front
        & (in_camera[:, 2] <= max_depth)
        & (pixels[:, 0] >= -0.5)
        & (pixels[:, 0] <= 639.5)
        & (pixels[:, 1] >= -0.5)
        & (pixels[:, 1] <= 479.5)
    )
    cell = (9 / 899) * (12 / 1199)
    assert area == pytest.approx(seen.sum() * cell, rel=0.01)
    # The far edge lies at the range: the farthest vertex is at max_depth along the axis.
    depths = transform_points(invert(pose), footprint)[:, 2]
    assert depths.max() == pytest.approx(max_depth)
    assert depths.min() > 0


def test_footprint_on_a_raised_plane():
    raised = Plane(0.0, 0.0, 1.0, -1.0)  # z = 1
    footprint = floor_footprint(KINECT, LOOKING_DOWN, max_depth=5.0, floor=raised)
    np.testing.assert_allclose(footprint[:, 2], 1.0)
    np.testing.assert_allclose(np.abs(footprint[:, 0]), 320 / 525 * 2.0)


def test_field_of_view_needs_the_image_size():
    with pytest.raises(ValueError, match="image size"):
        camera_frustum(Intrinsics(525.0, 525.0, 319.5, 239.5), LOOKING_DOWN, 1.0)
