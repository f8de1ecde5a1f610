"""``optrack gui``: the operator application's command.

The ``optrack`` command line sits below the application and does not import
it: the application registers this command itself, through the
``optrack.commands`` entry point group (pyproject.toml), which
``optrack.cli.build_parser`` reads.
"""

from __future__ import annotations

import argparse
from typing import Any

__all__ = ["add_commands", "add_gui_options", "cmd_gui"]


def add_gui_options(parser: argparse.ArgumentParser) -> None:
    """The options of ``optrack gui`` (also those of ``python -m app.main``)."""
    parser.add_argument(
        "--screenshot", metavar="PNG", help="save a screenshot of the window to this file"
    )
    parser.add_argument(
        "--quit-after", type=float, metavar="S", help="close the window after S seconds"
    )
    parser.add_argument("--config", metavar="FILE", help="YAML configuration of the site")
    where = parser.add_mutually_exclusive_group()
    where.add_argument(
        "--join", action="store_true", help="join the site already running on this computer"
    )
    where.add_argument(
        "--connect", metavar="ENDPOINTS", help="join a site on the network (tcp/HOST:PORT,...)"
    )
    where.add_argument("--no-site", action="store_true", help="open without a site")
    parser.add_argument("--site", help="site name (default: the configuration's site.name)")


def cmd_gui(args: argparse.Namespace) -> int:
    """``optrack gui [--join | --connect ENDPOINTS | --no-site] [--config FILE] ...``."""
    from app.main import run

    return run(args)


def add_commands(commands: Any, command: Any) -> None:
    """Declare ``optrack gui`` on the ``optrack`` parser (see optrack/cli.py)."""
    add_gui_options(command("gui", "Open the operator application.", "app.cli:cmd_gui"))
