"""``optrack bench sim``: how fast the simulator renders Kinect v2 frames on one core.

The figure ``kinect2_fps`` is Kinect v2 frames (depth and infrared, noise
included, the people's motion and meshes included) rendered per second by
one process pinned to ONE processor core: ``os.sched_setaffinity`` restricts
the process to a single core, Open3D's ray casting is told to use one thread
(``sim_render.threads = 1``) and OpenCV's thread pool is set to one thread.
The scene is the ``crowd`` scenario with 7 people walking 1-9 m from the
sensor, as in the OpenPTrack paper. Several runs are timed; ``kinect2_fps``
is the median of the wall-clock rates, with every run. The process is
pinned to the idlest core; on a machine shared with other work the wall
clock also counts time the core spent on others, so ``kinect2_fps_cpu``
(frames per second of this process's own CPU time) is reported beside it.
"""

from __future__ import annotations

import os
import statistics
import time
from typing import Any

import numpy as np

from optrack.bench.common import info, pin_to_one_core
from optrack.params import Param, Schema, register
from optrack.sim.render import RENDER_PARAMS
from optrack.sim.world import Simulation

__all__ = ["BENCH_PARAMS", "measure_kinect2_fps", "sim_bench"]

BENCH_PARAMS = register(
    Schema(
        "sim_bench",
        [
            Param("runs", 5, 1, 50, 1, "", "Timed runs (the median is reported)."),
            Param("frames", 90, 5, 10000, 5, "", "Frames per run."),
            Param("warmup_frames", 10, 0, 1000, 1, "", "Frames rendered before timing."),
            Param("people", 7, 1, 100, 1, "", "People in the scene."),
            Param("scenario", "crowd", help="Scenario rendered."),
        ],
        help="The simulator benchmark.",
    )
)


def measure_kinect2_fps(runs: int, frames: int, warmup: int, people: int, scenario: str) -> dict:
    render = RENDER_PARAMS.create({"threads": 1})
    sim = Simulation(
        scenario,
        seed=0,
        people=people,
        sensors=1,
        sensor_model="kinect2",
        params={"sim_render": render},
    )
    sensor = sim.sensors[0]
    renderer = sim.renderer(0, streams=("depth", "infrared"))
    rng = np.random.default_rng(0)
    n = 0
    visible = []

    def one() -> None:
        nonlocal n
        state = sim.snapshot(sensor.frame_time(n))
        result = renderer.render(state.geometry)
        sensor.model.measure(result, rng)
        if n % 10 == 0:
            visible.append(len(np.unique(result.labels[result.labels >= 0])))
        n += 1

    for _ in range(warmup):
        one()
    rates, cpu_rates = [], []
    for _ in range(runs):
        start, cpu_start = time.perf_counter(), time.process_time()
        for _ in range(frames):
            one()
        rates.append(frames / (time.perf_counter() - start))
        cpu_rates.append(frames / max(time.process_time() - cpu_start, 1e-9))
    return {
        "kinect2_fps": round(statistics.median(rates), 1),
        "runs_fps": [round(r, 1) for r in rates],
        "kinect2_fps_cpu": round(statistics.median(cpu_rates), 1),
        "runs_fps_cpu": [round(r, 1) for r in cpu_rates],
        "frames_per_run": frames,
        "people": people,
        "people_in_view_mean": round(float(np.mean(visible)), 2) if visible else 0.0,
        "width": sensor.model.width,
        "height": sensor.model.height,
        "streams": ["depth", "infrared"],
        "scenario": scenario,
    }


def sim_bench() -> dict[str, Any]:
    """The figures of ``optrack bench sim`` (see the module docstring)."""
    p = BENCH_PARAMS.create()
    core = pin_to_one_core()
    info(
        f"bench sim: Kinect v2 depth+IR, {p.people} people, {p.runs} runs of {p.frames} frames "
        f"on core {core} (one thread); load average {os.getloadavg()[0]:.2f}."
    )
    result = measure_kinect2_fps(
        int(p.runs), int(p.frames), int(p.warmup_frames), int(p.people), str(p.scenario)
    )
    result["core"] = core
    result["threads"] = 1
    result["load_average"] = round(os.getloadavg()[0], 2)
    return result
