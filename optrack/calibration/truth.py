"""What a recording's ground truth says about a calibration made from it.

Simulated recordings know their sensors' true poses and where the board
really was; recordings made with a calibration carry its poses too (without
claiming they are the truth).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from optrack.calibration.quality import calibration_errors

__all__ = ["floor_view_errors", "recorded_poses", "true_poses", "truth_errors"]


def recorded_poses(recording: Any) -> dict[str, np.ndarray]:
    """world_T_camera of every sensor whose recorded info has one."""
    return {
        sid: np.asarray(info.world_T_camera, dtype=np.float64)
        for sid, info in recording.sensors.items()
        if info.world_T_camera is not None
    }


def true_poses(recording: Any) -> dict[str, np.ndarray]:
    """The sensors' true poses, when the recording has ground truth (else none)."""
    return recorded_poses(recording) if recording.has_ground_truth else {}


def truth_errors(
    recording: Any, world_T_camera: dict[str, np.ndarray], *, ground: bool = True
) -> dict[str, Any]:
    """Poses against the recording's true ones (:func:`calibration_errors`' figures; none
    without ground truth); the ground's error only with ``ground`` (a world frame on the
    floor)."""
    truth = true_poses(recording)
    if not truth:
        return {}
    errors = calibration_errors(world_T_camera, truth).as_dict()
    if ground:
        return errors
    return {k: v for k, v in errors.items() if not k.startswith("ground_error")}


def floor_view_errors(recording: Any, timeline: list[tuple[float, bool]]) -> dict[str, int]:
    """How many instants of ``timeline`` ((time, taken for the board on the floor)) were
    wrongly taken for (or not taken for) the board on the floor, when the recording's
    ground truth has the board."""
    if not recording.has_ground_truth or not timeline:
        return {}
    truth = [(g.t, g.boards[0].on_floor) for g in recording.ground_truth() if g.boards]
    if not truth:
        return {}
    times = np.array([t for t, _ in truth])
    wrong_floor = missed_floor = 0
    for t, on_floor in timeline:
        actual = truth[int(np.argmin(np.abs(times - t)))][1]
        wrong_floor += int(on_floor and not actual)
        missed_floor += int(actual and not on_floor)
    return {"floor_views_wrong": wrong_floor, "floor_views_missed": missed_floor}
