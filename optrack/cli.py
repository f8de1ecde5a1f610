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

    from optrack.bench import cli as bench_cli
    from optrack.calibration import cli as calibration_cli
    from optrack.detection import cli as detection_cli
    from optrack.evaluation import cli as evaluation_cli
    from optrack.io import cli as io_cli
    from optrack.runtime import cli as runtime_cli
    from optrack.sensors import cli as sensors_cli
    from optrack.sim import cli as sim_cli

    def command(
        name: str, help: str, handler: Callable[[argparse.Namespace], int], parent: Any = commands
    ) -> argparse.ArgumentParser:
        sub = parent.add_parser(name, help=help, description=help)
        sub.set_defaults(handler=handler)
        return sub

    sim_cli.add_commands(commands, command)

    detection_cli.add_commands(commands, command)

    evaluation_cli.add_commands(commands, command)

    calibration_cli.add_commands(commands, command)

    bench_cli.add_commands(commands, command)

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
