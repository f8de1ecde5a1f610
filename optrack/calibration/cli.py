"""``optrack calibrate ...``: intrinsics, stereo, network, refine, ground, board, export, truth.

Each handler takes the parsed arguments and returns an exit code; with
``--json`` it prints one JSON object on stdout, and progress goes to stderr.
The handlers read the arguments, call the package's maths (intrinsics.py,
stereo.py, session.py, ground.py, refinement.py, ...) and write the files;
:func:`add_commands` declares the whole ``calibrate`` command tree. Imports
of the maths stay inside the handlers, so that building the parser is quick.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any

from optrack.cli import CommandError, add_group, add_json, emit_json, info

if TYPE_CHECKING:
    import numpy as np

    from optrack.calibration.board import Checkerboard
    from optrack.calibration.files import CalibrationFile
    from optrack.params import Params

__all__ = [
    "add_commands",
    "cmd_calibrate_board",
    "cmd_calibrate_export",
    "cmd_calibrate_ground",
    "cmd_calibrate_intrinsics",
    "cmd_calibrate_network",
    "cmd_calibrate_refine",
    "cmd_calibrate_stereo",
    "cmd_calibrate_truth",
]


def _board(args: argparse.Namespace) -> Checkerboard:
    from optrack.calibration.board import Checkerboard

    return Checkerboard.parse(args.board, args.square)


def cmd_calibrate_intrinsics(args: argparse.Namespace) -> int:
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
        info(f"the {board.cols}x{board.rows} board was not found in: {', '.join(missing)}")
    result = calibrate_intrinsics(views, board, size, config.get("calibration_intrinsics"))
    payload = result.as_dict(labels)
    payload["not_found"] = missing
    if args.out:
        result.save(args.out)
        payload["out"] = args.out
    if args.json:
        emit_json(payload)
    else:
        info(result.describe(labels))
    return 0


def cmd_calibrate_stereo(args: argparse.Namespace) -> int:
    """Relative pose of a stereo pair from chessboard image pairs."""
    from optrack.calibration.intrinsics import corners_from_images
    from optrack.calibration.stereo import stereo_calibrate

    board = _board(args)
    if len(args.left) != len(args.right):
        raise CommandError(
            f"--left lists {len(args.left)} images but --right {len(args.right)}; give the "
            "pairs in the same order."
        )
    left, size = corners_from_images(args.left, board)
    right, right_size = corners_from_images(args.right, board)
    if size != right_size:
        raise CommandError(
            f"left images are {size[0]}x{size[1]} but right ones {right_size[0]}x{right_size[1]}; "
            "a stereo pair needs both at one resolution."
        )
    payload = stereo_calibrate(left, right, board, size)
    if args.json:
        emit_json(payload)
    else:
        info(
            f"baseline {payload['baseline_m'] * 1000:.2f} mm, rotation {payload['rotation_deg']:.3f} "
            f"deg, RMS {payload['rms']:.3f} px over {payload['pairs']} pairs"
        )
    return 0


def _network_params(args: argparse.Namespace) -> Params:
    from optrack.calibration.network import NETWORK_PARAMS

    thickness = getattr(args, "board_thickness", None)
    return NETWORK_PARAMS.create({} if thickness is None else {"board_thickness": thickness})


def _recording_board(args: argparse.Namespace, recording: Any) -> Checkerboard:
    from optrack.calibration.session import board_from_recording

    if args.board or args.square is not None:
        if not (args.board and args.square is not None):
            raise CommandError("give both --board CxR and --square M (or neither).")
        return _board(args)
    board = board_from_recording(recording)
    if board is None:
        raise CommandError(
            f"recording {recording.path} does not say which checkerboard was used; give "
            "--board CxR (inner corners) and --square M."
        )
    return board


def cmd_calibrate_network(args: argparse.Namespace) -> int:
    """Calibrate every sensor of a recorded checkerboard session."""
    from optrack.calibration.files import save_calibration, session_file
    from optrack.calibration.session import calibrate_recording
    from optrack.calibration.truth import floor_view_errors, truth_errors
    from optrack.recording import Recording

    recording = Recording(args.recording)
    board = _recording_board(args, recording)
    params = _network_params(args)
    session = calibrate_recording(
        recording, board, floor=args.floor, network_params=params, progress=info
    )
    network = session.network
    if not network.world_T_camera:
        raise CommandError("no sensor could be calibrated.")
    models = {sid: sensor.model for sid, sensor in recording.sensors.items()}
    calibration = session_file(
        session,
        models,
        thickness=float(params.board_thickness),
        notes=f"from recording {recording.path}",
    )
    backup = save_calibration(args.out, calibration)
    if network.uncalibrated:
        info(
            f"not calibrated (never shared a board view with a calibrated sensor): "
            f"{', '.join(network.uncalibrated)}"
        )
    if network.world != "floor":
        info(
            "no board was seen lying on the floor, so the world frame is the camera "
            f"{network.root}'s; lay the board on the floor and run 'optrack calibrate ground'."
        )
    payload = {
        "out": str(args.out),
        "backup": str(backup) if backup else None,
        "id": calibration.id,
        **network.as_dict(session.image),
        "instants": session.instants,
        "detections": session.detections,
    }
    payload.update(floor_view_errors(recording, session.timeline))
    payload.update(truth_errors(recording, network.world_T_camera, ground=network.world == "floor"))
    if args.json:
        emit_json(payload)
    else:
        info(
            f"wrote {args.out}: {len(calibration.sensors)} sensors, RMS {network.rms_px:.3f} px, "
            f"{network.floor_views} floor views, world: {network.world}"
        )
        if "max_position_error_m" in payload:
            info(
                f"against the truth: position {payload['max_position_error_m'] * 100:.2f} cm, "
                f"rotation {payload['max_rotation_error_deg']:.3f} deg"
            )
    return 0


def cmd_calibrate_ground(args: argparse.Namespace) -> int:
    """Set the world frame: from boards on the floor in a recording, or from points of
    known world coordinates."""
    from optrack.calibration.files import (
        load_calibration,
        new_calibration_id,
        now_iso,
        save_calibration,
    )
    from optrack.calibration.ground import frame_change, world_from_points
    from optrack.recording import Recording

    calibration = load_calibration(args.calibration)
    recording = Recording(args.recording) if args.recording else None
    details: dict[str, Any]
    if args.points:
        transform, rms, count = world_from_points(Path(args.points), calibration, recording)
        details = {"points": count, "points_rms_m": rms}
        world = "points"
    elif recording is not None:
        transform, details = _floor_from_recording(args, calibration, recording)
        world = "floor"
    else:
        raise CommandError(
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
    payload = {
        "out": str(args.out),
        "backup": str(backup) if backup else None,
        "world": world,
        **frame_change(transform),
        **details,
    }
    if args.json:
        emit_json(payload)
    else:
        info(
            f"wrote {args.out}: world from the {world}; the floor tilted by "
            f"{payload['tilt_change_deg']:.3f} deg"
        )
    return 0


def _floor_from_recording(
    args: argparse.Namespace, calibration: CalibrationFile, recording: Any
) -> tuple[np.ndarray, dict[str, Any]]:
    """new_world_T_world from boards lying on the floor: the calibration's board unless
    ``--board`` names one."""
    from optrack.calibration.board import Checkerboard
    from optrack.calibration.ground import floor_from_recording

    if (known := calibration.board) is not None and not args.board:
        board = Checkerboard(known.cols, known.rows, known.square)
    else:
        board = _recording_board(args, recording)
    return floor_from_recording(
        recording,
        calibration,
        board,
        floor=args.floor,
        network_params=_network_params(args),
        progress=info,
        where=f"file {args.calibration}",
    )


def cmd_calibrate_refine(args: argparse.Namespace) -> int:
    """Refine a calibration from one person walking (Algorithm 1)."""
    from optrack.calibration.files import (
        load_calibration,
        new_calibration_id,
        now_iso,
        save_calibration,
    )
    from optrack.calibration.refinement import (
        REFINEMENT_PARAMS,
        person_trajectories,
        refine_from_trajectories,
    )
    from optrack.calibration.truth import truth_errors
    from optrack.recording import Recording

    recording = Recording(args.recording)
    calibration = load_calibration(args.calibration)
    calibration.require(recording.sensor_ids, f"file {args.calibration}")
    params = REFINEMENT_PARAMS.create({"dof": args.dof})
    trajectories, crowded = person_trajectories(recording, calibration, args.rate, info)
    for sid, frames in sorted(crowded.items()):
        info(
            f"{sid}: more than one person in {frames} frames; refinement wants exactly one "
            "person walking (the most confident detection was used)."
        )
    result = refine_from_trajectories(trajectories, params)
    refined = calibration.with_corrections(
        result.corrections,
        id=new_calibration_id(),
        created=now_iso(),
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
        **result.as_dict(),
        "detections": {sid: len(tr.t) for sid, tr in trajectories.items()},
    }
    before = truth_errors(recording, {s: calibration.sensors[s].pose for s in result.corrections})
    if before:
        payload["truth_before"] = before
        payload["truth_after"] = truth_errors(
            recording, {s: refined.sensors[s].pose for s in result.corrections}
        )
    if args.json:
        emit_json(payload)
    else:
        info(
            f"wrote {args.out}: mean distance between sensors' detections "
            f"{result.error_before_m * 100:.1f} cm -> {result.error_after_m * 100:.1f} cm"
        )
    return 0


def cmd_calibrate_truth(args: argparse.Namespace) -> int:
    """Write a recording's true sensor poses as a calibration file, optionally perturbed
    (to measure refinement, or to track with a known calibration)."""
    from optrack.calibration.files import CalibrationFile, save_calibration
    from optrack.calibration.synthetic import perturb_poses
    from optrack.calibration.truth import recorded_poses
    from optrack.recording import Recording

    recording = Recording(args.recording)
    truth = recorded_poses(recording)
    if not truth:
        raise CommandError(
            f"recording {recording.path} does not know its sensors' poses; only simulated "
            "recordings (or ones recorded with a calibration) do."
        )
    translation = rotation = 0.0
    if args.perturb:
        try:
            translation, rotation = (float(v) for v in args.perturb.split(","))
        except ValueError:
            raise CommandError(
                f"--perturb must be METRES,DEGREES, e.g. 0.1,2; got '{args.perturb}'."
            ) from None
        truth = perturb_poses(truth, translation, rotation, seed=args.seed)
    calibration = CalibrationFile.of_poses(
        truth,
        recording.sensors,
        world="floor",
        quality={"perturbation_m": translation, "perturbation_deg": rotation},
        notes=f"true poses of recording {recording.path}"
        + (f", each moved {translation} m and turned {rotation} deg" if args.perturb else ""),
    )
    backup = save_calibration(args.out, calibration)
    if args.json:
        emit_json(
            {
                "out": str(args.out),
                "backup": str(backup) if backup else None,
                "sensors": sorted(calibration.sensors),
            }
        )
    else:
        info(
            f"wrote {args.out}: the true poses of {len(calibration.sensors)} sensors "
            f"({calibration.notes})"
        )
    return 0


def cmd_calibrate_board(args: argparse.Namespace) -> int:
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
        emit_json(payload)
    else:
        info(f"wrote {args.out} ({page[0]:.0f} x {page[1]:.0f} mm): {board.describe()}")
    return 0


def cmd_calibrate_export(args: argparse.Namespace) -> int:
    """Export a calibration file as OpenPTrack's camera_poses.yaml or ROS static transforms."""
    from optrack.calibration.files import (
        CalibrationFileError,
        load_calibration,
        openptrack_camera_poses,
        ros_static_transforms,
    )
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
        emit_json(
            {"out": str(args.out), "format": args.format, "sensors": sorted(calibration.sensors)}
        )
    else:
        info(f"wrote {args.out} ({args.format}, {len(calibration.sensors)} sensors)")
    return 0


def add_commands(commands: Any, command: Any) -> None:
    """Declare ``optrack calibrate`` and its steps on the ``optrack`` parser (see
    optrack/cli.py); each step's handler is named ``cmd_calibrate_<step>``."""
    calibrate = add_group(
        commands,
        "calibrate",
        "Calibrate intrinsics, stereo pairs and the camera network.",
        "calibrate_command",
        "STEP",
    )
    _add_image_steps(calibrate, command)
    _add_network_steps(calibrate, command)
    _add_file_steps(calibrate, command)
    _add_live_step(calibrate, command)


def _add_image_steps(calibrate: Any, command: Any) -> None:
    """The steps that read chessboard images: one camera's intrinsics, a stereo pair."""
    q = command(
        "intrinsics",
        "Intrinsics of one camera from chessboard images.",
        "optrack.calibration.cli:cmd_calibrate_intrinsics",
        calibrate,
    )
    q.add_argument("images", nargs="+", help="chessboard images")
    q.add_argument("--board", required=True, help="inner corners, columns x rows, e.g. 9x6")
    q.add_argument("--square", type=float, required=True, help="square size, m")
    q.add_argument(
        "--infrared", action="store_true", help="infrared images (equalised, upsampled if small)"
    )
    q.add_argument("--out", help="also write the intrinsics to this YAML file")
    q.add_argument(
        "--config", help="YAML parameter file (calibration_corners, calibration_intrinsics)"
    )
    add_json(q)
    q = command(
        "stereo",
        "Relative pose of a stereo pair from chessboard image pairs.",
        "optrack.calibration.cli:cmd_calibrate_stereo",
        calibrate,
    )
    q.add_argument("--board", required=True, help="inner corners, columns x rows, e.g. 9x6")
    q.add_argument("--square", type=float, required=True, help="square size, m")
    q.add_argument("--left", nargs="+", required=True, help="left images")
    q.add_argument("--right", nargs="+", required=True, help="right images (same order)")
    add_json(q)


def _add_network_steps(calibrate: Any, command: Any) -> None:
    """The steps that read recordings: the network, its refinement, its world frame."""
    q = command(
        "network",
        "Calibrate every sensor of a recording (checkerboard, ground).",
        "optrack.calibration.cli:cmd_calibrate_network",
        calibrate,
    )
    q.add_argument("recording", help="recording of the checkerboard session")
    q.add_argument("--out", required=True, help="calibration file to write")
    q.add_argument("--board", help="inner corners CxR (default: the recording's board)")
    q.add_argument("--square", type=float, help="square size, m (default: the recording's)")
    q.add_argument(
        "--board-thickness", type=float, help="board face above the floor when laid on it, m"
    )
    q.add_argument(
        "--floor",
        default="auto",
        help="which views lie on the floor: auto (depth test), none, after:SECONDS",
    )
    add_json(q)
    q = command(
        "refine",
        "Refine a calibration from one person walking.",
        "optrack.calibration.cli:cmd_calibrate_refine",
        calibrate,
    )
    q.add_argument("recording", help="recording of one person walking")
    q.add_argument("--calibration", required=True, help="calibration file to refine")
    q.add_argument("--out", required=True, help="refined calibration file to write")
    q.add_argument(
        "--rate", type=float, default=10.0, help="frames per second run through the detector"
    )
    q.add_argument(
        "--dof",
        choices=("full", "heading"),
        default="full",
        help="full: also level each camera's tilt (Algorithm 1); heading: keep the tilts",
    )
    add_json(q)
    q = command(
        "ground",
        "Set the world frame: boards lying on the floor, or points of known coordinates.",
        "optrack.calibration.cli:cmd_calibrate_ground",
        calibrate,
    )
    q.add_argument("recording", nargs="?", help="recording with the board on the floor")
    q.add_argument("--calibration", required=True, help="calibration file to update")
    q.add_argument("--out", required=True, help="calibration file to write")
    q.add_argument("--points", help="YAML file of points with known world coordinates")
    q.add_argument("--board", help="inner corners CxR (default: the calibration's board)")
    q.add_argument("--square", type=float, help="square size, m")
    q.add_argument(
        "--board-thickness", type=float, help="board face above the floor when laid on it, m"
    )
    q.add_argument("--floor", default="auto", help="views on the floor: auto, all, after:SECONDS")
    add_json(q)


def _add_file_steps(calibrate: Any, command: Any) -> None:
    """The steps that write files: a printable board, exports, a recording's true poses."""
    q = command(
        "board",
        "Write a printable checkerboard (PDF or PNG) with its size printed on it.",
        "optrack.calibration.cli:cmd_calibrate_board",
        calibrate,
    )
    q.add_argument("--board", default="9x6", help="inner corners, columns x rows (default 9x6)")
    q.add_argument("--square", type=float, default=0.1, help="square size, m (default 0.1)")
    q.add_argument("--out", required=True, help="output .pdf or .png")
    q.add_argument("--paper", default="fit", help="fit, a4, a3, a2, a1, a0 or letter")
    q.add_argument("--dpi", type=int, default=300, help="PNG resolution (default 300)")
    add_json(q)
    q = command(
        "export",
        "Export a calibration as OpenPTrack's camera_poses.yaml or ROS static transforms.",
        "optrack.calibration.cli:cmd_calibrate_export",
        calibrate,
    )
    q.add_argument("calibration", help="calibration file")
    q.add_argument("--format", required=True, choices=("openptrack", "ros"), help="what to write")
    q.add_argument("--out", required=True, help="file to write")
    q.add_argument("--parent", default="world", help="ROS parent frame (default world)")
    add_json(q)
    q = command(
        "truth",
        "Write a recording's true sensor poses as a calibration file (optionally perturbed).",
        "optrack.calibration.cli:cmd_calibrate_truth",
        calibrate,
    )
    q.add_argument("recording", help="simulated recording (it knows its sensors' poses)")
    q.add_argument("--out", required=True, help="calibration file to write")
    q.add_argument("--perturb", metavar="M,DEG", help="move each sensor M metres, turn it DEG")
    q.add_argument("--seed", type=int, default=0, help="seed of the perturbation's directions")
    add_json(q)


def _add_live_step(calibrate: Any, command: Any) -> None:
    """The calibration wizard without a window (its handler is the runtime's)."""
    q = command(
        "live",
        "The calibration wizard without a window: extrinsics, floor, refinement on a running site.",
        "optrack.runtime.cli:cmd_calibrate_live",
        calibrate,
    )
    q.add_argument("--site", help="site name (default: the config's site.name)")
    q.add_argument("--board", default="6x5", help="inner corners CxR (default 6x5)")
    q.add_argument("--square", type=float, default=0.2, help="square size, m (default 0.2)")
    q.add_argument("--out", required=True, help="calibration file to write")
    q.add_argument("--config", help="YAML parameter file (bus, calibration_live, ...)")
    q.add_argument(
        "--extrinsics-seconds", type=float, default=120.0, help="longest extrinsics phase, s"
    )
    q.add_argument(
        "--min-views", type=int, default=3, help="extrinsics end when every sensor has this many"
    )
    q.add_argument("--floor-seconds", type=float, default=60.0, help="longest floor phase, s")
    q.add_argument(
        "--floor-views", type=int, default=3, help="the floor phase ends at this many floor views"
    )
    q.add_argument(
        "--refine-seconds",
        type=float,
        default=0.0,
        help="seconds of one person walking for the refinement (0: no refinement)",
    )
    q.add_argument("--no-publish", action="store_true", help="save only; do not send to the nodes")
    add_json(q)
