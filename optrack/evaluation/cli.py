"""``optrack eval RECORDING``: detect and track a recording, score it against its ground truth."""

from __future__ import annotations

import argparse
from typing import Any

from optrack.cli import EXIT_OK, add_json, emit_json, info

__all__ = ["add_commands", "cmd_eval"]


def cmd_eval(args: argparse.Namespace) -> int:
    """Score a recording with CLEAR MOT (:func:`optrack.evaluation.run.evaluate`)."""
    from optrack.evaluation.run import evaluate

    skeleton = None
    if getattr(args, "skeleton", False):
        from optrack.evaluation.skeleton import evaluate_skeleton

        skeleton = evaluate_skeleton(
            args.recording, args.calibration, args.config, progress=not args.json
        )
    result, overall = evaluate(
        args.recording,
        calibration=args.calibration,
        config_file=args.config,
        appearance=getattr(args, "appearance", None),
        progress=not args.json,
    )
    if skeleton is not None:
        result["skeleton"] = skeleton
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
        if skeleton is not None:
            info(
                f"  skeleton: mean marker error {skeleton['mean_error_m']} m, "
                f"{skeleton['pct_under_0_20']} % under 0.2 m, {skeleton['lost_pct']} % lost, "
                f"{skeleton['fps']} person-frames/s"
            )
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
    p.add_argument(
        "--skeleton",
        action="store_true",
        help="also track each person's skeleton and score it against the joint truth",
    )
    add_json(p)
