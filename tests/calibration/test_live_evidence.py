"""The shared evidence of a live calibration's sensors: distinct board poses seen together
with another calibrated sensor (optrack.calibration.live_evidence)."""

import numpy as np

from optrack.calibration.board import Checkerboard
from optrack.calibration.live_evidence import board_centres, shared_board_poses
from optrack.calibration.network import NetworkCalibrator
from optrack.calibration.overlap import facing_rotations
from optrack.calibration.synthetic import look_at
from optrack.geometry import invert, make_pose, project, transform_points
from optrack.types import Intrinsics

BOARD = Checkerboard(6, 5, 0.15)
K = Intrinsics(365.0, 365.0, 256.0, 212.0, width=512, height=424)
CAMERAS = {
    "a": look_at(np.array([-1.5, -3.0, 2.0]), np.array([0.0, 0.5, 1.2])),
    "b": look_at(np.array([1.5, -3.0, 2.0]), np.array([0.0, 0.5, 1.2])),
    "c": look_at(np.array([4.0, 0.0, 2.0]), np.array([0.0, 0.5, 1.2])),
}


def board_at(x: float, y: float, z: float, turn_deg: float = 0.0) -> np.ndarray:
    """A board upright, its printed face towards the cameras (-y), turned about the
    vertical by ``turn_deg``, its pattern's centre at (x, y, z)."""
    t = np.radians(turn_deg)
    rotation = facing_rotations(np.array([[np.sin(t), -np.cos(t), 0.0]]))[0]
    return make_pose(rotation, np.array([x, y, z]) - rotation @ BOARD.center)


def corners(world_T_board: np.ndarray, sensors) -> dict[str, np.ndarray]:
    seen = {}
    for sid in sensors:
        points = transform_points(invert(CAMERAS[sid]) @ world_T_board, BOARD.object_points)
        pixels, _ = project(points, K)
        seen[sid] = pixels
    return seen


def test_still_views_of_one_held_board_are_one_shared_pose_and_another_place_is_a_second():
    calibrator = NetworkCalibrator(BOARD, {s: K for s in CAMERAS})
    held = board_at(0.0, 0.5, 1.2)
    for _ in range(4):  # four still views of the same held board: one pose
        calibrator.add(corners(held, ("a", "b")))
    calibrator.add(corners(board_at(0.1, 0.5, 1.2), ("a",)))  # seen alone: not shared
    poses = shared_board_poses(calibrator, 0.3, 15.0)
    assert {s: len(p) for s, p in poses.items()} == {"a": 1, "b": 1}
    calibrator.add(corners(board_at(0.05, 0.5, 1.25), ("a", "b")))  # 7 cm off: the same
    calibrator.add(corners(board_at(0.0, 0.5, 1.2, 20.0), ("a", "b")))  # turned 20 deg
    calibrator.add(corners(board_at(0.6, 0.9, 1.4), ("a", "b")))  # another place
    poses = shared_board_poses(calibrator, 0.3, 15.0)
    assert {s: len(p) for s, p in poses.items()} == {"a": 3, "b": 3}
    # the centres, in the frame of the camera's pose, are where the boards were held
    centres = board_centres(CAMERAS["a"], poses["a"], BOARD.center)
    assert np.allclose(centres[0], [0.0, 0.5, 1.2], atol=1e-3)
    assert np.allclose(centres[2], [0.6, 0.9, 1.4], atol=1e-3)
