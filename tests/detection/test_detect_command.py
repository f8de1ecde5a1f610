"""``optrack detect`` on bad input says one sentence and fails."""

from __future__ import annotations

import json

import cv2
import numpy as np

from optrack.cli import EXIT_ERROR, main
from optrack.io.pcd import write_pcd

INTRINSICS = ["--intrinsics", "525,525,319.5,239.5"]


def fails_with_one_sentence(capsys, argv, *says):
    assert main(["detect", *argv]) == EXIT_ERROR
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("optrack detect: ") and lines[0].endswith(".")
    for phrase in says:
        assert phrase in lines[0], lines[0]


def test_truncated_pcd(shared_data, tmp_path, capsys):
    cut = tmp_path / "cut.pcd"
    cut.write_bytes((shared_data / "pcl" / "five_people.pcd").read_bytes()[:200_000])
    fails_with_one_sentence(capsys, [str(cut), *INTRINSICS], "cut.pcd is damaged")


def test_depth_image_without_intrinsics(shared_data, capsys):
    depth = next((shared_data / "pcl" / "grabber_sequences" / "tiff").glob("*_depth.tiff"))
    fails_with_one_sentence(capsys, [str(depth)], "needs the camera intrinsics", "--intrinsics")


def test_ground_that_is_not_a_plane(shared_data, capsys):
    cloud = str(shared_data / "pcl" / "five_people.pcd")
    fails_with_one_sentence(capsys, [cloud, *INTRINSICS, "--ground=0,0,0,1.2"], "is not a plane")
    fails_with_one_sentence(capsys, [cloud, *INTRINSICS, "--ground=0,1,0"], "four finite numbers")


def test_cloud_that_is_not_organised(tmp_path, capsys):
    flat = tmp_path / "flat.pcd"
    write_pcd(flat, np.random.default_rng(0).uniform(1, 2, (100, 3)))
    fails_with_one_sentence(capsys, [str(flat), *INTRINSICS], "unorganised")


def test_scene_without_a_floor(tmp_path, capsys):
    # A wall 2 m in front of the camera and nothing else.
    depth = np.full((240, 320), 2000, np.uint16)
    path = tmp_path / "wall.png"
    cv2.imwrite(str(path), depth)
    fails_with_one_sentence(
        capsys, [str(path), "--intrinsics", "285,285,160,120"], "no floor was found", "--ground"
    )


def test_missing_input_and_plain_directory(tmp_path, capsys):
    fails_with_one_sentence(capsys, [str(tmp_path / "nothing.pcd")], "does not exist")
    fails_with_one_sentence(capsys, [str(tmp_path)], "not an optrack recording")


def test_depth_image_with_colour_is_detected(shared_data, capsys):
    tiff = shared_data / "pcl" / "grabber_sequences" / "tiff"
    stem = "frame_20121214T142255.814212"
    argv = [
        "detect",
        str(tiff / f"{stem}_depth.tiff"),
        "--color",
        str(tiff / f"{stem}_rgb.tiff"),
        "--intrinsics",
        "525,525,320,240",
        "--json",
    ]
    # This camera looks down at 46 degrees: beyond the default tilt limit, so give the floor.
    assert main([*argv, "--ground=0.065,-0.691,-0.720,0.712"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["detections"] == []  # a laptop and a box on the floor: nobody


def test_config_file_sets_detection_per_sensor_model(shared_data, tmp_path, capsys):
    cloud = str(shared_data / "pcl" / "five_people.pcd")
    config = tmp_path / "strict.yaml"

    def people(section: str, *extra: str) -> int:
        config.write_text(section)
        assert main(["detect", cloud, *INTRINSICS, "--config", str(config), *extra, "--json"]) == 0
        return len(json.loads(capsys.readouterr().out)["detections"])

    strict = "detection:\n  kinect1:\n    min_height: 2.2\n"  # Kinect v1 sensors only
    assert people(strict) == 5  # a bare .pcd has PCL's settings: not a Kinect v1
    assert people(strict, "--sensor-model", "kinect1") == 0
    assert people("detection:\n  min_height: 2.2\n") == 0  # every sensor
    config.write_text("detection:\n  kinect1:\n    max_distance: 100\n")
    fails_with_one_sentence(
        capsys, [cloud, *INTRINSICS, "--config", str(config)], "strict.yaml", "under kinect1"
    )
