"""The world frame of a calibrated network: from boards lying on the floor, or from points
of known world coordinates.

Either way the result is ``new_world_T_world``, the rigid move that takes every camera's
pose from the calibration's present world frame to the new one; the cameras keep their
relative poses.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from optrack.calibration.board import Checkerboard
from optrack.calibration.files import CalibrationFile
from optrack.calibration.session import calibrate_recording
from optrack.errors import UserError
from optrack.geometry import Plane, invert, rotation_angle_deg
from optrack.params import Params

__all__ = ["GroundError", "floor_from_recording", "frame_change", "world_from_points"]


class GroundError(UserError):
    """A world frame that cannot be set as asked."""


# ------------------------------------------------------------------ points


def world_from_points(
    path: Path, calibration: CalibrationFile, recording: Any
) -> tuple[np.ndarray, float, int]:
    """new_world_T_world from points of known world coordinates (Kabsch, Open3D), its RMS
    residual (m) and the number of points.

    Each point: ``{sensor, world: [x, y, z]}`` and either ``camera: [x, y, z]`` (metres in
    that camera) or ``u, v`` (a pixel of the depth image; its depth is read from the
    recording's first frame of that sensor, or ``frame: N``).
    """
    measured, known = [], []
    frames: dict[tuple[str, int], Any] = {}
    for n, point in enumerate(_read_points(path), start=1):
        if not isinstance(point, dict) or "sensor" not in point or "world" not in point:
            raise GroundError(f"points file {path}: point {n} needs 'sensor' and 'world'.")
        sid = str(point["sensor"])
        calibration.require([sid], f"file for points file {path}")
        camera_xyz = _camera_point(path, n, point, recording, frames)
        pose = calibration.sensors[sid].pose
        measured.append(pose[:3, :3] @ camera_xyz + pose[:3, 3])
        known.append(_xyz(path, n, point, "world"))
    transform, rms = _fit_rigid(path, np.asarray(measured), np.asarray(known))
    return transform, rms, len(known)


def _read_points(path: Path) -> list[Any]:
    """The points listed in a YAML file (at least three)."""
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise GroundError(f"points file {path} does not exist; check the path.") from None
    except yaml.YAMLError:
        raise GroundError(f"points file {path} is not valid YAML.") from None
    points = data.get("points") if isinstance(data, dict) else data
    if not isinstance(points, list) or len(points) < 3:
        raise GroundError(
            f"points file {path} must list at least 3 points, each with sensor, world and "
            "camera (or u, v)."
        )
    return points


def _camera_point(
    path: Path, n: int, point: dict[str, Any], recording: Any, frames: dict[tuple[str, int], Any]
) -> np.ndarray:
    """Point ``n`` in its camera's frame (metres): as given, or back-projected from its
    pixel and the depth the recording measured there (frames read once, kept in
    ``frames``)."""
    if "camera" in point:
        return _xyz(path, n, point, "camera")
    if "u" not in point or "v" not in point:
        raise GroundError(f"points file {path}: point {n} needs 'camera' or 'u' and 'v'.")
    sid = str(point["sensor"])
    if recording is None:
        raise GroundError(
            f"points file {path}: point {n} is a pixel (u, v); give the RECORDING to "
            "read its depth from."
        )
    key = (sid, int(_number(path, n, point, "frame", 0, np.inf, default=0)))
    if key not in frames:
        frames[key] = recording.frame(*key)
    frame = frames[key]
    height, width = frame.depth.shape
    u = _number(path, n, point, "u", 0, width - 1)
    v = _number(path, n, point, "v", 0, height - 1)
    z = frame.depth_m()[int(round(v)), int(round(u))]
    if not np.isfinite(z):
        raise GroundError(
            f"points file {path}: point {n} (sensor {sid}, pixel {u:g},{v:g}) has no "
            "depth; click a point on a surface the sensor measures."
        )
    k = frame.intrinsics
    if k.has_distortion:
        import cv2

        x, y = cv2.undistortPoints(
            np.array([[[u, v]]], dtype=np.float64), k.K, k.dist_coeffs
        ).reshape(2)
    else:
        x, y = (u - k.cx) / k.fx, (v - k.cy) / k.fy
    return np.array([x * z, y * z, z])


def _xyz(path: Path, n: int, point: dict[str, Any], key: str) -> np.ndarray:
    """Point ``n``'s ``key`` as three finite numbers (metres)."""
    try:
        xyz = np.asarray(point[key], dtype=np.float64)
    except (TypeError, ValueError):
        xyz = np.zeros(0)
    if xyz.shape != (3,) or not np.all(np.isfinite(xyz)):
        raise GroundError(
            f"points file {path}: point {n}'s {key} must be three finite numbers x, y, z in "
            f"metres; got {point[key]!r}."
        )
    return xyz


def _number(
    path: Path,
    n: int,
    point: dict[str, Any],
    key: str,
    low: float,
    high: float,
    default: Any = None,
) -> float:
    """Point ``n``'s ``key``: a number from ``low`` to ``high`` (a pixel of the depth image
    from 0 to its width or height - 1)."""
    value = point.get(key, default)
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = np.nan
    if not low <= number <= high:
        span = f"from {low:g} to {high:g}" if np.isfinite(high) else f"of {low:g} or more"
        raise GroundError(
            f"points file {path}: point {n}'s {key} must be a number {span}; got {value!r}."
        )
    return number


def _fit_rigid(path: Path, measured: np.ndarray, known: np.ndarray) -> tuple[np.ndarray, float]:
    """The rigid transform taking ``measured`` points (Nx3) onto ``known`` ones (Kabsch,
    Open3D) and its RMS residual, m."""
    import open3d as o3d

    centred = known - known.mean(axis=0)
    if np.linalg.svd(centred, compute_uv=False)[1] < 1e-3:
        raise GroundError(
            f"points file {path}: the points are (nearly) on one line; use points that span a plane."
        )
    pairs = np.repeat(np.arange(len(known))[:, None], 2, axis=1).astype(np.int32)
    transform = np.asarray(
        o3d.pipelines.registration.TransformationEstimationPointToPoint().compute_transformation(
            o3d.geometry.PointCloud(o3d.utility.Vector3dVector(measured)),
            o3d.geometry.PointCloud(o3d.utility.Vector3dVector(known)),
            o3d.utility.Vector2iVector(pairs),
        )
    )
    moved = measured @ transform[:3, :3].T + transform[:3, 3]
    return transform, float(np.sqrt(np.mean(np.sum((moved - known) ** 2, axis=1))))


# ------------------------------------------------------------------- floor


def floor_from_recording(
    recording: Any,
    calibration: CalibrationFile,
    board: Checkerboard,
    *,
    floor: str,
    network_params: Params,
    progress: Callable[[str], None] | None = None,
    where: str = "",
) -> tuple[np.ndarray, dict[str, Any]]:
    """new_world_T_world from boards lying on the floor in ``recording``, the cameras held
    at their calibrated poses; and the figures of that solve (``floor_views``, ``rms_px``).
    ``floor`` says which views lie on the floor (as ``calibrate_recording``'s, plus
    ``all``); ``where`` names the calibration in messages."""
    calibration.require(recording.sensor_ids, where)
    fixed = {sid: calibration.sensors[sid].pose for sid in recording.sensor_ids}
    session = calibrate_recording(
        recording,
        board,
        floor="after:0" if floor == "all" else floor,
        network_params=network_params,
        progress=progress,
        fixed_poses=fixed,
    )
    network = session.network
    if network.world != "floor":
        raise GroundError(
            f"no board was found lying on the floor in {recording.path}; lay it flat where "
            "cameras see it, or use --floor all if the recording only shows floor placements."
        )
    # The cameras were held at their poses in the old world, so any one of them gives
    # new_world_T_old_world = new_world_T_camera @ camera_T_old_world.
    sid = sorted(network.world_T_camera)[0]
    transform = network.world_T_camera[sid] @ invert(fixed[sid])
    return transform, {"floor_views": network.floor_views, "rms_px": network.rms_px}


def frame_change(new_world_T_world: np.ndarray) -> dict[str, float]:
    """How far a new world frame is from the old one: the floor's tilt, the whole turn and
    the shift."""
    old_up = Plane(0.0, 0.0, 1.0, 0.0)
    new_ground_in_old = old_up.transform(invert(new_world_T_world))
    return {
        "tilt_change_deg": new_ground_in_old.angle_deg(old_up),
        "rotation_change_deg": rotation_angle_deg(new_world_T_world),
        "translation_change_m": float(np.linalg.norm(new_world_T_world[:3, 3])),
    }
