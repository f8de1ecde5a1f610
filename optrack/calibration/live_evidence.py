"""How much shared evidence places each sensor of a live calibration: the distinct board
poses it saw together with another calibrated sensor.

A sensor joins the network at its first board view shared with a calibrated sensor,
and one board pose leaves it where that pose's views put it: measured on the simulated
operator's plans (corners projected with 0.3 px of noise, solved with the floor), the
sensors calibrated from one shared pose were up to 13 mm and 0.29 degree off on six
sensors and 42 mm and 0.59 degree on the default three, against 6 mm and 0.15 degree,
and 22 mm and 0.26 degree, once each shared two poses 0.6 m apart. The extrinsics
page therefore calls a sensor calibrated once it shares
``calibration_live.min_shared_poses`` distinct poses (:attr:`SensorLive.settled`);
still views of one held board are one pose, not several.
"""

from __future__ import annotations

import numpy as np

from optrack.calibration.network import NetworkCalibrator
from optrack.geometry import rotation_angle_deg

__all__ = ["board_centres", "shared_board_poses"]


def shared_board_poses(
    calibrator: NetworkCalibrator, spacing_m: float, turn_deg: float
) -> dict[str, list[np.ndarray]]:
    """Per calibrated sensor, the distinct poses (camera_T_board, 4x4) of the board it saw
    at an instant together with another calibrated sensor: a pose counts once however
    many still views it gave; two are distinct when their board centres are ``spacing_m``
    apart or they are turned ``turn_deg`` from each other."""
    tree = calibrator.tree
    centre = np.append(calibrator.board.center, 1.0)
    poses: dict[str, list[np.ndarray]] = {sid: [] for sid in tree.sensors}
    for instant in calibrator.instants:
        sharing = [s for s in instant.views if tree.calibrated(s)]
        if len(sharing) < 2:
            continue
        for sid in sharing:
            pose = instant.views[sid].camera_T_board
            kept = poses[sid]
            if not any(
                np.linalg.norm((pose - old) @ centre) < spacing_m
                and rotation_angle_deg(pose, old) < turn_deg
                for old in kept
            ):
                kept.append(pose)
    return poses


def board_centres(
    world_T_camera: np.ndarray, poses: list[np.ndarray], centre: np.ndarray
) -> np.ndarray:
    """The board centres (Kx3) of a sensor's ``poses`` (camera_T_board) in the frame of
    its ``world_T_camera``."""
    if not poses:
        return np.zeros((0, 3))
    stacked = np.stack([world_T_camera @ pose for pose in poses])
    return stacked[:, :3, :3] @ centre + stacked[:, :3, 3]
