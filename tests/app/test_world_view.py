"""The World 3D view draws cameras, clouds and people (OpenGL: run under Xvfb)."""

import numpy as np
import pytest

from app.trails import track_color
from app.widgets.world_view import WorldView
from optrack.geometry import make_pose
from optrack.types import Intrinsics, NetworkCalibration, SensorCalibration, Track, TrackBatch

from .test_main_window import image_array

pytestmark = pytest.mark.opengl

KINECT = Intrinsics(525.0, 525.0, 319.5, 239.5, width=640, height=480)


def matrix(pose):
    return tuple(tuple(float(v) for v in row) for row in pose)


def shown(qtbot, **kwargs) -> WorldView:
    view = WorldView(**kwargs)
    qtbot.addWidget(view)
    view.resize(640, 480)
    view.show()
    qtbot.waitExposed(view)
    return view


def frame(view: WorldView) -> np.ndarray:
    return image_array(view.grabFramebuffer()).astype(int)


def near(pixels: np.ndarray, rgb, tolerance: int = 60) -> np.ndarray:
    return np.abs(pixels - np.array(rgb)).sum(axis=2) < tolerance


def same_hue(pixels: np.ndarray, rgb) -> np.ndarray:
    """Pixels of the colour ``rgb`` however shaded: the same direction in RGB, not dark."""
    target = np.array(rgb, dtype=float) / np.linalg.norm(rgb)
    length = np.linalg.norm(pixels, axis=2)
    cosine = (pixels @ target) / np.maximum(length, 1e-9)
    return (cosine > 0.995) & (length > 80)


def test_people_are_cylinders_in_their_track_colour_with_trails(qtbot):
    view = shown(qtbot)
    view.overlay.show_message("")
    before = frame(view)
    colors = {track_id: track_color(track_id) for track_id in (2, 5)}
    for k in range(20):
        view.set_batch(
            TrackBatch(
                stamp=k * 0.1,
                tracks=[Track(2, -1.0 + 0.1 * k, 0.0, 1.8), Track(5, 2.0, 1.0 - 0.1 * k, 1.6)],
            )
        )
    after = frame(view)
    for rgb in colors.values():
        assert same_hue(after, rgb).sum() > same_hue(before, rgb).sum() + 500
    assert set(view.people) == {2, 5}
    assert [view.people[i][1].text for i in (2, 5)] == ["2", "5"]
    assert set(view.trail_items) == {2, 5}
    view.set_batch(TrackBatch(stamp=2.0, tracks=[Track(5, 2.0, -1.0, 1.6)]))
    assert set(view.people) == {5}


def test_cameras_are_drawn_as_named_pyramids(qtbot):
    view = shown(qtbot)
    before = frame(view)
    looking_down = make_pose(np.diag([1.0, -1.0, -1.0]), [1.0, 1.0, 3.0])
    calibration = NetworkCalibration(
        sensors={
            "ceiling": SensorCalibration(world_T_camera=matrix(looking_down), intrinsics=KINECT),
            "no_intrinsics": SensorCalibration(
                world_T_camera=matrix(make_pose(translation=[-2, 0, 2]))
            ),
        }
    )
    view.set_calibration(calibration, frustum_depth=1.5)
    assert set(view.cameras) == {"ceiling", "no_intrinsics"}
    assert view.cameras["ceiling"][1].text == "ceiling"
    lines = view.cameras["ceiling"][0].pos
    assert lines.shape == (16, 3)
    np.testing.assert_allclose(lines[0], [1.0, 1.0, 3.0])
    np.testing.assert_allclose(lines[1, 2], 1.5)  # a far corner, 1.5 m below the camera
    after = frame(view)
    assert near(after, (115, 191, 255)).sum() > near(before, (115, 191, 255)).sum() + 100


def test_point_clouds_are_drawn_per_sensor(qtbot):
    view = shown(qtbot)
    before = frame(view)
    xs, ys = np.meshgrid(np.linspace(-2, 2, 80), np.linspace(-2, 2, 80))
    points = np.column_stack([xs.ravel(), ys.ravel(), np.full(xs.size, 1.0)])
    colors = np.tile(np.array([[255, 0, 255]], dtype=np.uint8), (len(points), 1))
    view.set_cloud("ceiling", points, colors)
    after = frame(view)
    assert near(after, (255, 0, 255)).sum() > near(before, (255, 0, 255)).sum() + 500
    view.set_cloud("ceiling", points[:10], None)  # replaced, not added
    assert len(view.clouds) == 1 and len(view.clouds["ceiling"].pos) == 10


def _ndc(view: WorldView, point) -> tuple[float, float]:
    """Where ``point`` lands in the view (normalised coordinates, -1..1)."""
    from PySide6.QtGui import QVector4D

    viewport = (0, 0, view.width(), view.height())
    mapped = (view.projectionMatrix(viewport, viewport) * view.viewMatrix()).map(
        QVector4D(*map(float, point), 1.0)
    )
    return mapped.x() / mapped.w(), mapped.y() / mapped.w()


def test_cameras_far_apart_are_framed_with_room_for_their_names(qtbot):
    view = shown(qtbot, floor_size_m=10.0)
    view.resize(420, 600)  # a tall, narrow dock, as in the main window
    qtbot.wait(50)
    places = {"east": (7.0, 4.0, 2.5), "west": (-6.5, 1.0, 2.5), "south": (0.5, -6.0, 2.5)}
    default = view.opts["distance"]
    outside = [name for name, p in places.items() if not -1 < _ndc(view, p)[0] < 1]
    calibration = NetworkCalibration(
        sensors={
            name: SensorCalibration(
                world_T_camera=matrix(make_pose(translation=place)), intrinsics=KINECT
            )
            for name, place in places.items()
        }
    )
    view.set_calibration(calibration, frustum_depth=1.0)
    assert view.opts["distance"] > default
    for name, place in places.items():
        u, v = _ndc(view, place)
        assert -0.9 < u < 0.6 and -0.85 < v < 0.85, f"{name} lands at ({u:.2f}, {v:.2f})"
    assert outside == ["east"]  # the plain view would cut it off
    # Once the operator zooms, the view is theirs: a new calibration does not move it.
    view.user_moved = True
    view.opts["distance"] = 5.0
    view.set_calibration(calibration, frustum_depth=1.0)
    assert view.opts["distance"] == 5.0
