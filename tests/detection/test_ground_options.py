"""``optrack detect`` with the floor given by hand: three points, three pixels, or a pick
(issue 4 item 2: manual and semi-automatic ground reachable from the command line)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from optrack.bench.detection import PCL_GROUND, PCL_PEOPLE_XZ, match_people
from optrack.cli import EXIT_ERROR, main
from optrack.detection.ground import check_ground

INTRINSICS = ["--intrinsics", "525,525,319.5,239.5"]
PCL_FLOOR = check_ground(PCL_GROUND)


def detect(capsys, shared_data, *options):
    cloud = str(shared_data / "pcl" / "five_people.pcd")
    assert main(["detect", cloud, *INTRINSICS, "--json", *options]) == 0
    return json.loads(capsys.readouterr().out)


def assert_is_pcls_floor(ground):
    plane = check_ground(ground)
    assert PCL_FLOOR.angle_deg(plane) < 3.0
    assert abs(PCL_FLOOR.d - plane.d) < 0.05


def assert_finds_pcls_five(result):
    found = np.array([(d["x"], d["z"]) for d in result["detections"]])
    matched, worst = match_people(found, np.array(PCL_PEOPLE_XZ))
    assert len(found) == 5 and matched == 5 and worst < 0.2


def test_three_floor_pixels_give_pcls_floor_and_its_five_people(shared_data, capsys):
    result = detect(capsys, shared_data, "--ground-pixels=120,470;600,470;300,380")
    assert result["ground_source"] == "pixels"
    assert_is_pcls_floor(result["ground"])
    assert_finds_pcls_five(result)


def test_a_pick_near_the_floor_picks_the_floor(shared_data, capsys):
    # 1.2 m below the camera, 2.5 m ahead: just above the floor, far from the walls.
    result = detect(capsys, shared_data, "--ground-pick=0,1.2,2.5")
    assert result["ground_source"] == "pick"
    assert_is_pcls_floor(result["ground"])
    assert_finds_pcls_five(result)


def test_three_floor_points_in_metres_are_the_floor_used(shared_data, capsys):
    # Three points of PCL's floor (y from its plane equation at the given x, z).
    a, b, c, d = PCL_GROUND
    points = [(x, -(a * x + c * z + d) / b, z) for x, z in ((-1.0, 2.0), (1.0, 2.0), (0.0, 3.5))]
    text = ";".join(",".join(f"{v:.6f}" for v in p) for p in points)
    result = detect(capsys, shared_data, f"--ground-points={text}")
    assert result["ground_source"] == "points"
    assert_is_pcls_floor(result["ground"])
    assert_finds_pcls_five(result)


@pytest.mark.parametrize(
    ("option", "says"),
    [
        ("--ground-points=0,1,1;0,1,2;0,1,3", "on one line"),
        ("--ground-points=0,1,1;0,1,2", "3 groups of 3 numbers"),
        ("--ground-pixels=120,470;600,470;900,380", "outside the 640x480 image"),
        ("--ground-pixels=1.5,2;3,4;5,6", "whole pixel numbers"),
        ("--ground-pick=0,1.2", "1 groups of 3 numbers"),
    ],
)
def test_unusable_floor_options_say_one_sentence(shared_data, capsys, option, says):
    cloud = str(shared_data / "pcl" / "five_people.pcd")
    assert main(["detect", cloud, *INTRINSICS, option]) == EXIT_ERROR
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("optrack detect: "), lines
    assert says in lines[0], lines[0]


def test_only_one_way_of_giving_the_floor_is_accepted(shared_data, capsys):
    cloud = str(shared_data / "pcl" / "five_people.pcd")
    with pytest.raises(SystemExit) as exit_:
        main(["detect", cloud, *INTRINSICS, "--ground=0,-1,0,1.2", "--ground-pick=0,1.2,2.5"])
    assert exit_.value.code != 0
    assert "not allowed with argument" in capsys.readouterr().err
