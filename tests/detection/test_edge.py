"""People cut by the image's left or right border (optrack.detection.edge): judged on
their visible part, flagged out_of_view, their floor position taken from their head."""

from __future__ import annotations

import numpy as np
import pytest

from optrack.bench.detection import PCL_GROUND
from optrack.detection.edge import corrected_head, lateral_cut
from optrack.detection.evaluate import evaluate_edges
from optrack.detection.params import detection_params
from optrack.detection.pipeline import PeopleDetector
from optrack.types import Intrinsics

KINECT1 = Intrinsics(525.0, 525.0, 319.5, 239.5, 640, 480)


def test_lateral_cut_names_the_border_that_crosses_a_persons_box():
    height = 1.8  # box 0.9 m wide
    assert lateral_cut(np.array([0.0, 0.0, 3.0]), height, KINECT1) == 0
    left_border_x = -319.5 / 525.0 * 3.0  # about -1.83 m at 3 m
    assert lateral_cut(np.array([left_border_x + 0.3, 0.0, 3.0]), height, KINECT1) == -1
    assert lateral_cut(np.array([-left_border_x - 0.3, 0.0, 3.0]), height, KINECT1) == 1
    assert lateral_cut(np.array([left_border_x + 0.5, 0.0, 3.0]), height, KINECT1) == 0


def _level_camera_c_T_g() -> np.ndarray:
    """A level camera 2 m above the floor: ground x = camera x, ground y = camera z
    (forward), ground z = -camera y (up)."""
    c_T_g = np.eye(4)
    c_T_g[:3, :3] = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])
    c_T_g[:3, 3] = (0.0, 2.0, 0.0)
    return c_T_g


def test_a_head_cut_by_the_border_is_centred_inside_its_visible_edge():
    c_T_g = _level_camera_c_T_g()
    g_T_c = np.linalg.inv(c_T_g)
    # A head (sphere, radius 0.09 m) whose centre sits 0.02 m outside the left border.
    depth, radius, height = 3.0, 0.09, 1.75
    border_slope = -319.5 / 525.0
    center_c = np.array([border_slope * depth - 0.02, 2.0 - (height - radius), depth])
    rng = np.random.default_rng(0)
    directions = rng.normal(size=(4000, 3))
    surface = center_c + radius * directions / np.linalg.norm(directions, axis=1)[:, None]
    seen = surface[surface[:, 0] / surface[:, 2] > border_slope]  # inside the image
    points = seen @ g_T_c[:3, :3].T + g_T_c[:3, 3]
    true_xy = (g_T_c[:3, :3] @ center_c + g_T_c[:3, 3])[:2]
    centroid = points[:, :2].mean(axis=0)
    assert np.linalg.norm(centroid - true_xy) > 0.05  # the visible part's centroid is off
    head = corrected_head(
        points, float(points[:, 2].max()), centroid, -1, c_T_g, KINECT1, 1.0, radius, 0.06
    )
    assert np.linalg.norm(head - true_xy) < 0.03
    # A head the border does not cut keeps its centroid.
    inside = points + np.array([0.5, 0.0, 0.0])
    kept = inside[:, :2].mean(axis=0)
    assert np.array_equal(
        corrected_head(
            inside, float(inside[:, 2].max()), kept, -1, c_T_g, KINECT1, 1.0, radius, 0.06
        ),
        kept,
    )


def _detect_right_part(five_people, cut: int, overrides=None):
    """five_people.pcd with the image's columns left of ``cut`` removed (a real image
    whose left border cuts through a person)."""
    points = np.ascontiguousarray(five_people.points[:, cut:])
    colors = np.ascontiguousarray(five_people.colors[:, cut:])
    intrinsics = Intrinsics(525.0, 525.0, 319.5 - cut, 239.5, 640 - cut, 480)
    detector = PeopleDetector(detection_params("pcl", overrides=overrides), ground=PCL_GROUND)
    return detector.process_cloud(points, intrinsics, colors).detections


def test_a_real_person_half_out_of_the_image_is_found_flagged_and_placed(five_people):
    full = PeopleDetector(detection_params("pcl"), ground=PCL_GROUND).process_cloud(
        five_people.points, KINECT1, five_people.colors
    )
    # The rightmost person, nobody beyond them; the new border through their axis.
    person = max(full.detections, key=lambda d: d.camera_xyz[0])
    x, _, z = person.camera_xyz
    cut = round(525.0 * x / z + 319.5)

    def near(detections):
        return [d for d in detections if np.hypot(d.camera_xyz[0] - x, d.camera_xyz[2] - z) < 0.3]

    found = near(_detect_right_part(five_people, cut))
    assert len(found) == 1 and found[0].out_of_view
    assert np.hypot(found[0].camera_xyz[0] - x, found[0].camera_xyz[2] - z) < 0.2
    # Judged on the black-bordered full-body window alone, the same half person is lost.
    assert near(_detect_right_part(five_people, cut, {"edge_window": False})) == []


@pytest.fixture(scope="module")
def edge_recording(tmp_path_factory):
    from optrack.sim.edge import edge_scenario
    from optrack.sim.recorder import write_recording
    from optrack.sim.world import Simulation

    path = tmp_path_factory.mktemp("edge") / "edge"
    write_recording(Simulation(edge_scenario(7, seconds=2.0), seed=7), path)
    return path


def test_simulated_people_crossing_the_border_are_found_and_placed(edge_recording):
    score = evaluate_edges(edge_recording)
    assert score.required >= 6
    assert score.recall >= 0.8 and score.position_error <= 0.15, vars(score)
    assert score.out_of_view >= 0.8 * score.found
    assert score.precision >= 0.95
    without = evaluate_edges(
        edge_recording, detection_params("kinect2", overrides={"edge_window": False})
    )
    assert without.recall < score.recall


def test_the_edge_scene_is_drawn_from_its_seed():
    from optrack.sim.edge import edge_scenario

    first, again, other = edge_scenario(3), edge_scenario(3), edge_scenario(4)
    assert first == again
    assert first.sensors.poses != other.sensors.poses
    assert first.people.routes != other.people.routes
    assert len(first.sensors.poses) == 1 and first.people.count == len(first.people.routes)
