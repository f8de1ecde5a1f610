"""Each sensor's detections of the one person walking through a recording: the input of
the refinement (``optrack calibrate refine``, :mod:`optrack.calibration.cli`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from optrack.calibration.files import CalibrationFile
from optrack.calibration.refinement import RefinementError

__all__ = ["person_trajectories"]


def person_trajectories(
    recording: Any,
    calibration: CalibrationFile,
    rate_hz: float,
    progress: Any = None,
) -> tuple[dict[str, Any], dict[str, int]]:
    """Each sensor's detections of the one person walking, in the calibration's world frame
    (camera-frame centroids moved by the sensor's world_T_camera); per sensor, the most
    confident detection of a frame. Returns (trajectories, frames with more than one person)."""
    try:
        from optrack.detection.params import detection_params
        from optrack.detection.pipeline import PeopleDetector
    except ImportError as error:
        raise RefinementError(
            f"the people detector is not available in this optrack ({error}); refinement needs it."
        ) from None
    from optrack.calibration.refinement import Trajectory

    times: dict[str, list[float]] = {}
    points: dict[str, list[np.ndarray]] = {}
    crowded: dict[str, int] = {}
    for sid in recording.sensor_ids:
        info = recording.sensors[sid]
        pose = calibration.sensors[sid].pose
        detector = PeopleDetector(detection_params(info.model), sensor_id=sid, world_T_camera=pose)
        last = -np.inf
        count = 0
        for entry in recording.index(sid):
            if entry.t - last < 1.0 / rate_hz - 1e-6:
                continue
            last = entry.t
            frame = recording.load(sid, entry)
            batch = detector.process(frame)
            found = [d for d in batch.detections if d.camera_xyz is not None]
            if len(found) > 1:
                crowded[sid] = crowded.get(sid, 0) + 1
            if not found:
                continue
            best = max(found, key=lambda d: d.confidence)
            xyz = np.asarray(best.camera_xyz, dtype=np.float64)
            times.setdefault(sid, []).append(entry.t)
            points.setdefault(sid, []).append(pose[:3, :3] @ xyz + pose[:3, 3])
            count += 1
        if progress:
            progress(f"{sid}: the person was detected in {count} frames")
    trajectories = {
        sid: Trajectory(np.asarray(times[sid]), np.asarray(points[sid])) for sid in times
    }
    return trajectories, crowded
