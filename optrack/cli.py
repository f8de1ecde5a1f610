"""The ``optrack`` command line.

Every subcommand of the measurement contract (docs/architecture.md) is
declared here with its options; its handler lives with the part it runs and
is imported only when the command runs. With ``--json`` a command prints one
JSON object on stdout; progress and messages go to stderr.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from optrack import __version__
from optrack.errors import UserError

EXIT_OK = 0
EXIT_ERROR = 1
EXIT_USAGE = 2


class CommandError(UserError):
    """A failure the user can fix; its message is one sentence."""


def emit_json(payload: dict[str, Any]) -> None:
    sys.stdout.write(json.dumps(payload) + "\n")
    sys.stdout.flush()


def info(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


Handler = Callable[[argparse.Namespace], int]


def resolve(handler: str | Handler) -> Handler:
    """A handler given as ``"package.module:function"`` is imported only when its
    command runs, so that ``optrack --help`` stays fast."""
    if not isinstance(handler, str):
        return handler
    module_name, _, function = handler.partition(":")
    return getattr(importlib.import_module(module_name), function)


# ------------------------------------------------------------------ commands


def cmd_cloud(args: argparse.Namespace) -> int:
    """Back-project a depth image (or a recording's frame) into a .pcd file."""
    import numpy as np

    from optrack.geometry import backproject
    from optrack.io.images import read_color_image, read_depth_image
    from optrack.io.pcd import write_pcd
    from optrack.recording import Recording, is_recording
    from optrack.types import Intrinsics, RGBDFrame

    source = Path(args.input)
    if not args.out.lower().endswith(".pcd"):
        raise CommandError(f"--out {args.out} must name a .pcd file.")
    if is_recording(source):
        recording = Recording(source)
        sensor = args.sensor or recording.sensor_ids[0]
        frame = recording.frame(sensor, args.frame)
        if args.intrinsics:
            frame.intrinsics = Intrinsics.parse(args.intrinsics, *frame.depth.shape[::-1])
        if args.depth_scale is not None:
            frame.depth_scale = args.depth_scale
    else:
        if source.is_dir():
            raise CommandError(
                f"{source} is a directory but not an optrack recording (no manifest.yaml); "
                "give a depth image or a recording."
            )
        if not args.intrinsics:
            raise CommandError(
                "a depth image needs --intrinsics fx,fy,cx,cy (pixels), e.g. --intrinsics 525,525,320,240."
            )
        depth = read_depth_image(source)
        height, width = depth.shape
        intrinsics = Intrinsics.parse(args.intrinsics, width, height)
        scale = args.depth_scale if args.depth_scale is not None else 0.001
        if depth.dtype != np.uint16:
            scale = 1.0  # float images are metres
        color = read_color_image(args.color) if args.color else None
        if color is not None and color.shape[:2] != depth.shape:
            raise CommandError(
                f"colour image {args.color} is {color.shape[1]}x{color.shape[0]} but the depth "
                f"image is {width}x{height}; give a registered colour image of the same size."
            )
        frame = RGBDFrame(depth, intrinsics, sensor_id=source.stem, depth_scale=scale, color=color)
    cloud = backproject(frame.depth_m(), frame.intrinsics)
    colors = (
        frame.color
        if frame.color is not None and frame.color.shape[:2] == frame.depth.shape
        else None
    )
    write_pcd(args.out, cloud, colors)
    valid = int(np.count_nonzero(np.isfinite(cloud[..., 2])))
    height, width = frame.depth.shape
    if args.json:
        emit_json(
            {
                "out": args.out,
                "points": valid,
                "width": width,
                "height": height,
                "color": colors is not None,
            }
        )
    else:
        info(f"wrote {args.out}: {width}x{height} organised cloud, {valid} valid points.")
    return EXIT_OK


# Each benchmark is a handler "module:function" taking the parsed arguments.
BENCHES: dict[str, str] = {
    "sim": "optrack.sim.bench:cmd_bench_sim",
    "detection": "optrack.detection.bench:bench_detection",
    "tracking": "optrack.tracking.bench:cmd_bench_tracking",
    "calibration": "optrack.calibration.bench:bench_calibration",
    "e2e": "optrack.runtime.bench:bench_e2e",
}


def cmd_bench(args: argparse.Namespace) -> int:
    return int(resolve(BENCHES[args.what])(args) or 0)


def cmd_gui(args: argparse.Namespace) -> int:
    from app.main import main as gui_main

    argv: list[str] = []
    if args.screenshot:
        argv += ["--screenshot", args.screenshot]
    if args.quit_after is not None:
        argv += ["--quit-after", str(args.quit_after)]
    for option in ("config", "connect", "site"):
        if getattr(args, option, None):
            argv += [f"--{option}", getattr(args, option)]
    for flag in ("join", "no_site"):
        if getattr(args, flag, False):
            argv.append("--" + flag.replace("_", "-"))
    return gui_main(argv)


# ------------------------------------------------------------------- parser


def _add_json(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--json", action="store_true", help="print one JSON object on stdout (logs go to stderr)"
    )


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="optrack",
        description="People tracking in networks of RGB-D cameras.",
        epilog="Each command has its own --help. Figures come from commands with --json.",
    )
    parser.add_argument("--version", action="version", version=f"optrack {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND")

    def command(
        name: str, help: str, handler: Callable[[argparse.Namespace], int], parent: Any = commands
    ) -> argparse.ArgumentParser:
        sub = parent.add_parser(name, help=help, description=help)
        sub.set_defaults(handler=handler)
        return sub

    # sim
    p = command(
        "sim",
        "Simulate a venue with walking people and write a recording with ground truth.",
        "optrack.sim.cli:cmd_sim",
    )
    p.add_argument("scenario", help="scenario name or YAML file (resources/scenarios)")
    p.add_argument("--out", required=True, help="output recording directory (must be new)")
    p.add_argument(
        "--seed", type=int, default=0, help="random seed (the same seed gives the same recording)"
    )
    p.add_argument("--seconds", type=float, help="simulated duration, s (default: the scenario's)")
    p.add_argument("--sensors", type=int, help="number of sensors (default: the scenario's)")
    p.add_argument("--people", type=int, help="number of people (default: the scenario's)")
    p.add_argument(
        "--sensor-model",
        choices=("kinect2", "kinect1", "sr4500", "stereo"),
        help="sensor model for every sensor",
    )
    p.add_argument("--config", help="YAML parameter file (sim_* stages, e.g. sim_kinect1)")
    _add_json(p)

    # detect
    p = command(
        "detect",
        "Detect people in a point cloud, a recording or a live sensor.",
        "optrack.detection.cli:cmd_detect",
    )
    p.add_argument("input", help=".pcd file, depth image, recording directory or sensor URI")
    p.add_argument("--intrinsics", help="fx,fy,cx,cy in pixels (needed for a bare .pcd)")
    floor = p.add_mutually_exclusive_group()
    floor.add_argument(
        "--ground", help="ground plane a,b,c,d in the camera frame (default: automatic)"
    )
    floor.add_argument(
        "--ground-points",
        help="three floor points 'x1,y1,z1;x2,y2,z2;x3,y3,z3' (metres, camera frame)",
    )
    floor.add_argument(
        "--ground-pixels",
        help="three floor pixels 'u1,v1;u2,v2;u3,v3' of the organised .pcd or depth image",
    )
    floor.add_argument(
        "--ground-pick",
        help="x,y,z (metres, camera frame): the segmented plane nearest this point is the floor",
    )
    p.add_argument("--config", help="YAML parameter file")
    p.add_argument(
        "--sensor-model",
        choices=("kinect1", "kinect2", "sr4500", "stereo", "pcl", "default"),
        help="parameter defaults of this sensor model (default: the recording's; PCL's for a .pcd)",
    )
    p.add_argument("--preset", choices=("children",), help="parameter preset on top of the model")
    p.add_argument("--sensor", help="recording: only this sensor (default: all)")
    p.add_argument("--frames", type=int, help="recording or sensor: stop after this many frames")
    p.add_argument("--color", help="depth image: registered colour image of the same size")
    p.add_argument(
        "--depth-scale",
        type=float,
        help="depth image: metres per unit (default 0.001: millimetres)",
    )
    _add_json(p)

    # eval
    p = command(
        "eval",
        "Track a recording and score it against its ground truth (CLEAR MOT).",
        "optrack.evaluation.run:cmd_eval",
    )
    p.add_argument("recording", help="recording directory with ground truth")
    p.add_argument("--calibration", help="calibration file (default: the recording's true poses)")
    p.add_argument("--config", help="YAML parameter file")
    p.add_argument(
        "--appearance",
        choices=("auto", "on", "off"),
        help="appearance recovery of identities (default: the config's, auto: on for one sensor)",
    )
    _add_json(p)

    # calibrate
    p = commands.add_parser(
        "calibrate",
        help="Calibrate intrinsics, stereo pairs and the camera network.",
        description="Calibrate intrinsics, stereo pairs and the camera network.",
    )
    p.set_defaults(handler=lambda a: _usage(p))
    calibrate = p.add_subparsers(dest="calibrate_command", metavar="STEP")
    q = command(
        "intrinsics",
        "Intrinsics of one camera from chessboard images.",
        "optrack.calibration.commands:cmd_intrinsics",
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
    _add_json(q)
    q = command(
        "stereo",
        "Relative pose of a stereo pair from chessboard image pairs.",
        "optrack.calibration.commands:cmd_stereo",
        calibrate,
    )
    q.add_argument("--board", required=True, help="inner corners, columns x rows, e.g. 9x6")
    q.add_argument("--square", type=float, required=True, help="square size, m")
    q.add_argument("--left", nargs="+", required=True, help="left images")
    q.add_argument("--right", nargs="+", required=True, help="right images (same order)")
    _add_json(q)
    q = command(
        "network",
        "Calibrate every sensor of a recording (checkerboard, ground).",
        "optrack.calibration.commands:cmd_network",
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
    _add_json(q)
    q = command(
        "refine",
        "Refine a calibration from one person walking.",
        "optrack.calibration.commands:cmd_refine",
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
    _add_json(q)
    q = command(
        "ground",
        "Set the world frame: boards lying on the floor, or points of known coordinates.",
        "optrack.calibration.commands:cmd_ground",
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
    _add_json(q)
    q = command(
        "board",
        "Write a printable checkerboard (PDF or PNG) with its size printed on it.",
        "optrack.calibration.commands:cmd_board",
        calibrate,
    )
    q.add_argument("--board", default="9x6", help="inner corners, columns x rows (default 9x6)")
    q.add_argument("--square", type=float, default=0.1, help="square size, m (default 0.1)")
    q.add_argument("--out", required=True, help="output .pdf or .png")
    q.add_argument("--paper", default="fit", help="fit, a4, a3, a2, a1, a0 or letter")
    q.add_argument("--dpi", type=int, default=300, help="PNG resolution (default 300)")
    _add_json(q)
    q = command(
        "export",
        "Export a calibration as OpenPTrack's camera_poses.yaml or ROS static transforms.",
        "optrack.calibration.commands:cmd_export",
        calibrate,
    )
    q.add_argument("calibration", help="calibration file")
    q.add_argument("--format", required=True, choices=("openptrack", "ros"), help="what to write")
    q.add_argument("--out", required=True, help="file to write")
    q.add_argument("--parent", default="world", help="ROS parent frame (default world)")
    _add_json(q)
    q = command(
        "truth",
        "Write a recording's true sensor poses as a calibration file (optionally perturbed).",
        "optrack.calibration.commands:cmd_truth",
        calibrate,
    )
    q.add_argument("recording", help="simulated recording (it knows its sensors' poses)")
    q.add_argument("--out", required=True, help="calibration file to write")
    q.add_argument("--perturb", metavar="M,DEG", help="move each sensor M metres, turn it DEG")
    q.add_argument("--seed", type=int, default=0, help="seed of the perturbation's directions")
    _add_json(q)
    q = command(
        "live",
        "The calibration wizard without a window: extrinsics, floor, refinement on a running site.",
        "optrack.calibration.live:cmd_live",
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
    _add_json(q)

    # bench
    p = command(
        "bench",
        "Measure speed, memory and accuracy of one part of optrack.",
        cmd_bench,
    )
    p.add_argument(
        "what",
        choices=tuple(BENCHES),
        help="what to measure",
    )
    _add_json(p)

    # run
    p = command(
        "run",
        "Run the embedded site (sensors, detectors, tracker) and stream to the outputs.",
        "optrack.runtime.cli:cmd_run",
    )
    p.add_argument("--headless", action="store_true", help="no window")
    p.add_argument("--seconds", type=float, help="stop after this many seconds")
    p.add_argument(
        "--udp",
        action="append",
        metavar="HOST:PORT",
        help="UDP JSON destination (default 127.0.0.1:21234)",
    )
    p.add_argument("--config", help="YAML site configuration")
    p.add_argument(
        "--recording",
        metavar="PATH",
        help="play this recording through the pipeline (its sensors as the detector nodes)",
    )
    p.add_argument(
        "--speed", type=float, default=1.0, help="--recording: times the recorded pace (0.25-4)"
    )
    p.add_argument(
        "--loop", action="store_true", help="--recording: play it again at its end (else stop)"
    )

    # gui
    p = command("gui", "Open the operator application.", cmd_gui)
    p.add_argument(
        "--screenshot", metavar="PNG", help="save a screenshot of the window to this file"
    )
    p.add_argument("--quit-after", type=float, metavar="S", help="close the window after S seconds")
    p.add_argument("--config", metavar="FILE", help="YAML configuration of the site")
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--join", action="store_true", help="join the site already running on this computer"
    )
    where.add_argument(
        "--connect", metavar="ENDPOINTS", help="join a site on the network (tcp/HOST:PORT,...)"
    )
    where.add_argument("--no-site", action="store_true", help="open without a site")
    p.add_argument("--site", help="site name (default: the configuration's site.name)")

    # sensors / record
    p = command(
        "sensors",
        "List the depth cameras attached to this computer.",
        "optrack.sensors.cli:cmd_sensors",
    )
    p.add_argument(
        "--udev-rules",
        action="store_true",
        help="print the udev rules that let users open the cameras (Linux) and exit",
    )
    _add_json(p)
    p = command("record", "Record live sensors into a recording.", "optrack.sensors.cli:cmd_record")
    p.add_argument(
        "--sensor",
        action="append",
        required=True,
        metavar="URI",
        help="sensor URI (repeat for several)",
    )
    p.add_argument("--seconds", type=float, required=True, help="how long to record, s")
    p.add_argument("--out", required=True, help="output recording directory (must be new)")
    _add_json(p)

    # cloud
    p = command(
        "cloud",
        "Back-project a depth image or a recording frame into a .pcd point cloud.",
        cmd_cloud,
    )
    p.add_argument("input", help="16-bit depth image (TIFF/PNG) or recording directory")
    p.add_argument(
        "--intrinsics",
        help="fx,fy,cx,cy in pixels (required for an image; a recording has its own)",
    )
    p.add_argument(
        "--depth-scale", type=float, help="metres per depth unit (default 0.001: millimetres)"
    )
    p.add_argument("--color", help="registered colour image for a depth image (same size)")
    p.add_argument("--sensor", help="recording: sensor id (default: the first)")
    p.add_argument(
        "--frame", type=int, default=0, help="recording: frame number of that sensor (default 0)"
    )
    p.add_argument("--out", required=True, help="output .pcd file")
    _add_json(p)

    # node
    p = commands.add_parser(
        "node",
        help="Run one node of a distributed site.",
        description="Run one node of a distributed site.",
    )
    p.set_defaults(handler=lambda a: _usage(p))
    node = p.add_subparsers(dest="node_command", metavar="NODE")
    q = command(
        "detect",
        "Detector node: capture one sensor, detect, publish detections.",
        "optrack.runtime.cli:cmd_node_detect",
        node,
    )
    q.add_argument("--sensor", required=True, metavar="URI", help="sensor URI")
    q.add_argument("--site", required=True, help="site name")
    q.add_argument("--config", help="YAML configuration")
    q = command(
        "track",
        "Tracker node: all detections in, tracks out.",
        "optrack.runtime.cli:cmd_node_track",
        node,
    )
    q.add_argument("--site", required=True, help="site name")
    q.add_argument("--config", help="YAML configuration")
    return parser


def _usage(parser: argparse.ArgumentParser) -> int:
    parser.print_help(sys.stderr)
    return EXIT_USAGE


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "handler", None) is None:
        parser.print_help(sys.stderr)
        return EXIT_USAGE
    names = [args.command] + [
        getattr(args, k) for k in ("calibrate_command", "node_command") if getattr(args, k, None)
    ]
    args.command_name = " ".join(names)
    started = time.perf_counter()
    try:
        return int(resolve(args.handler)(args) or 0)
    except KeyboardInterrupt:
        info(
            f"optrack {args.command_name}: interrupted after {time.perf_counter() - started:.1f} s."
        )
        return 130
    except UserError as error:
        info(f"optrack {args.command_name}: {error}")
        return EXIT_ERROR
    except OSError as error:
        target = f" {error.filename}" if error.filename else ""
        info(f"optrack {args.command_name}: cannot use{target}: {error.strerror or error}.")
        return EXIT_ERROR


if __name__ == "__main__":
    sys.exit(main())
