"""The live wizard's walk refinement (optrack/calibration/live_refine.py): a sensor's walk
correction is checked against what its checkerboard views say, and the corrections are
applied all together or not at all."""

from __future__ import annotations

import numpy as np

from optrack.calibration.live_refine import board_rms_px, refine_walk, walk_trajectories
from optrack.calibration.network import NetworkCalibrator
from optrack.calibration.refinement import alignment_error
from optrack.calibration.synthetic import synthetic_session, synthetic_walk
from optrack.net.messages import DetectionsMessage
from optrack.types import (
    Detection,
    DetectionBatch,
    NetworkCalibration,
    SensorCalibration,
    as_matrix4,
)


def _moved(pose: np.ndarray, dx: float) -> np.ndarray:
    moved = pose.copy()
    moved[0, 3] += dx
    return moved


def _walk(network, seed=0):
    """Each sensor's detections of one walker, as the nodes send them (camera frame)."""
    truth, intrinsics = network
    _, _, detections = synthetic_walk(truth, intrinsics, seconds=45, seed=seed, noise_m=0.012)
    return {
        sid: [
            DetectionsMessage(
                batch=DetectionBatch(
                    sid, float(t), detections=[Detection(0, 0, 0.9, 1.75, 2.0, camera_xyz=tuple(p))]
                )
            )
            for t, p in zip(times, xyz, strict=True)
        ]
        for sid, (times, xyz) in detections.items()
    }


def _calibration(poses: dict[str, np.ndarray]) -> NetworkCalibration:
    return NetworkCalibration(
        sensors={s: SensorCalibration(world_T_camera=as_matrix4(p)) for s, p in poses.items()}
    )


def _board(believed: dict[str, np.ndarray], indifferent: set[str] = frozenset()):
    """Board evidence that puts each sensor at ``believed[sensor]``: its RMS, 1 px there,
    grows by 10 px a metre away from it (a sensor in ``indifferent`` has 1 px wherever)."""

    def rms(poses):
        return {
            s: 1.0
            if s in indifferent
            else 1.0 + 10.0 * float(np.linalg.norm(p[:3, 3] - believed[s][:3, 3]))
            for s, p in poses.items()
        }

    return rms


def _no_progress(fraction: float, text: str) -> None:
    assert 0.0 <= fraction <= 1.0 and text


def test_corrections_the_board_agrees_with_are_applied(network):
    truth, _ = network
    base = dict(truth)
    base["cam1"] = _moved(truth["cam1"], 0.10)
    report = refine_walk(_calibration(base), _walk(network), _board(truth), 0.5, _no_progress)
    assert report.refused == {}
    assert report.error_after_m < 0.5 * report.error_before_m
    assert "cam1" in report.corrections
    moved = report.calibration.pose("cam1")[:3, 3] - truth["cam1"][:3, 3]
    assert np.linalg.norm(moved[:2]) < 0.04  # 10 cm off before


def test_corrections_left_that_make_the_sensors_disagree_more_are_not_applied(network):
    """cam1 is 10 cm off and its board says it is right (its correction is refused); the
    other sensors' corrections lean towards cam1, and only cam0's is not refused (its board
    does not care): applied alone it would make the sensors disagree more than none."""
    truth, _ = network
    base = dict(truth)
    base["cam1"] = _moved(truth["cam1"], 0.10)
    batches = _walk(network)
    report = refine_walk(_calibration(base), batches, _board(base, {"cam0"}), 0.05, _no_progress)
    # The premise: cam0's correction alone makes the disagreement worse.
    unrefused = refine_walk(
        _calibration(base), batches, _board(base, set(base)), 0.05, _no_progress
    )
    trajectories = walk_trajectories(_calibration(base), batches)
    alone = dict(trajectories)
    alone["cam0"] = trajectories["cam0"].transformed(unrefused.corrections["cam0"])
    assert alignment_error(alone) > report.error_before_m
    # Then nothing is applied: every sensor keeps its pose, and the report lists them all.
    assert report.corrections == {}
    assert set(report.refused) == set(unrefused.corrections)
    assert report.error_after_m == report.error_before_m
    for sid, pose in base.items():
        np.testing.assert_allclose(report.calibration.pose(sid), pose)


def test_one_far_off_board_view_does_not_hide_a_wrong_pose():
    """A sensor's board evidence is the median of its views' RMS: one view 40 px off (which
    the solve's Huber loss leaves off) neither makes the sensor look badly placed nor makes
    a 3 cm wrong pose look small beside it."""
    session = synthetic_session(3, 24, floor_views=1, seed=4)
    calibrator = NetworkCalibrator(session.board, session.intrinsics)
    shared = 0
    for corners, floor in zip(session.corners, session.floor, strict=True):
        if not floor and {"cam1", "cam2"} <= set(corners):
            shared += 1
            if shared == 6:  # a view of a pair well linked by others: the solve keeps it off
                corners = {**corners, "cam2": corners["cam2"] + 40.0}
        calibrator.add(corners, floor=floor)
    assert shared > 6
    result = calibrator.solve()
    assert result.sensors["cam2"].rms_px > 5.0  # over all its corners, the view shows
    poses = result.world_T_camera
    right = board_rms_px(calibrator, result, session.board, poses)
    assert set(right) == set(poses)
    assert right["cam2"] < 1.0  # the spoiled view's 40 px do not count
    wrong = board_rms_px(calibrator, result, session.board, {"cam2": _moved(poses["cam2"], 0.03)})
    assert wrong["cam2"] > 2.0 * right["cam2"]
