"""``optrack sim SCENARIO --out DIR``: simulate a venue into a recording with ground truth."""

from __future__ import annotations

import argparse
from typing import Any

from optrack.cli import add_json, emit_json, info

__all__ = ["add_commands", "cmd_sim"]


def cmd_sim(args: argparse.Namespace) -> int:
    """Simulate a venue into a new recording with ground truth."""
    from optrack.params import load_config
    from optrack.sim.recorder import ProgressBar, write_recording
    from optrack.sim.world import Simulation

    params = load_config(args.config) if getattr(args, "config", None) else None
    sim = Simulation(
        args.scenario,
        seed=args.seed,
        people=args.people,
        sensors=args.sensors,
        sensor_model=args.sensor_model,
        seconds=args.seconds,
        params=params,
        clips=args.clip,
    )
    bar = ProgressBar(
        f"sim {sim.scenario.name}", sum(sim.frame_count(k) for k in range(len(sim.sensors)))
    )
    try:
        counts = write_recording(
            sim,
            args.out,
            progress=lambda done, total: bar.update(done),
            params=params.get("recording") if params else None,
        )
    finally:
        bar.close()
    frames = sum(counts.values())
    if args.json:
        emit_json(
            {
                "frames": frames,
                "sensors": len(sim.sensors),
                "seconds": sim.seconds,
                "out": str(args.out),
                "scenario": sim.scenario.name,
                "seed": sim.seed,
                "people": len(sim.crowd.people),
                "sensor_models": sorted({s.model.name for s in sim.sensors}),
                "frames_per_sensor": counts,
            }
        )
    else:
        info(
            f"wrote {args.out}: {len(sim.sensors)} sensors, {frames} frames, "
            f"{sim.seconds:g} s of scenario '{sim.scenario.name}' (seed {sim.seed})."
        )
    return 0


def add_commands(commands: Any, command: Any) -> None:
    """Declare this package's commands on the ``optrack`` parser (see optrack/cli.py)."""
    p = command(
        "sim",
        "Simulate a venue with walking people and write a recording with ground truth.",
        "optrack.sim.cli:cmd_sim",
    )
    p.add_argument("scenario", help="scenario name or YAML file (optrack/resources/scenarios)")
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
    p.add_argument(
        "--clip",
        action="append",
        metavar="PATH",
        help="motion each person performs: a BVH file or walk/wave/crouch/turn "
        "(repeat for one per person; e.g. with the mocap scenario)",
    )
    add_json(p)
