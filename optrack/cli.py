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


# Each package declares its own commands in its cli.py (``add_commands(commands, command)``),
# in the order `optrack --help` lists them; a command's handler is
# ``optrack.<package>.cli:cmd_<command words>``, imported only when the command runs.
COMMAND_MODULES = (
    "optrack.sim.cli",
    "optrack.detection.cli",
    "optrack.evaluation.cli",
    "optrack.calibration.cli",
    "optrack.bench.cli",
    "optrack.runtime.cli",
)
LATE_COMMAND_MODULES = ("optrack.sensors.cli", "optrack.io.cli")


def add_command(
    parent: Any, name: str, help: str, handler: str | Handler
) -> argparse.ArgumentParser:
    """A command (or a group's step) with its help and its handler."""
    sub = parent.add_parser(name, help=help, description=help)
    sub.set_defaults(handler=handler)
    return sub


def add_group(commands: Any, name: str, help: str, dest: str, metavar: str) -> Any:
    """A command made of steps (``optrack calibrate STEP``): alone it prints its usage."""
    group = commands.add_parser(name, help=help, description=help)
    group.set_defaults(handler=lambda _args: usage(group))
    return group.add_subparsers(dest=dest, metavar=metavar)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="optrack",
        description="People tracking in networks of RGB-D cameras.",
        epilog="Each command has its own --help. Figures come from commands with --json.",
    )
    parser.add_argument("--version", action="version", version=f"optrack {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND")

    def command(
        name: str, help: str, handler: str | Handler, parent: Any = commands
    ) -> argparse.ArgumentParser:
        return add_command(parent, name, help, handler)

    for module in COMMAND_MODULES:
        importlib.import_module(module).add_commands(commands, command)
    # the packages above the command line (the application's gui) register their
    # commands through the "optrack.commands" entry point group
    for entry in entry_points(group="optrack.commands"):
        entry.load()(commands, command)
    for module in LATE_COMMAND_MODULES:
        importlib.import_module(module).add_commands(commands, command)
    return parser


def usage(parser: argparse.ArgumentParser) -> int:
    """Print a command's usage (a group called without its step) and fail."""
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
