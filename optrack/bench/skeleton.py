"""``optrack bench skeleton``: speed and accuracy of the skeleton stage (MDCA).

Real CMU motion (../shared/data/mocap) performed by simulated people with
shapes of their own, before three simulated Kinect v2 (the ``mocap``
scenario), scored as ``optrack eval --skeleton`` scores
(:mod:`optrack.evaluation.skeleton`: clouds fused around each person's true
floor position, the four markers). Recordings are rendered once and cached
(:func:`optrack.bench.tracking.bench_cache`, keyed by the clip, the setting
and a digest of the simulator's code).

* Accuracy: each clip of :data:`ACCURACY_CLIPS`, one person for
  ``seconds``, the performer kept in the middle of the room (``AREA``: where
  the three sensors' views overlap), scored with the three sensors, the first
  two, and the first alone: the same recording, so the settings differ only
  by the sensors fused. ``accuracy`` holds each setting's figures over all
  those clips together and per clip, ``initialisation`` among them: how soon
  each person is tracked after they appear (``init_s`` per clip, its median
  and maximum, ``init_within_1s``; :func:`~optrack.evaluation.skeleton.initialisation_times`):
  each clip has its performer enter in the pose it starts with.
* Initialisation in a crowd: ``initialisation_4people_3sensors``, the four
  performers of the speed run below (each clip's first pose), three sensors.
* Speed: ``fps_1person_3sensors`` (person-frames per second of the stage:
  backprojection of each person's image rectangle, crop, decimation and the
  tracker's update) on the first clip with three sensors, and
  ``fps_4people_3sensors`` per person with four performers; both leave out
  each run's first frame (initialisation, and numba's compilation);
  ``ms_per_frame_p50``/``_p95`` are of one person's frames with three
  sensors (wall time), ``cpu_ms_per_frame_p50`` the CPU time of those frames
  (every thread's): on a loaded machine the better guide. The machine's load
  average is reported beside them.
"""

from __future__ import annotations

import hashlib
import os
import shutil
from pathlib import Path
from typing import Any

import msgspec
import numpy as np

from optrack.bench.common import info, shared_data
from optrack.bench.tracking import bench_cache
from optrack.evaluation.skeleton import (
    SkeletonRun,
    initialisation_times,
    run_skeleton,
    score_initialisation,
    score_markers,
)
from optrack.recording import Recording
from optrack.skeleton.fusion import FUSION_PARAMS
from optrack.skeleton.params import SKELETON_PARAMS

__all__ = ["ACCURACY_CLIPS", "AREA", "SPEED_CLIPS", "skeleton_bench"]

ACCURACY_CLIPS = ("cmu_16_27_walk_turn_left.bvh", "cmu_13_30_jumping_jacks_excerpt.bvh")
SPEED_CLIPS = (
    "cmu_16_27_walk_turn_left.bvh",
    "cmu_13_30_jumping_jacks_excerpt.bvh",
    "cmu_13_30_squat_excerpt.bvh",
    "cmu_01_01_jumps_turnaround.bvh",
)
AREA = (-1.2, -1.2, 1.2, 1.2)  # where one performer stays: seen by all three sensors
SEED = 1  # a placement the three sensors see throughout (seed 0 puts the walk out of one's view)
SETTINGS = (("3_sensors", 3), ("2_sensors", 2), ("1_sensor", 1))


def _digest(clips: list[Path]) -> str:
    import optrack.sim

    digest = hashlib.sha1()
    for file in sorted(Path(optrack.sim.__file__).parent.glob("*.py")):
        digest.update(file.read_bytes())
    for clip in clips:
        digest.update(clip.read_bytes())
    return digest.hexdigest()[:10]


def _recording(clips: list[Path], people: int, seconds: float, area: bool) -> Recording:
    """A mocap recording (three Kinect v2), rendered once and cached."""
    from optrack.sim import Simulation, load_scenario
    from optrack.sim.recorder import write_recording

    names = "+".join(c.stem for c in clips)
    key = f"skeleton-{names}-{people}p-{seconds:g}s-seed{SEED}-{_digest(clips)}"
    folder = bench_cache() / key
    if not (folder / "recording" / "manifest.yaml").is_file():
        scenario = load_scenario("mocap")
        if area:
            spec = msgspec.structs.replace(scenario.people, area=AREA)
            scenario = msgspec.structs.replace(scenario, people=spec)
        info(f"bench skeleton: simulating {names} ({seconds:g} s, {people} people) once")
        sim = Simulation(
            scenario,
            people=people,
            sensors=3,
            seconds=seconds,
            clips=[str(c) for c in clips],
            seed=SEED,
        )
        partial = folder / "partial"
        shutil.rmtree(partial, ignore_errors=True)
        folder.mkdir(parents=True, exist_ok=True)
        write_recording(sim, partial)
        partial.rename(folder / "recording")
    return Recording(folder / "recording")


def _run(recording: Recording, sensors: int, label: str) -> SkeletonRun:
    info(f"bench skeleton: {label}, {sensors} sensor(s)")
    poses = {s: np.asarray(i.world_T_camera) for s, i in recording.sensors.items()}
    return run_skeleton(recording, poses, recording.sensor_ids[:sensors])


def _accuracy(runs: dict[str, dict[str, SkeletonRun]]) -> dict[str, Any]:
    """Each setting's figures over every clip, and per clip."""
    out: dict[str, Any] = {}
    for setting, _ in SETTINGS:
        per_clip = {clip: runs[clip][setting] for clip in runs}
        pooled = score_markers(np.concatenate([r.errors for r in per_clip.values()]))
        times = {
            f"{clip}/{pid}": t
            for clip, run in per_clip.items()
            for pid, t in initialisation_times(run.errors, run.person_ids, run.stamps).items()
        }
        pooled["initialisation"] = score_initialisation(times)
        pooled["clips"] = {
            clip: {k: v for k, v in run.figures().items() if k != "sensors"}
            for clip, run in per_clip.items()
        }
        out[setting] = pooled
    return out


def skeleton_bench(
    seconds: float = 3.0,
    clips: tuple[str, ...] = ACCURACY_CLIPS,
    speed_seconds: float = 2.0,
) -> dict[str, Any]:
    """The figures of ``optrack bench skeleton --json`` (see the module docstring);
    ``{"skipped": reason}`` without the CMU clips."""
    folder = shared_data() / "mocap"
    missing = [c for c in (*clips, *SPEED_CLIPS) if not (folder / c).is_file()]
    if missing:
        return {"skipped": f"the CMU clips are not in {folder} ({', '.join(missing)} missing)."}
    runs: dict[str, dict[str, SkeletonRun]] = {}
    for clip in clips:
        recording = _recording([folder / clip], 1, seconds, area=True)
        runs[Path(clip).stem] = {
            setting: _run(recording, count, Path(clip).stem) for setting, count in SETTINGS
        }
    alone = runs[Path(clips[0]).stem]["3_sensors"]
    crowd = _recording([folder / c for c in SPEED_CLIPS], 4, speed_seconds, area=False)
    four = _run(crowd, 3, "four people")
    skip = 1 if len(alone.frame_ms) > 1 else 0
    steady, cpu = alone.frame_ms[skip:], alone.frame_cpu_ms[skip:]
    return {
        "fps_1person_3sensors": alone.speed(1),
        "fps_4people_3sensors": four.speed(1),
        "ms_per_frame_p50": round(float(np.percentile(steady, 50)), 1),
        "ms_per_frame_p95": round(float(np.percentile(steady, 95)), 1),
        "cpu_ms_per_frame_p50": round(float(np.percentile(cpu, 50)), 1),
        "particles": int(SKELETON_PARAMS.create().particles),
        "points_per_person": int(FUSION_PARAMS.create().points),
        "points_per_person_mean": round(float(np.mean(alone.points)), 1),
        "accuracy": _accuracy(runs),
        "initialisation_4people_3sensors": four.initialisation(),
        "seconds_per_clip": seconds,
        "load_average": round(os.getloadavg()[0], 2),
        "cpu_count": os.cpu_count(),
    }
