"""``optrack bench calibration``: speed (and accuracy) of the network solver.

A synthetic session (:mod:`optrack.calibration.synthetic`): 10 sensors on a
ring, 300 board views each seen by two or more of them, 3 floor placements,
0.3 px corner noise.

* ``ba_seconds_10x300``: the global solve (factor graph built, then
  Levenberg-Marquardt to convergence) from the live tree's initial poses,
  median of 3 runs (wall clock; ``ba_cpu_seconds_10x300``: the
  process's CPU time over the same solve, all threads, which a busy machine
  inflates less).
* ``feedback_hz``: live feedback refreshes per second while views stream in
  as fast as they can (PnP, tree, iSAM2 update, per-sensor figures), from
  the median time of one update over the whole session. Finding the corners
  in the images is not included (it runs per sensor, beside this).
* ``intrinsics_left_*`` and ``stereo_*``: OpenCV's real stereo images
  (../shared/data/opencv, 9x6 board, 25 mm squares) with the default corner
  settings: the left camera's fx against OpenCV's 536.1, and the left-right
  pose from the network solver (intrinsics fixed) against
  ``cv2.stereoCalibrate(..., CALIB_FIX_INTRINSIC)`` on the same corners.
  ``null`` with ``stereo_skipped`` saying why when the folder is absent.
* ``intrinsics_replica_*``: the same 13 views rendered from a replica of
  OpenCV's sample board (its outer columns cut to half a square) through
  left_intrinsics.yml's own camera and poses, so that the true fx is known:
  the fx error (signed, %) and worst corner error of our default corners, and
  (``_opencv_sample``) of OpenCV's calibration sample's method, which made the
  536.1 reference.
* ``refinement_*``: Algorithm 1 on a synthetic walk (6 sensors, 45 s, 1.2 cm
  detection noise) from the true calibration moved 10 cm and turned 2 degrees
  per sensor: the mean alignment error before and after.

The simulated scenarios (``calibration``: 6 mixed sensors; ``refinement``:
the detector on rendered frames) take minutes; their commands and figures
are in docs/calibration.md.
"""

from __future__ import annotations

import platform
import time
from pathlib import Path
from typing import Any

import numpy as np

from optrack.bench.common import shared_data
from optrack.calibration.network import NETWORK_PARAMS, NetworkCalibrator
from optrack.calibration.quality import calibration_errors
from optrack.calibration.synthetic import (
    SyntheticSession,
    perturb_poses,
    synthetic_session,
    synthetic_walk,
)

__all__ = ["OPENCV_FX", "calibration_bench", "opencv_stereo_pose"]

OPENCV_FX = 536.1  # the reference for OpenCV's left*.jpg (left_intrinsics.yml: 535.9)


def opencv_stereo_pose(left, right, k_left, k_right, board, size) -> np.ndarray:
    """right_T_left from cv2.stereoCalibrate with CALIB_FIX_INTRINSIC on the views both
    cameras saw (``left``/``right``: per-view corners or None): the reference the network
    solver's stereo pose is compared with."""
    import cv2

    from optrack.geometry import make_pose

    pairs = [(a, b) for a, b in zip(left, right, strict=True) if a is not None and b is not None]
    opencv = cv2.stereoCalibrate(
        [board.object_points.astype(np.float32)] * len(pairs),
        [a.reshape(-1, 1, 2).astype(np.float32) for a, _ in pairs],
        [b.reshape(-1, 1, 2).astype(np.float32) for _, b in pairs],
        k_left.K,
        k_left.dist_coeffs,
        k_right.K,
        k_right.dist_coeffs,
        size,
        flags=cv2.CALIB_FIX_INTRINSIC,
        criteria=(cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-12),
    )
    return make_pose(opencv[5], opencv[6].ravel())


def _stereo_figures(folder: Path) -> dict[str, Any]:
    """The left camera's intrinsics and the stereo pose against cv2.stereoCalibrate."""

    from optrack.calibration.board import Checkerboard
    from optrack.calibration.intrinsics import calibrate_intrinsics, corners_from_images
    from optrack.calibration.stereo import stereo_calibrate
    from optrack.geometry import make_pose, rotation_angle_deg

    board = Checkerboard(9, 6, 0.025)
    left, size = corners_from_images(sorted(folder.glob("left*.jpg")), board)
    right, _ = corners_from_images(sorted(folder.glob("right*.jpg")), board)
    fits = {
        name: calibrate_intrinsics([c for c in views if c is not None], board, size)
        for name, views in (("left", left), ("right", right))
    }
    ours = stereo_calibrate(left, right, board, size)
    k_left, k_right = fits["left"].intrinsics, fits["right"].intrinsics
    reference = opencv_stereo_pose(left, right, k_left, k_right, board, size)
    estimate = make_pose(np.asarray(ours["rotation"]), np.asarray(ours["translation"]))
    reference_baseline = float(np.linalg.norm(reference[:3, 3]))
    return {
        "intrinsics_left_fx": k_left.fx,
        "intrinsics_left_fx_error_pct": abs(k_left.fx - OPENCV_FX) / OPENCV_FX * 100.0,
        "intrinsics_left_rms_px": fits["left"].rms,
        "intrinsics_left_rejected": len(fits["left"].rejected),
        "intrinsics_right_rejected": len(fits["right"].rejected),
        "stereo_baseline_m": ours["baseline_m"],
        "stereo_rotation_deg": ours["rotation_deg"],
        "stereo_rms_px": ours["rms"],
        "stereo_opencv_baseline_m": reference_baseline,
        "stereo_opencv_rotation_deg": rotation_angle_deg(reference),
        "stereo_baseline_error_pct": abs(ours["baseline_m"] - reference_baseline)
        / reference_baseline
        * 100.0,
        "stereo_rotation_error_deg": rotation_angle_deg(estimate, reference),
    }


def _replica_figures(folder: Path) -> dict[str, Any]:
    """fx from rendered views of a replica of OpenCV's sample board whose truth is known
    (:func:`optrack.calibration.printed.opencv_sample_replica`): our default corners, and
    OpenCV's calibration sample's 11-px window with every view kept, which is how
    left_intrinsics.yml (the reference above) was made."""
    from optrack.calibration.board import CORNER_PARAMS, OPENCV_SAMPLE_CORNERS, find_corners
    from optrack.calibration.intrinsics import INTRINSICS_PARAMS, calibrate_intrinsics
    from optrack.calibration.printed import opencv_sample_replica

    replica = opencv_sample_replica(folder)
    opencv_sample = CORNER_PARAMS.create(OPENCV_SAMPLE_CORNERS)
    keep_all = INTRINSICS_PARAMS.create({"fix_aspect_ratio": True, "max_rejection_rounds": 0})
    figures: dict[str, Any] = {"intrinsics_replica_true_fx": replica.fx}
    for suffix, corner_params, intrinsics_params in (
        ("", None, None),
        ("_opencv_sample", opencv_sample, keep_all),
    ):
        found = [find_corners(image, replica.board, corner_params) for image in replica.images]
        views = [c for c in found if c is not None]
        result = calibrate_intrinsics(views, replica.board, replica.size, intrinsics_params)
        errors = [replica.corner_errors(k, c).max() for k, c in enumerate(found) if c is not None]
        figures[f"intrinsics_replica_fx{suffix}"] = result.intrinsics.fx
        figures[f"intrinsics_replica_fx_error_pct{suffix}"] = (
            (result.intrinsics.fx - replica.fx) / replica.fx * 100.0
        )
        figures[f"intrinsics_replica_max_corner_error_px{suffix}"] = float(max(errors))
    return figures


def _refinement_figures() -> dict[str, Any]:
    """Algorithm 1 undoing a 10 cm / 2 degree perturbation of every sensor (synthetic)."""
    from optrack.calibration.refinement import Trajectory, refine_from_trajectories
    from optrack.geometry import transform_points

    session = synthetic_session(6, 10, floor_views=0, seed=3)
    truth = session.world_T_camera
    perturbed = perturb_poses(truth, 0.10, 2.0, seed=0)
    _, _, detections = synthetic_walk(truth, session.intrinsics, seconds=45, seed=0, noise_m=0.012)
    trajectories = {
        sid: Trajectory(t, transform_points(perturbed[sid], xyz))
        for sid, (t, xyz) in detections.items()
    }
    started = time.perf_counter()
    result = refine_from_trajectories(trajectories)
    seconds = time.perf_counter() - started
    refined = {sid: result.corrections[sid] @ perturbed[sid] for sid in result.corrections}
    after = calibration_errors(refined, truth)
    return {
        "refinement_error_before_m": result.error_before_m,
        "refinement_error_after_m": result.error_after_m,
        "refinement_improvement": result.error_before_m / max(result.error_after_m, 1e-12),
        "refinement_max_position_error_m": after.max_position_error_m,
        "refinement_max_rotation_error_deg": after.max_rotation_error_deg,
        "refinement_seconds": seconds,
    }


def _global_solve_figures(session: SyntheticSession, repeat: int) -> dict[str, Any]:
    """The global solve from scratch (no incremental tree), ``repeat`` times: median wall
    and CPU seconds, and how far the last solution is from the truth."""
    seconds, cpu_seconds, errors = [], [], None
    for _ in range(repeat):
        calibrator = NetworkCalibrator(
            session.board, session.intrinsics, NETWORK_PARAMS.create({"incremental": False})
        )
        for corners, floor in zip(session.corners, session.floor, strict=True):
            calibrator.add(corners, floor=floor)
        started, started_cpu = time.perf_counter(), time.process_time()
        result = calibrator.solve()
        seconds.append(time.perf_counter() - started)
        cpu_seconds.append(time.process_time() - started_cpu)
        errors = calibration_errors(result.world_T_camera, session.world_T_camera)
    assert errors is not None
    return {
        "ba_seconds_10x300": float(np.median(seconds)),
        "ba_cpu_seconds_10x300": float(np.median(cpu_seconds)),
        "max_position_error_m": errors.max_position_error_m,
        "max_rotation_error_deg": errors.max_rotation_error_deg,
        "ground_error_deg": errors.ground_error_deg,
    }


def _live_feedback_figures(session: SyntheticSession) -> dict[str, Any]:
    """Views streamed into the live (incremental) solver one by one: the time of each
    update, then the final solve from the live state."""
    calibrator = NetworkCalibrator(session.board, session.intrinsics, NETWORK_PARAMS.create())
    update_seconds = []
    for corners, floor in zip(session.corners, session.floor, strict=True):
        started = time.perf_counter()
        calibrator.add(corners, floor=floor)
        update_seconds.append(time.perf_counter() - started)
    started = time.perf_counter()
    result = calibrator.solve()
    final_from_live = time.perf_counter() - started
    median_update = float(np.median(update_seconds))
    return {
        "feedback_hz": 1.0 / median_update,
        "feedback_ms_median": median_update * 1000.0,
        "feedback_ms_p95": float(np.percentile(update_seconds, 95)) * 1000.0,
        "feedback_ms_max": float(np.max(update_seconds)) * 1000.0,
        "ba_seconds_from_live": final_from_live,
        "floor_views": result.floor_views,
        "reprojection_rms_px": result.rms_px,
    }


def calibration_bench() -> dict[str, Any]:
    """The figures of ``optrack bench calibration`` (see the module docstring)."""
    repeat = 3
    sensors, views = 10, 300
    session = synthetic_session(sensors, views, floor_views=3, seed=0)
    payload = {
        **_global_solve_figures(session, repeat),
        **_live_feedback_figures(session),
        "sensors": sensors,
        "board_views": views,
        "sensors_per_view": float(np.mean([len(c) for c in session.corners])),
        "repeat": repeat,
        "machine": platform.processor() or platform.machine(),
    }
    payload.update(_refinement_figures())
    folder = shared_data() / "opencv"
    if folder.is_dir():
        payload.update(_stereo_figures(folder))
        payload.update(_replica_figures(folder))
    else:
        payload.update(dict.fromkeys(("intrinsics_left_fx", "stereo_baseline_m"), None))
        payload["stereo_skipped"] = f"OpenCV's chessboard images not found at {folder}"
    return payload
