"""``optrack bench calibration``: speed (and accuracy) of the network solver.

A synthetic session (:mod:`optrack.calibration.synthetic`): 10 sensors on a
ring, 300 board views each seen by two or more of them, 3 floor placements,
0.3 px corner noise.

* ``ba_seconds_10x300``: the global solve (factor graph built, then
  Levenberg-Marquardt to convergence) from the live tree's initial poses,
  median of ``--repeat`` runs.
* ``feedback_hz``: live feedback refreshes per second while views stream in
  as fast as they can (PnP, tree, iSAM2 update, per-sensor figures), from
  the median time of one update over the whole session. Finding the corners
  in the images is not included (it runs per sensor, beside this).
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time

import numpy as np

from optrack.calibration.network import NETWORK_PARAMS, NetworkCalibrator
from optrack.calibration.quality import calibration_errors
from optrack.calibration.synthetic import synthetic_session

__all__ = ["bench_calibration"]


def bench_calibration(args: argparse.Namespace) -> int:
    repeat = 3
    sensors, views = 10, 300
    session = synthetic_session(sensors, views, floor_views=3, seed=0)
    corners_per_update = float(np.mean([len(c) for c in session.corners]))

    batch_seconds, batch_errors = [], None
    for _ in range(repeat):
        calibrator = NetworkCalibrator(
            session.board, session.intrinsics, NETWORK_PARAMS.create({"incremental": False})
        )
        for corners, floor in zip(session.corners, session.floor, strict=True):
            calibrator.add(corners, floor=floor)
        started = time.perf_counter()
        result = calibrator.solve()
        batch_seconds.append(time.perf_counter() - started)
        batch_errors = calibration_errors(result.world_T_camera, session.world_T_camera)

    calibrator = NetworkCalibrator(session.board, session.intrinsics, NETWORK_PARAMS.create())
    update_seconds = []
    for corners, floor in zip(session.corners, session.floor, strict=True):
        started = time.perf_counter()
        calibrator.add(corners, floor=floor)
        update_seconds.append(time.perf_counter() - started)
    started = time.perf_counter()
    live_result = calibrator.solve()
    final_from_live = time.perf_counter() - started
    median_update = float(np.median(update_seconds))
    assert batch_errors is not None
    payload = {
        "ba_seconds_10x300": float(np.median(batch_seconds)),
        "feedback_hz": 1.0 / median_update,
        "feedback_ms_median": median_update * 1000.0,
        "feedback_ms_p95": float(np.percentile(update_seconds, 95)) * 1000.0,
        "feedback_ms_max": float(np.max(update_seconds)) * 1000.0,
        "ba_seconds_from_live": final_from_live,
        "sensors": sensors,
        "board_views": views,
        "floor_views": live_result.floor_views,
        "sensors_per_view": corners_per_update,
        "reprojection_rms_px": live_result.rms_px,
        "max_position_error_m": batch_errors.max_position_error_m,
        "max_rotation_error_deg": batch_errors.max_rotation_error_deg,
        "ground_error_deg": batch_errors.ground_error_deg,
        "repeat": repeat,
        "machine": platform.processor() or platform.machine(),
    }
    if getattr(args, "json", False):
        sys.stdout.write(json.dumps(payload) + "\n")
    else:
        print(
            f"global solve {payload['ba_seconds_10x300']:.2f} s (10 sensors x 300 views); "
            f"live feedback {payload['feedback_hz']:.1f} Hz",
            file=sys.stderr,
        )
    return 0
