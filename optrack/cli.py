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
from importlib.metadata import entry_points
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


# ------------------------------------------------------------------- parser


def add_json(parser: argparse.ArgumentParser) -> None:
    """The --json flag every measuring command has."""
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

    from optrack.detection import cli as detection_cli
    from optrack.io import cli as io_cli
    from optrack.runtime import cli as runtime_cli
    from optrack.sensors import cli as sensors_cli

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
    add_json(p)

    detection_cli.add_commands(commands, command)

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
    add_json(p)

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
    add_json(q)
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
    add_json(q)
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
    add_json(q)
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
    add_json(q)
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
    add_json(q)
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
    add_json(q)
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
    add_json(q)
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
    add_json(q)
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
    add_json(q)

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
    add_json(p)

    runtime_cli.add_commands(commands, command)

    # commands of the packages above the command line (the application's gui), which
    # register themselves through the "optrack.commands" entry point group
    for entry in entry_points(group="optrack.commands"):
        entry.load()(commands, command)

    sensors_cli.add_commands(commands, command)

    io_cli.add_commands(commands, command)

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
