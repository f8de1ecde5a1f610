"""``optrack eval RECORDING``: detect and track a recording, score it against its ground truth."""

from __future__ import annotations

import argparse
from typing import Any

from optrack.cli import EXIT_OK, add_json, emit_json, info

__all__ = ["add_commands", "cmd_eval"]


def cmd_eval(args: argparse.Namespace) -> int:
    """Score a recording with CLEAR MOT (:func:`optrack.evaluation.run.evaluate`)."""
    from optrack.evaluation.run import evaluate

    result, overall = evaluate(
        args.recording,
        calibration=args.calibration,
        config_file=args.config,
        appearance=getattr(args, "appearance", None),
        progress=not args.json,
    )
    if args.json:
        emit_json(result)
    else:
        info(
            f"{result['recording']}: MOTA {overall.mota:.3f}, MOTP {overall.motp:.3f} m, "
            f"{overall.idsw} ID switches, {overall.fp} false positives, {overall.fn} misses "
            f"over {overall.frames} frames ({result['fps']} frames/s)."
        )
        for sid, s in result["sensors"].items():
            info(f"  {sid}: MOTA {s['mota']:.3f}, {s['idsw']} ID switches")
    return EXIT_OK


def add_commands(commands: Any, command: Any) -> None:
    """Declare this package's commands on the ``optrack`` parser (see optrack/cli.py)."""
    p = command(
        "eval",
        "Track a recording and score it against its ground truth (CLEAR MOT).",
        "optrack.evaluation.cli:cmd_eval",
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
