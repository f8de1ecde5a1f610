"""``optrack sim SCENARIO --out DIR``: simulate a venue into a recording with ground truth."""

from __future__ import annotations

import argparse

from optrack.cli import emit_json, info
from optrack.params import load_config
from optrack.sim.recorder import ProgressBar, write_recording
from optrack.sim.world import Simulation

__all__ = ["cmd_sim"]


def cmd_sim(args: argparse.Namespace) -> int:
    params = load_config(args.config) if getattr(args, "config", None) else None
    sim = Simulation(
        args.scenario,
        seed=args.seed,
        people=args.people,
        sensors=args.sensors,
        sensor_model=args.sensor_model,
        seconds=args.seconds,
        params=params,
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
