"""A stereo pair's relative pose from chessboard image pairs.

Each camera's intrinsics first (:mod:`optrack.calibration.intrinsics`), then
their relative pose through the network solver with the intrinsics fixed
(:mod:`optrack.calibration.network`), the left camera at the origin.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from optrack.calibration.board import Checkerboard
from optrack.calibration.intrinsics import calibrate_intrinsics
from optrack.calibration.network import NETWORK_PARAMS, CalibrationError, NetworkCalibrator
from optrack.geometry import invert, rotation_angle_deg
from optrack.types import as_matrix4

__all__ = ["stereo_calibrate"]


def stereo_calibrate(
    left: list[np.ndarray | None],
    right: list[np.ndarray | None],
    board: Checkerboard,
    size: tuple[int, int],
) -> dict[str, Any]:
    """Both cameras' intrinsics, then their relative pose through the network solver
    (intrinsics fixed). ``translation`` and ``rotation`` follow OpenCV's stereoCalibrate:
    they map left-camera points into the right camera (x_r = R x_l + T)."""
    intrinsics = {}
    for name, corners in (("left", left), ("right", right)):
        views = [c for c in corners if c is not None]
        intrinsics[name] = calibrate_intrinsics(views, board, size)
    calibrator = NetworkCalibrator(
        board,
        {name: r.intrinsics for name, r in intrinsics.items()},
        NETWORK_PARAMS.create({"incremental": False}),
        root="left",
    )
    pairs = 0
    for a, b in zip(left, right, strict=True):
        if a is not None and b is not None:
            calibrator.add({"left": a, "right": b})
            pairs += 1
    if pairs == 0:
        raise CalibrationError(
            "no image pair shows the board in both cameras; give --left and --right images "
            "taken at the same moments, in the same order."
        )
    result = calibrator.solve()
    left_T_right = invert(result.world_T_camera["left"]) @ result.world_T_camera["right"]
    right_T_left = invert(left_T_right)
    return {
        "baseline_m": float(np.linalg.norm(right_T_left[:3, 3])),
        "rotation_deg": rotation_angle_deg(right_T_left),
        "translation": [float(v) for v in right_T_left[:3, 3]],
        "rotation": [row[:3] for row in as_matrix4(right_T_left)[:3]],
        "left_T_right": as_matrix4(left_T_right),
        "rms": result.rms_px,
        "pairs": pairs,
        "left": intrinsics["left"].as_dict(),
        "right": intrinsics["right"].as_dict(),
    }
