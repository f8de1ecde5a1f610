"""``optrack calibrate ...``: intrinsics, stereo, network, ground, refine, board, export.

Each handler takes the parsed arguments and returns an exit code; with
``--json`` it prints one JSON object on stdout, and progress goes to stderr.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from optrack.calibration.board import Checkerboard
from optrack.calibration.files import (
    BoardEntry,
    CalibrationFile,
    CalibrationFileError,
    SensorEntry,
    load_calibration,
    new_calibration_id,
    now_iso,
    openptrack_camera_poses,
    ros_static_transforms,
    save_calibration,
)
from optrack.errors import UserError
from optrack.geometry import invert

__all__ = [
    "cmd_board",
    "cmd_export",
    "cmd_ground",
    "cmd_intrinsics",
    "cmd_network",
    "cmd_refine",
    "cmd_stereo",
    "cmd_truth",
]


class CalibrateError(UserError):
    """A calibration command that cannot run as asked."""


def _info(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def _emit(payload: Mapping[str, Any]) -> None:
    sys.stdout.write(json.dumps(payload) + "\n")
    sys.stdout.flush()


def _matrix_list(pose: np.ndarray) -> list[list[float]]:
    return [[float(v) for v in row] for row in np.asarray(pose)]


def _board(args: argparse.Namespace) -> Checkerboard:
    return Checkerboard.parse(args.board, args.square)


# ------------------------------------------------------------------ intrinsics


def cmd_intrinsics(args: argparse.Namespace) -> int:
    """Intrinsics of one camera from chessboard images."""
    from optrack.calibration.intrinsics import calibrate_intrinsics, corners_from_images
    from optrack.params import load_config

    board = _board(args)
    config = load_config(args.config) if getattr(args, "config", None) else {}
    found, size = corners_from_images(
        args.images, board, infrared=args.infrared, params=config.get("calibration_corners")
    )
    views = [c for c in found if c is not None]
    labels = [Path(p).name for p, c in zip(args.images, found, strict=True) if c is not None]
    missing = [Path(p).name for p, c in zip(args.images, found, strict=True) if c is None]
    if missing:
        _info(f"the {board.cols}x{board.rows} board was not found in: {', '.join(missing)}")
    result = calibrate_intrinsics(views, board, size, config.get("calibration_intrinsics"))
    payload = result.as_dict(labels)
    payload["not_found"] = missing
    if args.out:
        from optrack.io.files import atomic_write_text

        k = result.intrinsics
        atomic_write_text(
            args.out,
            yaml.safe_dump(
                {
                    "fx": k.fx,
                    "fy": k.fy,
                    "cx": k.cx,
                    "cy": k.cy,
                    "width": k.width,
                    "height": k.height,
                    "dist": list(k.dist),
                    "rms_px": result.rms,
                    "views": len(result.used),
                },
                sort_keys=False,
            ),
        )
        payload["out"] = args.out
    if args.json:
        _emit(payload)
    else:
        k = result.intrinsics
        _info(
            f"fx={k.fx:.2f} fy={k.fy:.2f} cx={k.cx:.2f} cy={k.cy:.2f} dist={[round(float(v), 5) for v in k.dist]} "
            f"RMS {result.rms:.3f} px over {len(result.used)} views"
            + (
                f"; rejected {', '.join(labels[i] for i in result.rejected)}"
                if result.rejected
                else ""
            )
            + f"; coverage {result.coverage.fraction:.0%} of the image"
        )
    return 0


# ---------------------------------------------------------------------- stereo


def stereo_calibrate(
    left: list[np.ndarray | None],
    right: list[np.ndarray | None],
    board: Checkerboard,
    size: tuple[int, int],
) -> dict[str, Any]:
    """Both cameras' intrinsics, then their relative pose through the network solver
    (intrinsics fixed). ``translation`` and ``rotation`` follow OpenCV's stereoCalibrate:
    they map left-camera points into the right camera (x_r = R x_l + T)."""
    from optrack.calibration.intrinsics import calibrate_intrinsics
    from optrack.calibration.network import NETWORK_PARAMS, NetworkCalibrator
    from optrack.geometry import rotation_angle_deg

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
        raise CalibrateError(
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
        "rotation": _matrix_list(right_T_left[:3, :3]),
        "left_T_right": _matrix_list(left_T_right),
        "rms": result.rms_px,
        "pairs": pairs,
        "left": intrinsics["left"].as_dict(),
        "right": intrinsics["right"].as_dict(),
    }


def cmd_stereo(args: argparse.Namespace) -> int:
    """Relative pose of a stereo pair from chessboard image pairs."""
    from optrack.calibration.intrinsics import corners_from_images

    board = _board(args)
    if len(args.left) != len(args.right):
        raise CalibrateError(
            f"--left lists {len(args.left)} images but --right {len(args.right)}; give the "
            "pairs in the same order."
        )
    left, size = corners_from_images(args.left, board)
    right, right_size = corners_from_images(args.right, board)
    if size != right_size:
        raise CalibrateError(
            f"left images are {size[0]}x{size[1]} but right ones {right_size[0]}x{right_size[1]}; "
            "a stereo pair needs both at one resolution."
        )
    payload = stereo_calibrate(left, right, board, size)
    if args.json:
        _emit(payload)
    else:
        _info(
            f"baseline {payload['baseline_m'] * 1000:.2f} mm, rotation {payload['rotation_deg']:.3f} "
            f"deg, RMS {payload['rms']:.3f} px over {payload['pairs']} pairs"
        )
    return 0


# --------------------------------------------------------------------- network


def _network_params(args: argparse.Namespace):  # noqa: ANN202 - Params
    from optrack.calibration.network import NETWORK_PARAMS

    overrides: dict[str, Any] = {}
    if getattr(args, "board_thickness", None) is not None:
        overrides["board_thickness"] = args.board_thickness
    return NETWORK_PARAMS.create(overrides)


def _recording_board(args: argparse.Namespace, recording: Any) -> Checkerboard:
    from optrack.calibration.session import board_from_recording

    if args.board or args.square is not None:
        if not (args.board and args.square is not None):
            raise CalibrateError("give both --board CxR and --square M (or neither).")
        return _board(args)
    board = board_from_recording(recording)
    if board is None:
        raise CalibrateError(
            f"recording {recording.path} does not say which checkerboard was used; give "
            "--board CxR (inner corners) and --square M."
        )
    return board


def _truth_poses(recording: Any) -> dict[str, np.ndarray]:
    if not recording.has_ground_truth:
        return {}
    return {
        sid: np.asarray(info.world_T_camera, dtype=np.float64)
        for sid, info in recording.sensors.items()
        if info.world_T_camera is not None
    }


def _floor_truth(recording: Any, timeline: list[tuple[float, bool]]) -> dict[str, int]:
    """How many instants were wrongly taken for (or not taken for) the board on the floor,
    when the recording's ground truth has the board."""
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


def cmd_network(args: argparse.Namespace) -> int:
    """Calibrate every sensor of a recorded checkerboard session."""
    from optrack.calibration.quality import calibration_errors
    from optrack.calibration.session import calibrate_recording
    from optrack.recording import Recording

    recording = Recording(args.recording)
    board = _recording_board(args, recording)
    params = _network_params(args)
    session = calibrate_recording(
        recording, board, floor=args.floor, network_params=params, progress=_info
    )
    network = session.network
    sensors = {}
    for sid, pose in network.world_T_camera.items():
        status = network.sensors[sid]
        sensors[sid] = SensorEntry(
            world_T_camera=tuple(tuple(float(v) for v in row) for row in pose),  # type: ignore[arg-type]
            intrinsics=session.intrinsics[sid],
            model=recording.sensors[sid].model,
            image=session.image.get(sid, ""),
            views=status.used_views,
            reprojection_rms_px=status.rms_px,
        )
    if not sensors:
        raise CalibrateError("no sensor could be calibrated.")
    calibration = CalibrationFile(
        sensors=sensors,
        id=new_calibration_id(),
        created=now_iso(),
        board=BoardEntry(board.cols, board.rows, board.square, float(params.board_thickness)),
        world=network.world,
        quality={
            "reprojection_rms_px": network.rms_px,
            "instants": session.instants,
            "floor_views": network.floor_views,
            "ground": "floor" if network.world == "floor" else "none",
        },
        notes=f"from recording {recording.path}",
    )
    backup = save_calibration(args.out, calibration)
    if network.uncalibrated:
        _info(
            f"not calibrated (never shared a board view with a calibrated sensor): "
            f"{', '.join(network.uncalibrated)}"
        )
    if network.world != "floor":
        _info(
            "no board was seen lying on the floor, so the world frame is the camera "
            f"{network.root}'s; lay the board on the floor and run 'optrack calibrate ground'."
        )
    payload: dict[str, Any] = {
        "out": str(args.out),
        "backup": str(backup) if backup else None,
        "id": calibration.id,
        "world": network.world,
        "sensors": {
            sid: {
                "world_T_camera": _matrix_list(network.world_T_camera[sid]),
                "views": network.sensors[sid].used_views,
                "rms_px": network.sensors[sid].rms_px,
                "image": session.image.get(sid, ""),
            }
            for sid in sorted(network.world_T_camera)
        },
        "uncalibrated": network.uncalibrated,
        "rms_px": network.rms_px,
        "instants": session.instants,
        "floor_views": network.floor_views,
        "detections": session.detections,
        "solve_seconds": network.seconds,
    }
    payload.update(_floor_truth(recording, session.timeline))
    truth = _truth_poses(recording)
    if truth and network.world == "floor":
        errors = calibration_errors(network.world_T_camera, truth)
        payload.update(errors.as_dict())
    elif truth:
        errors = calibration_errors(network.world_T_camera, truth)
        payload.update(
            {k: v for k, v in errors.as_dict().items() if not k.startswith("ground_error")}
        )
    if args.json:
        _emit(payload)
    else:
        _info(
            f"wrote {args.out}: {len(sensors)} sensors, RMS {network.rms_px:.3f} px, "
            f"{network.floor_views} floor views, world: {network.world}"
        )
        if "max_position_error_m" in payload:
            _info(
                f"against the truth: position {payload['max_position_error_m'] * 100:.2f} cm, "
                f"rotation {payload['max_rotation_error_deg']:.3f} deg"
            )
    return 0


# ---------------------------------------------------------------------- ground


def _world_from_points(
    path: Path, calibration: CalibrationFile, recording: Any
) -> tuple[np.ndarray, float, int]:
    """new_world_T_world from points of known world coordinates (Kabsch, Open3D).

    Each point: ``{sensor, world: [x, y, z]}`` and either ``camera: [x, y, z]`` (metres in
    that camera) or ``u, v`` (a pixel of the depth image; its depth is read from the
    recording's first frame of that sensor, or ``frame: N``).
    """
    import open3d as o3d

    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise CalibrateError(f"points file {path} does not exist; check the path.") from None
    except yaml.YAMLError:
        raise CalibrateError(f"points file {path} is not valid YAML.") from None
    points = data.get("points") if isinstance(data, dict) else data
    if not isinstance(points, list) or len(points) < 3:
        raise CalibrateError(
            f"points file {path} must list at least 3 points, each with sensor, world and "
            "camera (or u, v)."
        )
    measured, known = [], []
    frames: dict[tuple[str, int], Any] = {}
    for n, point in enumerate(points, start=1):
        if not isinstance(point, dict) or "sensor" not in point or "world" not in point:
            raise CalibrateError(f"points file {path}: point {n} needs 'sensor' and 'world'.")
        sid = str(point["sensor"])
        calibration.require([sid], f"file for points file {path}")
        if "camera" in point:
            camera_xyz = np.asarray(point["camera"], dtype=np.float64)
        elif "u" in point and "v" in point:
            if recording is None:
                raise CalibrateError(
                    f"points file {path}: point {n} is a pixel (u, v); give the RECORDING to "
                    "read its depth from."
                )
            key = (sid, int(point.get("frame", 0)))
            if key not in frames:
                frames[key] = recording.frame(*key)
            frame = frames[key]
            u, v = float(point["u"]), float(point["v"])
            depth = frame.depth_m()
            z = depth[int(round(v)), int(round(u))]
            if not np.isfinite(z):
                raise CalibrateError(
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
            camera_xyz = np.array([x * z, y * z, z])
        else:
            raise CalibrateError(f"points file {path}: point {n} needs 'camera' or 'u' and 'v'.")
        pose = calibration.sensors[sid].pose
        measured.append(pose[:3, :3] @ camera_xyz + pose[:3, 3])
        known.append(np.asarray(point["world"], dtype=np.float64))
    measured_array, known_array = np.asarray(measured), np.asarray(known)
    centred = known_array - known_array.mean(axis=0)
    if np.linalg.svd(centred, compute_uv=False)[1] < 1e-3:
        raise CalibrateError(
            f"points file {path}: the points are (nearly) on one line; use points that span a plane."
        )
    pairs = np.repeat(np.arange(len(known_array))[:, None], 2, axis=1).astype(np.int32)
    transform = np.asarray(
        o3d.pipelines.registration.TransformationEstimationPointToPoint().compute_transformation(
            o3d.geometry.PointCloud(o3d.utility.Vector3dVector(measured_array)),
            o3d.geometry.PointCloud(o3d.utility.Vector3dVector(known_array)),
            o3d.utility.Vector2iVector(pairs),
        )
    )
    moved = measured_array @ transform[:3, :3].T + transform[:3, 3]
    rms = float(np.sqrt(np.mean(np.sum((moved - known_array) ** 2, axis=1))))
    return transform, rms, len(known_array)


def _floor_from_recording(
    args: argparse.Namespace, calibration: CalibrationFile, recording: Any
) -> tuple[np.ndarray, dict[str, Any]]:
    """new_world_T_world from boards lying on the floor, cameras held where they are."""
    from optrack.calibration.session import calibrate_recording

    if calibration.board is not None and not args.board:
        board = Checkerboard(
            calibration.board.cols, calibration.board.rows, calibration.board.square
        )
    else:
        board = _recording_board(args, recording)
    calibration.require(recording.sensor_ids, f"file {args.calibration}")
    fixed = {sid: calibration.sensors[sid].pose for sid in recording.sensor_ids}
    session = calibrate_recording(
        recording,
        board,
        floor="after:0" if args.floor == "all" else args.floor,
        network_params=_network_params(args),
        progress=_info,
        fixed_poses=fixed,
    )
    network = session.network
    if network.world != "floor":
        raise CalibrateError(
            f"no board was found lying on the floor in {recording.path}; lay it flat where "
            "cameras see it, or use --floor all if the recording only shows floor placements."
        )
    # The cameras were held at their poses in the old world, so any one of them gives
    # new_world_T_old_world = new_world_T_camera @ camera_T_old_world.
    sid = sorted(network.world_T_camera)[0]
    transform = network.world_T_camera[sid] @ invert(fixed[sid])
    return transform, {"floor_views": network.floor_views, "rms_px": network.rms_px}


def cmd_ground(args: argparse.Namespace) -> int:
    """Set the world frame: from boards on the floor in a recording, or from points of
    known world coordinates."""
    from optrack.geometry import Plane, rotation_angle_deg
    from optrack.recording import Recording

    calibration = load_calibration(args.calibration)
    recording = Recording(args.recording) if args.recording else None
    details: dict[str, Any]
    if args.points:
        transform, rms, count = _world_from_points(Path(args.points), calibration, recording)
        details = {"points": count, "points_rms_m": rms}
        world = "points"
    elif recording is not None:
        transform, details = _floor_from_recording(args, calibration, recording)
        world = "floor"
    else:
        raise CalibrateError(
            "give a RECORDING with the board lying on the floor, or --points FILE with points "
            "of known world coordinates."
        )
    poses = {sid: transform @ entry.pose for sid, entry in calibration.sensors.items()}
    updated = calibration.with_poses(
        poses,
        id=new_calibration_id(),
        created=now_iso(),
        world=world,
        quality={**calibration.quality, **details, "ground": world},
    )
    backup = save_calibration(args.out, updated)
    old_up = Plane(0.0, 0.0, 1.0, 0.0)
    new_ground_in_old = old_up.transform(invert(transform))
    payload = {
        "out": str(args.out),
        "backup": str(backup) if backup else None,
        "world": world,
        "tilt_change_deg": new_ground_in_old.angle_deg(old_up),
        "rotation_change_deg": rotation_angle_deg(transform),
        "translation_change_m": float(np.linalg.norm(transform[:3, 3])),
        **details,
    }
    if args.json:
        _emit(payload)
    else:
        _info(
            f"wrote {args.out}: world from the {world}; the floor tilted by "
            f"{payload['tilt_change_deg']:.3f} deg"
        )
    return 0


# ---------------------------------------------------------------------- refine


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
        raise CalibrateError(
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


def cmd_refine(args: argparse.Namespace) -> int:
    """Refine a calibration from one person walking (Algorithm 1)."""
    from optrack.calibration.quality import calibration_errors
    from optrack.calibration.refinement import REFINEMENT_PARAMS, refine_from_trajectories
    from optrack.recording import Recording

    recording = Recording(args.recording)
    calibration = load_calibration(args.calibration)
    calibration.require(recording.sensor_ids, f"file {args.calibration}")
    params = REFINEMENT_PARAMS.create({"dof": args.dof})
    trajectories, crowded = person_trajectories(recording, calibration, args.rate, _info)
    for sid, frames in sorted(crowded.items()):
        _info(
            f"{sid}: more than one person in {frames} frames; refinement wants exactly one "
            "person walking (the most confident detection was used)."
        )
    result = refine_from_trajectories(trajectories, params)
    poses, sensors = {}, dict(calibration.sensors)
    for sid, correction in result.corrections.items():
        entry = sensors[sid]
        previous = (
            np.asarray(entry.refinement, dtype=np.float64)
            if entry.refinement is not None
            else np.eye(4)
        )
        poses[sid] = correction @ entry.pose
        sensors[sid] = SensorEntry(
            world_T_camera=tuple(tuple(float(v) for v in row) for row in poses[sid]),  # type: ignore[arg-type]
            intrinsics=entry.intrinsics,
            model=entry.model,
            image=entry.image,
            refinement=tuple(tuple(float(v) for v in row) for row in correction @ previous),  # type: ignore[arg-type]
            views=entry.views,
            reprojection_rms_px=entry.reprojection_rms_px,
        )
    refined = CalibrationFile(
        sensors=sensors,
        id=new_calibration_id(),
        created=now_iso(),
        board=calibration.board,
        world=calibration.world,
        ground=calibration.ground,
        quality={
            **calibration.quality,
            "refinement_error_before_m": result.error_before_m,
            "refinement_error_after_m": result.error_after_m,
        },
        notes=f"refined from {calibration.id} with recording {recording.path}",
    )
    backup = save_calibration(args.out, refined)
    payload: dict[str, Any] = {
        "out": str(args.out),
        "backup": str(backup) if backup else None,
        "error_before_m": result.error_before_m,
        "error_after_m": result.error_after_m,
        "error_before_xyz_m": result.error_before_xyz_m,
        "error_after_xyz_m": result.error_after_xyz_m,
        "detections": {sid: len(tr.t) for sid, tr in trajectories.items()},
        "refined": sorted(result.corrections),
        "skipped": result.skipped,
        "corrections": {
            sid: {
                "translation_m": float(np.linalg.norm(c[:3, 3])),
                "matrix": _matrix_list(c),
            }
            for sid, c in result.corrections.items()
        },
    }
    truth = _truth_poses(recording)
    if truth:
        before = {sid: calibration.sensors[sid].pose for sid in result.corrections}
        after = {sid: poses[sid] for sid in result.corrections}
        payload["truth_before"] = calibration_errors(before, truth).as_dict()
        payload["truth_after"] = calibration_errors(after, truth).as_dict()
    if args.json:
        _emit(payload)
    else:
        _info(
            f"wrote {args.out}: mean distance between sensors' detections "
            f"{result.error_before_m * 100:.1f} cm -> {result.error_after_m * 100:.1f} cm"
        )
    return 0


# ----------------------------------------------------------------------- truth


def cmd_truth(args: argparse.Namespace) -> int:
    """Write a recording's true sensor poses as a calibration file, optionally perturbed
    (to measure refinement, or to track with a known calibration)."""
    from optrack.calibration.synthetic import perturb_poses
    from optrack.recording import Recording

    recording = Recording(args.recording)
    truth = {
        sid: np.asarray(info.world_T_camera, dtype=np.float64)
        for sid, info in recording.sensors.items()
        if info.world_T_camera is not None
    }
    if not truth:
        raise CalibrateError(
            f"recording {recording.path} does not know its sensors' poses; only simulated "
            "recordings (or ones recorded with a calibration) do."
        )
    translation = rotation = 0.0
    if args.perturb:
        try:
            translation, rotation = (float(v) for v in args.perturb.split(","))
        except ValueError:
            raise CalibrateError(
                f"--perturb must be METRES,DEGREES, e.g. 0.1,2; got '{args.perturb}'."
            ) from None
        truth = perturb_poses(truth, translation, rotation, seed=args.seed)
    sensors = {
        sid: SensorEntry(
            world_T_camera=tuple(tuple(float(v) for v in row) for row in pose),  # type: ignore[arg-type]
            intrinsics=recording.sensors[sid].intrinsics,
            model=recording.sensors[sid].model,
        )
        for sid, pose in truth.items()
    }
    calibration = CalibrationFile(
        sensors=sensors,
        id=new_calibration_id(),
        created=now_iso(),
        world="floor",
        quality={"perturbation_m": translation, "perturbation_deg": rotation},
        notes=f"true poses of recording {recording.path}"
        + (f", each moved {translation} m and turned {rotation} deg" if args.perturb else ""),
    )
    backup = save_calibration(args.out, calibration)
    if args.json:
        _emit(
            {
                "out": str(args.out),
                "backup": str(backup) if backup else None,
                "sensors": sorted(sensors),
            }
        )
    else:
        _info(f"wrote {args.out}: the true poses of {len(sensors)} sensors ({calibration.notes})")
    return 0


# ----------------------------------------------------------------------- board


def cmd_board(args: argparse.Namespace) -> int:
    """Write a printable checkerboard (PDF or PNG)."""
    from optrack.calibration.printable import board_label, save_printable_board

    board = _board(args)
    page = save_printable_board(args.out, board, args.paper, args.dpi)
    payload = {
        "out": str(args.out),
        "cols": board.cols,
        "rows": board.rows,
        "square": board.square,
        "page_mm": [round(page[0], 1), round(page[1], 1)],
        "label": board_label(board),
    }
    if args.json:
        _emit(payload)
    else:
        _info(f"wrote {args.out} ({page[0]:.0f} x {page[1]:.0f} mm): {board.describe()}")
    return 0


# ---------------------------------------------------------------------- export


def cmd_export(args: argparse.Namespace) -> int:
    """Export a calibration file as OpenPTrack's camera_poses.yaml or ROS static transforms."""
    from optrack.io.files import atomic_write_text

    calibration = load_calibration(args.calibration)
    if args.format == "openptrack":
        text = openptrack_camera_poses(calibration)
    elif args.format == "ros":
        text = ros_static_transforms(calibration, args.parent)
    else:  # argparse's choices keep this unreachable from the command line
        raise CalibrationFileError(f"unknown export format '{args.format}'.")
    atomic_write_text(args.out, text)
    if args.json:
        _emit({"out": str(args.out), "format": args.format, "sensors": sorted(calibration.sensors)})
    else:
        _info(f"wrote {args.out} ({args.format}, {len(calibration.sensors)} sensors)")
    return 0
