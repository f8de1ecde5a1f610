"""The detector on real Kinect frames from PCL's test data, against PCL's own answers."""

from __future__ import annotations

import json

import numpy as np
import pytest

from optrack.bench.detection import PCL_GROUND, PCL_PEOPLE_XZ, match_people
from optrack.cli import main
from optrack.detection import PeopleDetector, detection_params
from optrack.detection.ground import check_ground, ground_T_camera
from optrack.geometry import transform_points
from optrack.types import RGBDFrame

from .conftest import KINECT1

INTRINSICS = "525,525,319.5,239.5"


def detect_json(capsys, *argv: str) -> dict:
    assert main(["detect", *argv, "--json"]) == 0
    out = capsys.readouterr().out
    assert out.count("\n") == 1  # exactly one JSON object on stdout
    return json.loads(out)


def assert_pcls_five(detections: list[dict]) -> None:
    found = np.array([(d["x"], d["z"]) for d in detections])
    assert len(found) == 5
    matched, worst = match_people(found, np.array(PCL_PEOPLE_XZ))
    assert matched == 5 and worst < 0.2, worst


def test_five_people_with_automatic_ground_are_pcls_five(shared_data, capsys):
    result = detect_json(
        capsys, str(shared_data / "pcl" / "five_people.pcd"), "--intrinsics", INTRINSICS
    )
    assert result["frame_id"] == "camera" and result["ground_source"] == "cloud"
    assert_pcls_five(result["detections"])
    for d in result["detections"]:
        assert 1.6 < d["height"] < 1.9  # adults
        assert 0.1 < d["y"] < 0.4  # centroids half way up, below the camera 1.27 m high


def test_five_people_with_pcls_ground_are_pcls_five(shared_data, capsys):
    ground = ",".join(str(v) for v in PCL_GROUND)
    result = detect_json(
        capsys,
        str(shared_data / "pcl" / "five_people.pcd"),
        "--intrinsics",
        INTRINSICS,
        f"--ground={ground}",
    )
    assert result["ground_source"] == "manual"
    assert_pcls_five(result["detections"])


def test_automatic_ground_agrees_with_pcls_within_3_degrees_and_5_cm(shared_data, capsys):
    result = detect_json(
        capsys, str(shared_data / "pcl" / "five_people.pcd"), "--intrinsics", INTRINSICS
    )
    ours = check_ground(result["ground"])
    pcl = check_ground(PCL_GROUND)
    assert ours.angle_deg(pcl) < 3.0
    assert abs(ours.d - pcl.d) < 0.05
    # Reported with the normal up, towards the camera: d is the camera's height.
    assert result["ground"][1] < 0 and 1.2 < result["ground"][3] < 1.35


def test_empty_office_has_nobody(shared_data, capsys):
    result = detect_json(
        capsys, str(shared_data / "pcl" / "office1.pcd"), "--intrinsics", INTRINSICS
    )
    assert result["detections"] == []
    assert result["ground"] is not None


def test_openptrack_kinect_defaults_find_the_same_five(five_people, office):
    # OpenPTrack's Kinect v1 settings: 1/4 of the pixels, people from 1.0 m, and the
    # luminance gate (this corridor's 113 is below 120, so from depth alone).
    detector = PeopleDetector(detection_params("kinect1"))
    batch = detector.process_cloud(five_people.points, KINECT1, five_people.colors)
    assert detector.last_luminance is not None and detector.last_luminance < 120
    assert {j.source for j in detector.last_judgements} == {"depth"}
    found = np.array([(d.camera_xyz[0], d.camera_xyz[2]) for d in batch.detections])
    assert match_people(found, np.array(PCL_PEOPLE_XZ))[0] == 5 and len(found) == 5
    empty = PeopleDetector(detection_params("kinect1"))
    assert empty.process_cloud(office.points, KINECT1, office.colors).detections == []


def test_depth_image_frame_finds_the_same_people_as_the_cloud(five_people):
    depth_mm = np.rint(np.nan_to_num(five_people.points[..., 2], nan=0.0) * 1000).astype(np.uint16)
    frame = RGBDFrame(depth_mm, KINECT1, depth_scale=0.001, color=five_people.colors)
    batch = PeopleDetector(detection_params("pcl")).process(frame)
    found = np.array([(d.camera_xyz[0], d.camera_xyz[2]) for d in batch.detections])
    assert len(found) == 5
    assert match_people(found, np.array(PCL_PEOPLE_XZ))[1] < 0.2


def test_dark_frame_is_judged_from_depth_alone_and_still_finds_five(five_people):
    dark = (five_people.colors // 20).astype(np.uint8)  # lights almost off
    detector = PeopleDetector(detection_params("pcl", overrides={"minimum_luminance": 120}))
    batch = detector.process_cloud(five_people.points, KINECT1, dark)
    assert {j.source for j in detector.last_judgements} == {"depth"}
    assert len(batch.detections) == 5
    # The candidate that is not a person (a poster board 4.8 m away) is still refused.
    assert any(not j.accepted for j in detector.last_judgements)


def test_people_cut_by_the_image_border_are_flagged_out_of_view(five_people):
    detector = PeopleDetector(detection_params("pcl"), ground=PCL_GROUND)
    batch = detector.process_cloud(five_people.points, KINECT1, five_people.colors)
    nearest = min(batch.detections, key=lambda d: d.camera_xyz[2])
    assert nearest.out_of_view  # the man on the right, 1.9 m away: his feet below the frame
    centre = min(batch.detections, key=lambda d: abs(d.camera_xyz[0] - 0.128))
    assert not centre.out_of_view
    for d in batch.detections:
        u, v, w, h = d.box
        assert 0 <= u and 0 <= v and u + w <= 640 and v + h <= 480 and w > 50 and h > 100
        assert len(d.histogram) == 16 * 4 and abs(sum(d.histogram) - 1.0) < 1e-6
    assert batch.frame_id == "ground" and batch.ground is not None


def test_world_positions_follow_the_calibration(five_people):
    # A calibration that agrees with PCL's floor: the world is that floor's frame.
    world_T_camera = ground_T_camera(check_ground(PCL_GROUND))
    detector = PeopleDetector(detection_params("pcl"), world_T_camera=world_T_camera)
    batch = detector.process_cloud(five_people.points, KINECT1, five_people.colors)
    assert batch.frame_id == "world" and len(batch.detections) == 5
    assert detector.ground.source == "cloud"  # the cloud's floor is within 0.2 m of it
    for d in batch.detections:
        expected = transform_points(world_T_camera, np.array([d.camera_xyz]))[0]
        np.testing.assert_allclose([d.x, d.y, d.z], expected, atol=1e-9)
        assert d.z == pytest.approx(d.height / 2, abs=0.05)  # the centroid, half way up
