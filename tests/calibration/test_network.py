from __future__ import annotations

import json

import numpy as np
import pytest

from optrack.bench.calibration import opencv_stereo_pose
from optrack.calibration.board import Checkerboard
from optrack.calibration.intrinsics import calibrate_intrinsics, corners_from_images
from optrack.calibration.network import (
    NETWORK_PARAMS,
    CalibrationError,
    NetworkCalibrator,
    observe_board,
)
from optrack.calibration.quality import calibration_errors
from optrack.calibration.synthetic import synthetic_session
from optrack.cli import main
from optrack.geometry import invert, make_pose, rotation_angle_deg

BOARD = Checkerboard(9, 6, 0.025)


@pytest.fixture(scope="module")
def stereo_corners(opencv_data):
    left, size = corners_from_images(sorted(opencv_data.glob("left*.jpg")), BOARD)
    right, _ = corners_from_images(sorted(opencv_data.glob("right*.jpg")), BOARD)
    return left, right, size


def test_stereo_pose_from_the_network_solver_matches_opencv_stereo_calibrate(stereo_corners):
    left, right, size = stereo_corners
    k_left = calibrate_intrinsics([c for c in left if c is not None], BOARD, size).intrinsics
    k_right = calibrate_intrinsics([c for c in right if c is not None], BOARD, size).intrinsics
    calibrator = NetworkCalibrator(BOARD, {"left": k_left, "right": k_right}, root="left")
    for a, b in zip(left, right, strict=True):
        calibrator.add({"left": a, "right": b})
    result = calibrator.solve()
    right_T_left = invert(result.world_T_camera["right"]) @ result.world_T_camera["left"]

    reference = opencv_stereo_pose(left, right, k_left, k_right, BOARD, size)
    baseline = np.linalg.norm(right_T_left[:3, 3])
    assert baseline == pytest.approx(np.linalg.norm(reference[:3, 3]), rel=0.005)
    assert rotation_angle_deg(right_T_left, reference) < 0.1
    assert result.rms_px < 0.5


def test_stereo_cli_reports_baseline_rotation_translation_and_rms(opencv_data, capsys):
    left = sorted(map(str, opencv_data.glob("left*.jpg")))
    right = sorted(map(str, opencv_data.glob("right*.jpg")))
    code = main(
        ["calibrate", "stereo", "--board", "9x6", "--square", "0.025", "--json"]
        + ["--left", *left, "--right", *right]
    )
    assert code == 0
    payload = json.loads(capsys.readouterr().out)
    assert 0.08 < payload["baseline_m"] < 0.09  # 25 mm squares: a ~83 mm baseline
    assert payload["translation"][0] < 0  # OpenCV's T: the left camera seen from the right
    assert payload["rms"] < 0.5 and 0 < payload["rotation_deg"] < 2


@pytest.fixture(scope="module")
def session():
    return synthetic_session(6, 80, floor_views=3, seed=2)


def _run(session, **params):
    calibrator = NetworkCalibrator(session.board, session.intrinsics, NETWORK_PARAMS.create(params))
    feedback = None
    for corners, floor in zip(session.corners, session.floor, strict=True):
        feedback = calibrator.add(corners, floor=floor)
    return calibrator, feedback, calibrator.solve()


def test_every_camera_of_a_synthetic_network_is_recovered(session):
    _, _, result = _run(session, incremental=False)
    errors = calibration_errors(result.world_T_camera, session.world_T_camera)
    assert result.uncalibrated == []
    assert errors.max_position_error_m < 0.005
    assert errors.max_rotation_error_deg < 0.1
    assert errors.ground_error_deg < 0.1 and errors.ground_error_m < 0.005
    assert result.rms_px == pytest.approx(0.3 * np.sqrt(2), rel=0.2)  # the corner noise


def test_the_world_is_the_floor_under_the_best_seen_floor_board(session):
    _, _, result = _run(session, incremental=False)
    assert result.world == "floor" and result.anchor is not None
    thickness = NETWORK_PARAMS.defaults()["board_thickness"]
    # The anchor board's first corner is above the world origin, its z points down.
    anchor = result.world_T_board[result.anchor]
    np.testing.assert_allclose(anchor[:3, 3], [0.0, 0.0, thickness], atol=1e-4)  # floor_sigma
    np.testing.assert_allclose(anchor[:3, 2], [0.0, 0.0, -1.0], atol=1e-4)
    # In that frame the true cameras sit where the solver put them.
    floor_T_board = make_pose(np.diag([1.0, -1.0, -1.0]), (0.0, 0.0, thickness))
    true_world_T_floor = session.world_T_board[result.anchor] @ invert(floor_T_board)
    for sid, pose in result.world_T_camera.items():
        truth = invert(true_world_T_floor) @ session.world_T_camera[sid]
        assert np.linalg.norm(pose[:3, 3] - truth[:3, 3]) < 0.02
        assert rotation_angle_deg(pose, truth) < 0.3


def test_floor_boards_end_in_one_plane(session):
    _, _, result = _run(session, incremental=False)
    thickness = NETWORK_PARAMS.defaults()["board_thickness"]
    floors = [i for i, on_floor in enumerate(session.floor) if on_floor]
    assert result.floor_views == len(floors)
    for index in floors:
        pose = result.world_T_board[index]
        assert pose[2, 3] == pytest.approx(thickness, abs=1e-4)  # eq. 3-4: on the plane
        assert np.degrees(np.arccos(-pose[2, 2])) < 0.02  # face up


def test_live_feedback_has_views_rms_tree_and_covisibility(session):
    calibrator, feedback, _ = _run(session, incremental=True)
    assert feedback.all_calibrated
    roots = [s for s, st in feedback.sensors.items() if st.parent is None]
    assert roots == [calibrator.tree.root]
    for status in feedback.sensors.values():
        assert status.views > 0 and status.used_views == status.views
        assert status.rms_px == pytest.approx(0.42, abs=0.1)
    pairs = sum(len(c) * (len(c) - 1) // 2 for c in session.corners)
    assert sum(feedback.covisibility.values()) == pairs
    json.dumps(feedback.as_dict())  # the GUI and the bus can carry it


def test_incremental_and_batch_solves_agree(session):
    _, _, batch = _run(session, incremental=False)
    _, _, live = _run(session, incremental=True)
    for sid in batch.world_T_camera:
        a, b = batch.world_T_camera[sid], live.world_T_camera[sid]
        assert np.linalg.norm(a[:3, 3] - b[:3, 3]) < 1e-4
        assert rotation_angle_deg(a, b) < 1e-3


def test_a_sensor_that_never_shares_a_view_is_reported_uncalibrated(session):
    intrinsics = {**session.intrinsics, "lonely": session.intrinsics["cam0"]}
    calibrator = NetworkCalibrator(
        session.board, intrinsics, NETWORK_PARAMS.create({"incremental": False})
    )
    for corners, floor in zip(session.corners, session.floor, strict=True):
        calibrator.add(corners, floor=floor)
    calibrator.add({"lonely": next(iter(session.corners[0].values()))})
    result = calibrator.solve()
    assert result.uncalibrated == ["lonely"]
    assert result.sensors["lonely"].views == 1 and not result.sensors["lonely"].calibrated


def test_no_shared_view_at_all_is_a_user_error(session):
    calibrator = NetworkCalibrator(session.board, session.intrinsics)
    sid, corners = next(iter(session.corners[0].items()))
    calibrator.add({sid: corners})
    with pytest.raises(CalibrationError, match="at the same time"):
        calibrator.solve()


def test_a_wrongly_detected_board_cannot_pull_the_solution(session):
    """A view whose corners are scrambled is refused by its PnP residual; one whose
    corners are merely off by a few pixels is held by the Huber loss."""
    calibrator = NetworkCalibrator(
        session.board, session.intrinsics, NETWORK_PARAMS.create({"incremental": False})
    )
    rng = np.random.default_rng(0)
    for i, (corners, floor) in enumerate(zip(session.corners, session.floor, strict=True)):
        if i == 5:
            sid = sorted(corners)[0]
            corners = {**corners, sid: rng.permutation(corners[sid])}
        if i == 9:
            sid = sorted(corners)[0]
            bad = corners[sid].copy()
            bad[:5] += 6.0
            corners = {**corners, sid: bad}
        calibrator.add(corners, floor=floor)
    result = calibrator.solve()
    errors = calibration_errors(result.world_T_camera, session.world_T_camera)
    assert errors.max_position_error_m < 0.006 and errors.max_rotation_error_deg < 0.12
    assert sum(status.rejected for status in result.sensors.values()) == 1  # the scrambled one


def test_cameras_held_at_known_poses_do_not_move_and_the_floor_is_still_found(session):
    truth = session.world_T_camera
    calibrator = NetworkCalibrator(session.board, session.intrinsics, fixed_poses=truth)
    for corners, floor in zip(session.corners, session.floor, strict=True):
        if floor:
            calibrator.add(corners, floor=True)
    result = calibrator.solve()
    assert result.world == "floor"
    root = sorted(truth)[0]
    new_T_old = result.world_T_camera[root] @ invert(truth[root])
    for sid in truth:
        moved = new_T_old @ truth[sid]
        assert np.linalg.norm(moved[:3, 3] - result.world_T_camera[sid][:3, 3]) < 1e-5
    # The true floor (z = 0) is the new world's floor.
    assert rotation_angle_deg(new_T_old) < 180
    up = new_T_old[:3, :3] @ np.array([0.0, 0.0, 1.0])
    assert np.degrees(np.arccos(np.clip(up[2], -1, 1))) < 0.1
    assert abs(new_T_old[2, 3]) < 0.005


def test_board_pose_of_one_view_comes_from_pnp(session):
    corners = session.corners[0]
    sid = sorted(corners)[0]
    view = observe_board(sid, corners[sid], session.intrinsics[sid], session.board)
    truth = invert(session.world_T_camera[sid]) @ session.world_T_board[0]
    assert np.linalg.norm(view.camera_T_board[:3, 3] - truth[:3, 3]) < 0.05
    assert view.rms_px < 1.0 and view.quality > 5
