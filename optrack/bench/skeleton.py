"""``optrack bench skeleton``: speed and accuracy of the skeleton stage (MDCA).

Real CMU motion (../shared/data/mocap) performed by simulated people with
shapes of their own, before three simulated Kinect v2 (the ``mocap``
scenario), scored as ``optrack eval --skeleton`` scores
(:mod:`optrack.evaluation.skeleton`: clouds fused around each person's true
floor position, the four markers). Recordings are rendered once and cached
(:func:`optrack.bench.tracking.bench_cache`, keyed by the clip, the setting
and a digest of the simulator's code).

* Accuracy: each clip (by default every clip of ../shared/data/mocap: the
  issue's "any clip"), one person for ``seconds``, the performer kept in the
  middle of the room (``AREA``: where the three sensors' views overlap),
  scored with the three sensors, the first two, and the first alone: the same
  recording, so the settings differ only by the sensors fused; each run
  repeated for ``seeds`` tracker seeds (0, 1, ...: the filter's draws and
  the clouds' decimation). ``accuracy`` holds each setting's figures over all
  those runs together, ``runs_over_0_10`` (runs whose mean is over 0.1 m),
  and per clip (over its seeds, with each seed's mean), ``initialisation``
  among them: how soon each person is tracked after they appear (``init_s``
  per clip and seed, its median and maximum, ``init_within_1s``;
  :func:`~optrack.evaluation.skeleton.initialisation_times`): each clip has
  its performer enter in the pose it starts with. ``jobs`` runs that many
  accuracy runs at once (separate processes); the speed figures come from
  runs of their own, one at a time, after them.
* Initialisation in a crowd: ``initialisation_4people_3sensors``, the four
  performers of the speed run below (each clip's first pose), three sensors.
* Speed: ``fps_1person_3sensors`` (person-frames per second of the stage:
  backprojection of each person's image rectangle, crop, decimation and the
  tracker's update) on the first clip with three sensors, and
  ``fps_4people_3sensors`` per person with four performers (tracker seed
  0); both leave out each run's first frame (initialisation, and numba's compilation);
  ``ms_per_frame_p50``/``_p95`` are of one person's frames with three
  sensors (wall time), ``cpu_ms_per_frame_p50`` the CPU time of those frames
  (every thread's): on a loaded machine the better guide. ``threads`` is the
  ``skeleton.threads`` setting (0: auto, the default: the cores no other process
  keeps busy, :mod:`optrack.skeleton.cores`), ``threads_used`` what it gave at the
  end of the speed runs (the bench runs nothing else then). The machine's load
  average is reported beside them, and ``reference_ms``: this computer's speed as
  the stage sees it, the CPU time of one fixed full-body likelihood
  (:func:`reference_ms`), the mean of its timings before and after the speed runs. A
  shared or virtual machine's speed varies from hour to hour; two speed figures
  compare only beside their references.
"""

from __future__ import annotations

import hashlib
import multiprocessing
import os
import shutil
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import msgspec
import numpy as np

from optrack.bench.common import info, shared_data
from optrack.bench.tracking import bench_cache
from optrack.evaluation.run import _config, _create
from optrack.evaluation.skeleton import (
    SkeletonRun,
    initialisation_times,
    run_skeleton,
    score_initialisation,
    score_markers,
)
from optrack.params import Params
from optrack.recording import Recording
from optrack.skeleton.cores import auto_threads
from optrack.skeleton.fusion import FUSION_PARAMS
from optrack.skeleton.params import SKELETON_PARAMS

__all__ = ["AREA", "SPEED_CLIPS", "all_clips", "reference_ms", "skeleton_bench"]

SPEED_CLIPS = (
    "cmu_16_27_walk_turn_left.bvh",
    "cmu_13_30_jumping_jacks_excerpt.bvh",
    "cmu_13_30_squat_excerpt.bvh",
    "cmu_01_01_jumps_turnaround.bvh",
)
AREA = (-1.2, -1.2, 1.2, 1.2)  # where one performer stays: seen by all three sensors
SEED = 1  # a placement the three sensors see throughout (seed 0 puts the walk out of one's view)
SETTINGS = (("3_sensors", 3), ("2_sensors", 2), ("1_sensor", 1))


def all_clips() -> tuple[str, ...]:
    """Every BVH clip of ../shared/data/mocap, by name."""
    return tuple(sorted(p.name for p in (shared_data() / "mocap").glob("*.bvh")))


def _digest(clips: list[Path]) -> str:
    import optrack.sim

    digest = hashlib.sha1()
    for file in sorted(Path(optrack.sim.__file__).parent.glob("*.py")):
        digest.update(file.read_bytes())
    for clip in clips:
        digest.update(clip.read_bytes())
    return digest.hexdigest()[:10]


def _recording(clips: list[Path], people: int, seconds: float, area: bool) -> Path:
    """A mocap recording (three Kinect v2), rendered once and cached: its folder."""
    from optrack.sim import Simulation, load_scenario
    from optrack.sim.recorder import write_recording

    names = "+".join(c.stem for c in clips)
    where = "-centre" if area else ""
    key = f"skeleton-{names}-{people}p-{seconds:g}s-seed{SEED}{where}-{_digest(clips)}"
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
        partial = folder / f"partial-{os.getpid()}"  # two benches at once: one each
        shutil.rmtree(partial, ignore_errors=True)
        folder.mkdir(parents=True, exist_ok=True)
        write_recording(sim, partial)
        try:
            partial.rename(folder / "recording")
        except OSError:  # another bench finished the same recording first: the same frames
            shutil.rmtree(partial, ignore_errors=True)
    return folder / "recording"


# A parameter file's values of the two stages, plain dicts (they cross to worker processes).
Stages = tuple[dict[str, Any], dict[str, Any]]


def _run(path: Path, sensors: int, label: str, seed: int, stages: Stages) -> SkeletonRun:
    """The skeleton over the recording at ``path`` with its first ``sensors`` sensors;
    ``stages``: the ``skeleton`` and ``skeleton_fusion`` values."""
    info(f"bench skeleton: {label}, {sensors} sensor(s), seed {seed}")
    recording = Recording(path)
    poses = {s: np.asarray(i.world_T_camera) for s, i in recording.sensors.items()}
    skeleton, fusion = _params(stages, None)
    return run_skeleton(
        recording, poses, recording.sensor_ids[:sensors], skeleton, fusion, seed=seed
    )


def reference_ms(repeats: int = 5, calls: int = 10) -> float:
    """The CPU time (ms) of one fixed workload of the stage's hot loop: the torso's
    likelihood (13 parts) of 2000 poses near a standing 1.75 m body, against 250 points
    spread between its joints (seeded: the same numbers every time), one thread; the
    median over ``repeats`` of ``calls`` calls."""
    import time

    from optrack.skeleton.filter import PARTITION_FRAMES, PARTITION_PARTS
    from optrack.skeleton.kernels import PartitionScorer
    from optrack.skeleton.likelihood import sorted_points
    from optrack.skeleton.model import PARTITIONS, BodyShape, D, forward_kinematics, rest_state

    rng = np.random.default_rng(0)
    shape = BodyShape.from_height(1.75)
    estimate = rest_state(shape)
    joints = forward_kinematics(estimate, shape)[0]
    ends = rng.integers(0, len(joints) - 1, (250, 2))
    along = rng.random((250, 1))
    points = joints[ends[:, 0]] * along + joints[ends[:, 0] + 1] * (1.0 - along)
    points += rng.normal(0.0, 0.06, points.shape)
    particles = estimate + rng.normal(0.0, 0.05, (2000, D))
    parts = PARTITION_PARTS["torso"]
    scorer = PartitionScorer(
        estimate, PARTITIONS["torso"], PARTITION_FRAMES["torso"], parts, shape,
        sorted_points(points, None), np.full((len(parts), 2), 5.0), (0.15, 0.6, 0.5),
    )  # fmt: skip
    scorer(particles)  # compiled (or loaded) before it is timed
    times = []
    for _ in range(repeats):
        start = time.process_time()
        for _ in range(calls):
            scorer(particles)
        times.append((time.process_time() - start) * 1000.0 / calls)
    return round(float(np.median(times)), 3)


def _params(stages: Stages, path: str | None) -> tuple[Params, Params]:
    """The ``skeleton`` and ``skeleton_fusion`` parameters of ``stages`` (checked)."""
    skeleton, fusion = stages
    return _create(SKELETON_PARAMS, skeleton, path), _create(FUSION_PARAMS, fusion, path)


def _accuracy(runs: dict[str, dict[str, list[SkeletonRun]]]) -> dict[str, Any]:
    """Each setting's figures over every clip and seed, and per clip (over its seeds)."""
    out: dict[str, Any] = {}
    for setting, _ in SETTINGS:
        per_clip = {clip: runs[clip][setting] for clip in runs}
        # Each run scored once: its mean and its people's initialisation times.
        means = {
            c: [score_markers(r.errors)["mean_error_m"] for r in s] for c, s in per_clip.items()
        }
        times = {
            clip: {
                f"{seed}/{pid}": t
                for seed, run in enumerate(seeded)
                for pid, t in initialisation_times(run.errors, run.person_ids, run.stamps).items()
            }
            for clip, seeded in per_clip.items()
        }
        every = [run for seeded in per_clip.values() for run in seeded]
        pooled = score_markers(np.concatenate([r.errors for r in every]))
        pooled["runs"] = len(every)
        pooled["runs_over_0_10"] = sum(
            1 for clip in means for m in means[clip] if m is None or m > 0.1
        )
        pooled["initialisation"] = score_initialisation(
            {f"{clip}/{key}": t for clip in times for key, t in times[clip].items()}
        )
        pooled["clips"] = {}
        for clip, seeded in per_clip.items():
            figures = score_markers(np.concatenate([r.errors for r in seeded]))
            figures["mean_error_m_by_seed"] = means[clip]
            figures["initialisation"] = score_initialisation(times[clip])
            pooled["clips"][clip] = figures
        out[setting] = pooled
    return out


def _accuracy_runs(
    recordings: dict[str, Path], seeds: int, jobs: int, stages: Stages
) -> dict[str, dict[str, list[SkeletonRun]]]:
    """Every clip x setting x seed run, ``jobs`` at a time (separate processes)."""
    tasks = [
        (clip, setting, count, seed)
        for clip in recordings
        for setting, count in SETTINGS
        for seed in range(seeds)
    ]
    runs: dict[str, dict[str, list[SkeletonRun]]] = {
        clip: {setting: [] for setting, _ in SETTINGS} for clip in recordings
    }
    # Each run's progress line says which of them it is: "run 5 of 108: CLIP".
    labels = [f"run {k + 1} of {len(tasks)}: {clip}" for k, (clip, *_) in enumerate(tasks)]
    work = [
        (recordings[c], n, label, seed, stages)
        for (c, _, n, seed), label in zip(tasks, labels, strict=True)
    ]
    if jobs <= 1:
        done = [_run(*args) for args in work]
    else:
        context = multiprocessing.get_context("spawn")  # numba and threads: no fork
        with ProcessPoolExecutor(jobs, mp_context=context) as pool:
            done = [f.result() for f in [pool.submit(_run, *args) for args in work]]
    for (clip, setting, _, _), run in zip(tasks, done, strict=True):
        runs[clip][setting].append(run)
    return runs


def skeleton_bench(
    seconds: float = 4.0,
    clips: tuple[str, ...] | None = None,
    speed_seconds: float = 2.0,
    seeds: int = 1,
    jobs: int = 1,
    config: str | None = None,
) -> dict[str, Any]:
    """The figures of ``optrack bench skeleton --json`` (see the module docstring):
    ``clips`` by name (default: every clip of ../shared/data/mocap); ``config``: a YAML
    parameter file whose ``skeleton`` and ``skeleton_fusion`` stages are used (as
    ``optrack eval --config``); ``{"skipped": reason}`` without the CMU clips."""
    folder = shared_data() / "mocap"
    clips = all_clips() if clips is None else tuple(clips)
    missing = [c for c in (*clips, *SPEED_CLIPS) if not (folder / c).is_file()]
    if missing or not clips:
        listed = ", ".join(missing) if missing else "no .bvh file"
        return {"skipped": f"the CMU clips are not in {folder} ({listed} missing)."}
    if seeds < 1 or jobs < 1 or seconds <= 0 or speed_seconds <= 0:
        raise ValueError(
            f"bench skeleton needs seeds and jobs of at least 1 and positive seconds "
            f"(got seeds {seeds}, jobs {jobs}, seconds {seconds:g}, speed seconds "
            f"{speed_seconds:g})."
        )
    values = _config(config)
    stages: Stages = (dict(values.get("skeleton", {})), dict(values.get("skeleton_fusion", {})))
    skeleton, fusion = _params(stages, config)  # checked before minutes of work
    recordings = {Path(c).stem: _recording([folder / c], 1, seconds, area=True) for c in clips}
    crowd = _recording([folder / c for c in SPEED_CLIPS], 4, speed_seconds, area=False)
    runs = _accuracy_runs(recordings, seeds, jobs, stages)
    # Speed: runs of their own, one at a time (the accuracy runs may share the cores),
    # between two timings of the reference workload.
    before = reference_ms()
    alone = _run(recordings[Path(clips[0]).stem], 3, "speed, one person", 0, stages)
    four = _run(crowd, 3, "speed, four people", 0, stages)
    # The threads the kernels used: the setting, or what auto gave at the runs' end.
    threads = int(skeleton.threads) if int(skeleton.threads) > 0 else auto_threads()
    after = reference_ms()
    skip = 1 if len(alone.frame_ms) > 1 else 0
    steady, cpu = alone.frame_ms[skip:], alone.frame_cpu_ms[skip:]
    return {
        "fps_1person_3sensors": alone.speed(1),
        "fps_4people_3sensors": four.speed(1),
        "ms_per_frame_p50": round(float(np.percentile(steady, 50)), 1),
        "ms_per_frame_p95": round(float(np.percentile(steady, 95)), 1),
        "cpu_ms_per_frame_p50": round(float(np.percentile(cpu, 50)), 1),
        "particles": int(skeleton.particles),
        "threads": int(skeleton.threads),
        "threads_used": threads,
        "points_per_person": int(fusion.points),
        "points_per_person_mean": round(float(np.mean(alone.points)), 1),
        "accuracy": _accuracy(runs),
        "initialisation_4people_3sensors": four.initialisation(),
        "clips": [Path(c).stem for c in clips],
        "seeds": seeds,
        "config": config,
        "seconds_per_clip": seconds,
        "load_average": round(os.getloadavg()[0], 2),
        "reference_ms": round((before + after) / 2.0, 3),
        "reference_ms_before_after": [before, after],
        "cpu_count": os.cpu_count(),
    }
