"""The live calibration's refinement: Algorithm 1 from the walker the nodes detected,
checked against the checkerboard.

The checkerboard's views are millimetre evidence, a walker's detections
centimetre evidence: a sensor's walk correction is applied only while that
sensor's checkerboard views still agree with it (their reprojection RMS, the
median over its views, grows by at most
``calibration_live.refinement_board_growth``); else the sensor keeps the
checkerboard's pose and the report says so (``refused``). When the corrections
left make the sensors disagree more than none would, none is applied.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence

import msgspec
import numpy as np

from optrack.calibration.board import Checkerboard
from optrack.calibration.files import new_calibration_id, now_iso
from optrack.calibration.network import NetworkCalibrator, NetworkResult, pinhole_residuals_px
from optrack.calibration.refinement import (
    REFINEMENT_PARAMS,
    Trajectory,
    alignment_error,
    refine_from_trajectories,
    walker_trajectory,
)
from optrack.geometry import invert
from optrack.net.messages import DetectionsMessage
from optrack.types import NetworkCalibration

__all__ = ["RefinementReport", "board_rms_px", "refine_walk", "walk_trajectories"]


@dataclasses.dataclass
class RefinementReport:
    """What a live refinement found."""

    calibration: NetworkCalibration  # the refined calibration (not yet saved or published)
    error_before_m: float  # mean ground-plane distance between sensors' detections (Fig. 19)
    error_after_m: float
    trajectories_before: dict[str, np.ndarray]  # sensor -> Nx3 world positions
    trajectories_after: dict[str, np.ndarray]
    # per-sensor 4x4 corrections applied in world x-y-z, and sensors skipped
    corrections: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    skipped: list[str] = dataclasses.field(default_factory=list)
    # sensors whose walk correction was not applied, with the reprojection RMS (px) their
    # checkerboard views would have had with it; every sensor's RMS without the walk's
    # correction and with it
    refused: dict[str, float] = dataclasses.field(default_factory=dict)
    board_rms_px: dict[str, float] = dataclasses.field(default_factory=dict)
    board_rms_refined_px: dict[str, float] = dataclasses.field(default_factory=dict)


def board_rms_px(
    calibrator: NetworkCalibrator,
    result: NetworkResult,
    board: Checkerboard,
    poses: Mapping[str, np.ndarray],
) -> dict[str, float]:
    """Per sensor, the median over its checkerboard views of each view's reprojection RMS
    (px, pinhole corners) in the solve ``result`` with the camera at ``poses[sensor]`` and
    every board where the solve put it: how far a pose is from what the board showed that
    sensor. The median, as one view the solve's Huber loss left 10-50 px off (seen on the
    four-sensor site: a camera's RMS over all corners 7.8 px) would make any correction
    look small beside it."""
    errors: dict[str, list[float]] = {}
    for instant in calibrator.instants:
        world_T_board = result.world_T_board.get(instant.index)
        if world_T_board is None:
            continue
        for sid in instant.added & set(poses):
            camera_T_board = invert(poses[sid]) @ world_T_board
            residual = pinhole_residuals_px(
                board.object_points,
                camera_T_board,
                calibrator.intrinsics[sid],
                instant.views[sid].pinhole,
            )
            errors.setdefault(sid, []).append(float(np.sqrt(np.mean(residual**2))))
    return {s: float(np.median(e)) for s, e in errors.items()}


def walk_trajectories(
    base: NetworkCalibration, batches: Mapping[str, Sequence[DetectionsMessage]]
) -> dict[str, Trajectory]:
    """Each calibrated sensor's detections of the walker, in the world of ``base``."""
    trajectories = {}
    for sid, messages in batches.items():
        if sid not in base.sensors:
            continue
        frames = ((m.batch.stamp, m.batch.detections) for m in messages)
        # the live walk's confidence floor: no partly seen body, no false detection
        trajectory, _ = walker_trajectory(frames, base.pose(sid), min_confidence=None)
        if trajectory is not None:
            trajectories[sid] = trajectory
    return trajectories


def refine_walk(
    base: NetworkCalibration,
    batches: Mapping[str, Sequence[DetectionsMessage]],
    board_rms: Callable[[dict[str, np.ndarray]], dict[str, float]],
    growth: float,
    progress: Callable[[float, str], None],
) -> RefinementReport:
    """Algorithm 1 (optrack/calibration/refinement.py) from the walker's per-sensor
    detections ``batches`` (camera-frame centroids moved into the world by ``base``; the
    most confident one per frame), starting from ``base``. ``board_rms(poses)``: each
    sensor's checkerboard reprojection RMS with those poses (:func:`board_rms_px`); a
    correction is refused when it grows that RMS by more than the fraction ``growth``."""
    progress(0.05, "collecting the walker's trajectories")
    trajectories = walk_trajectories(base, batches)
    progress(0.2, f"Algorithm 1 over {len(trajectories)} sensors")
    p = REFINEMENT_PARAMS.create()
    result = refine_from_trajectories(trajectories, p)
    board_before = board_rms({s: base.pose(s) for s in result.corrections})
    board_after = board_rms({s: c @ base.pose(s) for s, c in result.corrections.items()})
    corrections, refused = {}, {}
    for sid, correction in result.corrections.items():
        if sid in board_after and board_after[sid] > board_before[sid] * (1.0 + growth):
            refused[sid] = board_after[sid]
        else:
            corrections[sid] = correction
    after = {
        s: tr.transformed(corrections[s]) if s in corrections else tr
        for s, tr in trajectories.items()
    }
    error_after = result.error_after_m
    if refused:
        moved = {s: tr for s, tr in after.items() if s in result.corrections}
        error_after = alignment_error(moved, float(p.max_gap))
    if error_after > result.error_before_m:
        # The corrections left (the others refused) make the sensors disagree more than
        # none: every sensor keeps the checkerboard's pose.
        refused.update({s: board_after.get(s, math.nan) for s in corrections})
        corrections, after, error_after = {}, dict(trajectories), result.error_before_m
    refined = base
    for sid, correction in corrections.items():
        refined = refined.with_pose(sid, correction @ base.pose(sid))
    refined = msgspec.structs.replace(refined, notes=new_calibration_id(), created=now_iso())
    return RefinementReport(
        calibration=refined,
        error_before_m=result.error_before_m,
        error_after_m=error_after,
        trajectories_before={s: tr.xyz.copy() for s, tr in trajectories.items()},
        trajectories_after={s: tr.xyz.copy() for s, tr in after.items()},
        corrections={s: c.copy() for s, c in corrections.items()},
        skipped=list(result.skipped),
        refused=refused,
        board_rms_px=board_before,
        board_rms_refined_px=board_after,
    )
