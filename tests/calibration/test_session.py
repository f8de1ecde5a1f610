"""Network calibration from a recording (rendered board views, known truth) and the CLI."""

from __future__ import annotations

import contextlib
import io
import json

import numpy as np
import pytest
import yaml
from calibration_helpers import (
    floor_board,
    render,
    standing_board,
    three_cameras,
    write_board_recording,
)

from optrack.calibration.board import Checkerboard, find_corners
from optrack.calibration.files import load_calibration
from optrack.calibration.network import NETWORK_PARAMS, observe_board
from optrack.calibration.quality import calibration_errors
from optrack.calibration.session import SESSION_PARAMS, board_on_floor
from optrack.cli import main
from optrack.geometry import invert, rotation_angle_deg
from optrack.types import Intrinsics

BOARD = Checkerboard(6, 5, 0.12)


def _placements(cameras):
    rng = np.random.default_rng(0)
    names = sorted(cameras)
    placements = []
    for i in range(9):
        centre = np.array([*rng.uniform(-0.7, 0.7, 2), rng.uniform(0.9, 1.5)])
        pair = [names[i % 3], names[(i + 1) % 3]]
        facing = sum(
            (cameras[n][:3, 3] - centre) / np.linalg.norm(cameras[n][:3, 3] - centre) for n in pair
        )
        facing[2] *= 0.3
        placements.append((standing_board(BOARD, centre, facing), False))
    placements.append((floor_board(BOARD, (0.0, 0.0), 0.3), True))
    placements.append((floor_board(BOARD, (0.5, -0.4), 1.3), True))
    return placements


@pytest.fixture(scope="module")
def board_recording(tmp_path_factory):
    out = tmp_path_factory.mktemp("session") / "boards"
    cameras = write_board_recording(out, BOARD, _placements(three_cameras()))
    return out, cameras


@pytest.fixture(scope="module")
def network_run(board_recording, tmp_path_factory):
    """``optrack calibrate network REC --out FILE --json``: (stdout, stderr, file)."""
    path, _ = board_recording
    out = tmp_path_factory.mktemp("network") / "network.yaml"
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        code = main(["calibrate", "network", str(path), "--out", str(out), "--json"])
    assert code == 0, stderr.getvalue()
    return stdout.getvalue(), stderr.getvalue(), out


def test_a_recorded_board_session_calibrates_every_sensor_and_the_floor(network_run):
    stdout, _, _ = network_run
    payload = json.loads(stdout)
    assert payload["world"] == "floor" and payload["uncalibrated"] == []
    assert payload["floor_views"] == 2
    assert payload["floor_views_wrong"] == 0 and payload["floor_views_missed"] == 0
    assert {s["image"] for s in payload["sensors"].values()} == {"infrared"}
    assert payload["max_position_error_m"] < 0.01
    assert payload["max_rotation_error_deg"] < 0.15
    assert payload["ground_error_deg"] < 0.2 and payload["ground_error_m"] < 0.005


def test_a_board_held_up_is_not_taken_for_the_floor_but_one_lying_on_it_is():
    k = Intrinsics(250.0, 250.0, 159.5, 119.5, 320, 240)
    camera = three_cameras()["a"]
    params = SESSION_PARAMS.create()
    thickness = NETWORK_PARAMS.defaults()["board_thickness"]
    held = standing_board(BOARD, np.array([0.0, 0.0, 1.2]), camera[:3, 3] - [0.0, 0.0, 1.2])
    tilted_up = floor_board(BOARD, (-0.9, -0.6), 0.3)  # face up, but held at waist height
    tilted_up[2, 3] += 0.8
    lying = floor_board(BOARD, (0.0, 0.0), 0.3)
    answers = []
    for pose in (held, tilted_up, lying):
        infrared, depth = render(BOARD, k, camera, pose, 2)
        corners = find_corners(infrared, BOARD, infrared=True)
        assert corners is not None
        view = observe_board("a", corners, k, BOARD)
        answers.append(board_on_floor(view, depth, k, BOARD, params, thickness))
    assert answers == [False, False, True]


def test_network_cli_writes_the_file_and_prints_one_json_object(network_run):
    stdout, stderr, out = network_run
    payload = json.loads(stdout)  # exactly one JSON object on stdout
    assert stdout.count("\n") == 1
    assert "board seen by" in stderr  # progress on stderr
    assert set(payload["sensors"]) == {"a", "b", "c"}
    calibration = load_calibration(out)
    assert calibration.board.cols == 6 and calibration.sensors["a"].image == "infrared"
    np.testing.assert_allclose(calibration.pose("b"), payload["sensors"]["b"]["world_T_camera"])


def test_network_cli_without_a_board_says_which_options_to_give(tmp_path, capsys):
    from optrack.recording import RecordingWriter, SensorInfo
    from optrack.types import RGBDFrame

    k = Intrinsics(250.0, 250.0, 159.5, 119.5, 320, 240)
    path = tmp_path / "plain"
    with RecordingWriter(
        path, [SensorInfo(id="a", intrinsics=k, streams=["depth", "infrared"])]
    ) as w:
        w.write(
            RGBDFrame(
                np.ones((240, 320), np.float32),
                k,
                "a",
                0.0,
                infrared=np.zeros((240, 320), np.uint8),
            )
        )
    assert main(["calibrate", "network", str(path), "--out", str(tmp_path / "n.yaml")]) == 1
    assert "--board" in capsys.readouterr().err


def _perturbed_file(board_recording, tmp_path):
    """The truth turned and lifted as a whole: the world frame is off, the network is right."""
    path, truth = board_recording
    from scipy.spatial.transform import Rotation

    from optrack.calibration.files import CalibrationFile, SensorEntry, save_calibration
    from optrack.geometry import make_pose

    offset = make_pose(
        Rotation.from_euler("xyz", [3.0, -2.0, 25.0], degrees=True), [0.4, -0.2, 0.3]
    )
    sensors = {
        sid: SensorEntry(
            world_T_camera=tuple(tuple(float(v) for v in row) for row in offset @ pose)
        )
        for sid, pose in truth.items()
    }
    file = tmp_path / "off.yaml"
    save_calibration(file, CalibrationFile(sensors=sensors))
    return path, truth, file, offset


def test_ground_cli_puts_the_world_back_on_the_floor_from_boards_lying_on_it(
    board_recording, tmp_path, capsys
):
    path, truth, file, _ = _perturbed_file(board_recording, tmp_path)
    out = tmp_path / "grounded.yaml"
    assert (
        main(
            [
                "calibrate",
                "ground",
                str(path),
                "--calibration",
                str(file),
                "--out",
                str(out),
                "--json",
                "--board",
                "6x5",
                "--square",
                "0.12",
            ]
        )
        == 0
    )
    payload = json.loads(capsys.readouterr().out)
    assert payload["world"] == "floor" and payload["floor_views"] == 2
    assert payload["tilt_change_deg"] == pytest.approx(3.6, abs=0.3)
    grounded = load_calibration(out)
    errors = calibration_errors({s: grounded.pose(s) for s in truth}, truth)
    assert errors.ground_error_deg < 0.2 and errors.ground_error_m < 0.005


def test_ground_cli_sets_the_world_from_points_of_known_coordinates(
    board_recording, tmp_path, capsys
):
    _, truth, file, offset = _perturbed_file(board_recording, tmp_path)
    rng = np.random.default_rng(3)
    points = []
    for sid, pose in truth.items():
        for _ in range(2):
            world = np.array([*rng.uniform(-1.5, 1.5, 2), rng.uniform(0.0, 1.0)])
            camera = invert(pose)[:3, :3] @ world + invert(pose)[:3, 3]
            points.append({"sensor": sid, "camera": camera.tolist(), "world": world.tolist()})
    points_file = tmp_path / "points.yaml"
    points_file.write_text(yaml.safe_dump({"points": points}))
    out = tmp_path / "world.yaml"
    assert (
        main(
            [
                "calibrate",
                "ground",
                "--calibration",
                str(file),
                "--points",
                str(points_file),
                "--out",
                str(out),
                "--json",
            ]
        )
        == 0
    )
    payload = json.loads(capsys.readouterr().out)
    assert payload["points"] == 6 and payload["points_rms_m"] < 1e-6
    assert payload["rotation_change_deg"] == pytest.approx(rotation_angle_deg(offset), abs=1e-4)
    placed = load_calibration(out)
    for sid, pose in truth.items():
        np.testing.assert_allclose(placed.pose(sid), pose, atol=1e-6)


def test_points_on_one_line_are_refused(board_recording, tmp_path, capsys):
    _, truth, file, _ = _perturbed_file(board_recording, tmp_path)
    sid = sorted(truth)[0]
    points = [
        {"sensor": sid, "camera": [0.0, 0.0, z], "world": [0.0, 0.0, z]} for z in (1.0, 2.0, 3.0)
    ]
    points_file = tmp_path / "line.yaml"
    points_file.write_text(yaml.safe_dump(points))
    code = main(
        [
            "calibrate",
            "ground",
            "--calibration",
            str(file),
            "--points",
            str(points_file),
            "--out",
            str(tmp_path / "x.yaml"),
        ]
    )
    assert code == 1
    assert "one line" in capsys.readouterr().err


def test_truth_cli_writes_the_true_poses_perturbed_by_exactly_what_was_asked(
    board_recording, tmp_path, capsys
):
    path, truth = board_recording
    out = tmp_path / "perturbed.yaml"
    assert main(["calibrate", "truth", str(path), "--out", str(out), "--perturb", "0.1,2"]) == 0
    perturbed = load_calibration(out)
    for sid, pose in truth.items():
        moved = perturbed.pose(sid)
        assert np.linalg.norm(moved[:3, 3] - pose[:3, 3]) == pytest.approx(0.1)
        assert rotation_angle_deg(moved, pose) == pytest.approx(2.0)
    assert main(["calibrate", "truth", str(path), "--out", str(out), "--perturb", "ten"]) == 1
    assert "METRES,DEGREES" in capsys.readouterr().err


def test_ground_cli_takes_clicked_pixels_and_reads_their_depth(board_recording, tmp_path, capsys):
    from optrack.recording import Recording

    path, truth, file, _ = _perturbed_file(board_recording, tmp_path)
    recording = Recording(path)
    points = []
    for sid, pose in truth.items():
        frame = recording.frame(sid, 0)
        depth, k = frame.depth_m(), frame.intrinsics
        for u, v in ((60, 200), (260, 190), (160, 230)):
            z = float(depth[v, u])
            camera = np.array([(u - k.cx) / k.fx * z, (v - k.cy) / k.fy * z, z])
            world = pose[:3, :3] @ camera + pose[:3, 3]
            points.append({"sensor": sid, "u": u, "v": v, "world": world.tolist()})
    points_file = tmp_path / "clicks.yaml"
    points_file.write_text(yaml.safe_dump({"points": points}))
    out = tmp_path / "clicked.yaml"
    args = ["calibrate", "ground", str(path), "--calibration", str(file)]
    assert main([*args, "--points", str(points_file), "--out", str(out), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["points_rms_m"] < 1e-6
    placed = load_calibration(out)
    for sid, pose in truth.items():
        np.testing.assert_allclose(placed.pose(sid), pose, atol=1e-6)
