"""``optrack bench detection``: speed and accuracy of the people detector.

Real frames (../shared/data/pcl, PCL's test data): ``five_people_ms`` is the
median time of one detection on ``five_people.pcd`` at full resolution with
PCL's unit-test settings and PCL's ground plane (the frame already in
memory, as PCL's test times it), over repeated runs after a warm-up; the
accuracy figures check the same frame against PCL's five people and its
floor, and ``office1.pcd`` (no one in it).

Simulated frames (seed 1; the detector's thresholds were chosen on seed 0):
``edge_*`` score the people 30-60 % visible at the left or right border of one
Kinect v2 sensor's image on the edge scene
(:func:`optrack.sim.edge.edge_scenario`, drawn from the seed), found within
0.5 m, ``edge_position_error_m`` their mean floor error;
``..._without_edge_window`` are the same with ``edge_window`` off.
``crowd`` and ``occlusions`` with three Kinect v2 sensors and ``mixed`` with
the lights almost off are simulated, detected with each sensor model's
defaults and scored per frame against the ground truth
(:mod:`optrack.detection.evaluate`); ``..._without_edge_window`` score the
same frames with ``edge_window`` off (the detector as it was before it).
``kinect2_fps`` is Kinect v2 frames of
the 7-person crowd detected per second by one process pinned to one core
(the frames decoded beforehand); ``..._cpu`` figures divide by the
process's own CPU time instead of the wall clock, which on a shared machine
also counts other work.
"""

from __future__ import annotations

import contextlib
import os
import re
import statistics
import subprocess
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import linear_sum_assignment

from optrack.bench.common import info, pin_to_one_core, shared_data
from optrack.detection.ground import check_ground
from optrack.detection.params import detection_params
from optrack.detection.pipeline import PeopleDetector
from optrack.errors import UserError
from optrack.types import Intrinsics

__all__ = [
    "PCL_GROUND",
    "PCL_PEOPLE_XZ",
    "detection_bench",
    "match_people",
    "parse_pcl_harness",
    "pcl_comparison",
    "real_frame_figures",
]

#: PCL's unit test: Kinect v1 intrinsics and the floor it sets (camera frame).
PCL_INTRINSICS = Intrinsics(525.0, 525.0, 319.5, 239.5, 640, 480)
PCL_GROUND = (-0.0103586, 0.997011, 0.0765573, -1.26614)
#: The five people PCL's detector reports in five_people.pcd, camera-frame (x, z), metres.
PCL_PEOPLE_XZ = ((0.128, 2.821), (0.475, 2.583), (-0.919, 2.103), (-0.592, 2.356), (0.763, 1.866))
#: Timed runs and warm-up runs of the five_people frame.
RUNS = 30
WARM_UP = 3
#: Simulated recordings: seed, length, lighting of the dark one, frames timed for fps.
SIM_SEED = 1
SIM_SECONDS = 8.0
DARK_LIGHTING = 0.02
FPS_FRAMES = 90
OPENPTRACK_KINECT_SAMPLING = 4
#: PCL's C++ detector on the same frame (../shared/bench/pcl_people): rounds of its
#: harness and of this detector, alternately, on one core; timed frames per round.
PCL_ROUNDS = 5
PCL_ITERS = 30
#: PCL's HOG+SVM people model, beside its test frames.
PCL_SVM = "trainedLinearSVMForPeopleDetectionWithHOG.yaml"
#: Where ``make -C build/pcl`` puts the harness, in the checkout.
PCL_BINARY = Path("build") / "pcl" / "people_bench"
PCL_BUILD = (
    "PCL's harness is not built: as root, apt-get install libpcl-dev cmake g++ make "
    "pkg-config, then cmake -S ../shared/bench/pcl_people -B build/pcl "
    "-DCMAKE_BUILD_TYPE=Release && make -C build/pcl (see ../shared/bench/pcl_people/"
    "README.md), and give it as --pcl-binary build/pcl/people_bench."
)
#: The issue's targets (``five_people_ratio_pcl`` and keys ending in _ms or _m: at most).
TARGETS = {
    "five_people_ms": 44.0,
    "five_people_ratio_pcl": 0.6,
    "kinect2_fps": 150.0,
    "crowd_recall": 0.9,
    "crowd_precision": 0.95,
    "occlusions_recall": 0.9,
    "occlusions_precision": 0.95,
    "dark_mixed_recall": 0.95,
    "dark_mixed_precision": 0.98,
    "edge_recall": 0.8,
    "edge_position_error_m": 0.15,
}
#: Each simulated run scored again without today's additions: (key suffix, parameters).
WITHOUT_EDGE = {"edge_window": False}
BEFORE = {
    "crowd": [("without_edge_window", WITHOUT_EDGE)],
    "occlusions": [("without_edge_window", WITHOUT_EDGE)],
    "dark_mixed": [
        ("without_edge_window", WITHOUT_EDGE),
        ("silhouette_hog", {"depth_classifier": "hog"}),
    ],
}
#: The edge scene (:func:`optrack.sim.edge.edge_scenario`): length, seconds.
EDGE_SECONDS = 10.0


def match_people(found_xz: np.ndarray, expected_xz: np.ndarray) -> tuple[int, float]:
    """One-to-one matching (Hungarian) of found to expected floor positions:
    (number matched, largest distance among the matches, metres)."""
    found_xz = np.asarray(found_xz, dtype=np.float64).reshape(-1, 2)
    expected_xz = np.asarray(expected_xz, dtype=np.float64).reshape(-1, 2)
    if len(found_xz) == 0 or len(expected_xz) == 0:
        return 0, float("nan")
    cost = np.linalg.norm(found_xz[:, None, :] - expected_xz[None, :, :], axis=2)
    rows, cols = linear_sum_assignment(cost)
    return len(rows), float(cost[rows, cols].max())


def _time_five_people(detector: PeopleDetector, five: Any, runs: int) -> tuple[list, list, Any]:
    """Wall and CPU times (ms) of ``runs`` detections of the five_people frame with PCL's
    floor (each run starts from it, as PCL's harness resets it), after a warm-up; and
    the last run's batch."""
    times, cpu_times = [], []
    for run in range(WARM_UP + runs):
        detector.ground.plane = check_ground(PCL_GROUND)  # every run starts from PCL's floor
        started, cpu_started = time.perf_counter(), time.process_time()
        batch = detector.process_cloud(five.points, PCL_INTRINSICS, five.colors)
        elapsed = (time.perf_counter() - started) * 1000.0
        if run >= WARM_UP:
            times.append(elapsed)
            cpu_times.append((time.process_time() - cpu_started) * 1000.0)
    return times, cpu_times, batch


def real_frame_figures(data: Path) -> dict[str, Any]:
    """The figures on PCL's real frames in ``data``/pcl (speed, people found, floor)."""
    from optrack.io.pcd import read_pcd

    pcl = data / "pcl"
    five = read_pcd(pcl / "five_people.pcd")
    office = read_pcd(pcl / "office1.pcd")
    out: dict[str, Any] = {}

    # Speed: PCL's settings and floor, the frame in memory, as PCL's test.
    detector = PeopleDetector(detection_params("pcl"), ground=PCL_GROUND)
    times, cpu_times, batch = _time_five_people(detector, five, RUNS)
    out["five_people_ms_cpu"] = statistics.median(cpu_times)
    out["five_people_ms"] = statistics.median(times)
    out["five_people_ms_min"] = min(times)
    found = np.array([(d.camera_xyz[0], d.camera_xyz[2]) for d in batch.detections])
    matched, worst = match_people(found, np.array(PCL_PEOPLE_XZ))
    out["five_people_count_pcl_ground"] = len(batch.detections)
    out["five_people_max_error_m_pcl_ground"] = worst if matched == 5 else None

    # Automatic floor: the same frame, a fresh detector.
    detector = PeopleDetector(detection_params("pcl"))
    started = time.perf_counter()
    batch = detector.process_cloud(five.points, PCL_INTRINSICS, five.colors)
    out["five_people_auto_ground_first_frame_ms"] = (time.perf_counter() - started) * 1000.0
    found = np.array([(d.camera_xyz[0], d.camera_xyz[2]) for d in batch.detections])
    matched, worst = match_people(found, np.array(PCL_PEOPLE_XZ))
    out["five_people_count"] = len(batch.detections)
    out["five_people_max_error_m"] = worst if matched == 5 else None
    reference = check_ground(PCL_GROUND)
    plane = detector.ground.plane
    out["ground_angle_deg"] = reference.angle_deg(plane) if plane is not None else None
    out["ground_offset_m"] = abs(reference.d - plane.d) if plane is not None else None

    detector = PeopleDetector(detection_params("pcl"))
    out["office1_count"] = len(
        detector.process_cloud(office.points, PCL_INTRINSICS, office.colors).detections
    )
    return out


def _simulate(out: Path, scenario: Any, sensors: int | None) -> Path:
    from optrack.sim.recorder import write_recording
    from optrack.sim.world import Simulation

    sim = Simulation(
        scenario, seed=SIM_SEED, sensors=sensors, sensor_model="kinect2", seconds=SIM_SECONDS
    )
    write_recording(sim, out)
    return out


def _dark_mixed() -> Any:
    import msgspec

    from optrack.sim.scenario import load_scenario

    mixed = load_scenario("mixed")
    lighting = msgspec.structs.replace(mixed.venue.lighting, level=DARK_LIGHTING)
    return msgspec.structs.replace(
        mixed, venue=msgspec.structs.replace(mixed.venue, lighting=lighting)
    )


@contextlib.contextmanager
def _one_core() -> Iterator[int | None]:
    """This process (and the processes it starts) on its idlest core, OpenCV on one
    thread, OMP_NUM_THREADS=1 for children; all as before afterwards. (The detector's
    numba kernels are single-threaded, and it hands BLAS no large product.)"""
    import cv2

    previous = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else None
    threads = cv2.getNumThreads()
    omp = os.environ.get("OMP_NUM_THREADS")
    try:
        os.environ["OMP_NUM_THREADS"] = "1"
        yield pin_to_one_core()
    finally:
        if previous is not None:
            os.sched_setaffinity(0, previous)
        cv2.setNumThreads(threads)
        if omp is None:
            os.environ.pop("OMP_NUM_THREADS", None)
        else:
            os.environ["OMP_NUM_THREADS"] = omp


def parse_pcl_harness(output: str) -> tuple[float, int]:
    """PCL's harness's median ``compute()`` time (ms) and the people it found, from its
    output (../shared/bench/pcl_people/people_bench.cpp)."""
    timing = re.search(r"^compute\(\) \[full, with HOG\]:.*\bmedian=([0-9.]+)", output, re.M)
    people = re.search(r"^people \(confidence > [-0-9.]+\): (\d+)", output, re.M)
    if timing is None or people is None:
        raise UserError(
            "PCL's harness printed no 'compute() [full, with HOG]: ... median=' and "
            "'people (confidence > ...): N' lines; is it ../shared/bench/pcl_people's people_bench?"
        )
    return float(timing.group(1)), int(people.group(1))


def _run_pcl(binary: Path, pcd: Path, iters: int) -> tuple[float, int]:
    """One run of PCL's harness on ``pcd`` (``--iters`` timed frames, ``--mode full``,
    PCL's SVM beside ``pcd``)."""
    svm = pcd.parent / PCL_SVM
    command = [str(binary), str(pcd), "--iters", str(iters), "--mode", "full", "--svm", str(svm)]
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["no message"])[-1]
        raise UserError(f"PCL's harness {binary} failed (exit {done.returncode}): {last}")
    return parse_pcl_harness(done.stdout)


def pcl_comparison(
    binary: Path | None, data: Path, rounds: int = PCL_ROUNDS, iters: int = PCL_ITERS
) -> dict[str, Any]:
    """PCL's C++ detector (its harness ``binary``) and this one on five_people.pcd with
    PCL's settings, both on one core, in alternate rounds of ``iters`` timed frames
    (wall clock, as the harness times): the medians over rounds of each round's
    median, and of their ratio. Without the harness the figures are None and
    ``pcl_comparison`` says how to build it."""
    from optrack.io.pcd import read_pcd

    keys = ("pcl_five_people_ms", "five_people_ms_pinned", "five_people_ratio_pcl")
    out: dict[str, Any] = dict.fromkeys(keys)
    if binary is None or not binary.is_file():
        out["pcl_comparison"] = PCL_BUILD
        return out
    pcd = data / "pcl" / "five_people.pcd"
    five = read_pcd(pcd)
    detector = PeopleDetector(detection_params("pcl"), ground=PCL_GROUND)
    pcl_ms, ours_ms, ours_cpu, ratios, people = [], [], [], [], []
    with _one_core() as core:
        for _ in range(rounds):
            median, found = _run_pcl(binary, pcd, iters)
            times, cpu_times, _ = _time_five_people(detector, five, iters)
            pcl_ms.append(median)
            people.append(found)
            ours_ms.append(statistics.median(times))
            ours_cpu.append(statistics.median(cpu_times))
            ratios.append(ours_ms[-1] / median)
    out.update(
        {
            "pcl_five_people_ms": statistics.median(pcl_ms),
            "five_people_ms_pinned": statistics.median(ours_ms),
            "five_people_ms_pinned_cpu": statistics.median(ours_cpu),
            "five_people_ratio_pcl": statistics.median(ratios),
            "pcl_five_people_ms_rounds": pcl_ms,
            "five_people_ms_pinned_rounds": ours_ms,
            "pcl_five_people_count": min(people),
            "pcl_comparison": (
                f"{rounds} alternate rounds of {iters} frames (PCL's harness {binary}, then "
                f"this detector) on core {core}, OMP_NUM_THREADS=1; wall-clock medians"
            ),
        }
    )
    return out


def _pinned_fps(frames: list[Any], detector: PeopleDetector) -> dict[str, float]:
    """Frames per second of ``detector.process`` on one core (wall clock and CPU time)."""
    with _one_core():
        for frame in frames[:WARM_UP]:
            detector.process(frame)
        wall, cpu = [], []
        for frame in frames:
            started, cpu_started = time.perf_counter(), time.process_time()
            detector.process(frame)
            wall.append(time.perf_counter() - started)
            cpu.append(time.process_time() - cpu_started)
    return {
        "kinect2_fps": 1.0 / statistics.median(wall),
        "kinect2_fps_cpu": 1.0 / max(statistics.median(cpu), 1e-9),
        "kinect2_ms": statistics.median(wall) * 1000.0,
    }


def _simulated(work: Path) -> dict[str, Any]:
    from optrack.detection.evaluate import evaluate_recording
    from optrack.recording import Recording

    out: dict[str, Any] = {}
    runs = [
        ("crowd", "crowd", 3),
        ("occlusions", "occlusions", 3),
        ("dark_mixed", _dark_mixed(), None),
    ]
    for name, scenario, sensors in runs:
        info(f"bench detection: simulating {name} ({SIM_SECONDS:g} s, seed {SIM_SEED})...")
        path = _simulate(work / name, scenario, sensors)
        score = evaluate_recording(path)
        out[f"{name}_recall"] = score.recall
        out[f"{name}_precision"] = score.precision
        out[f"{name}_frames"] = score.frames
        out[f"{name}_people"] = score.required
        out[f"{name}_confidence_sources"] = dict(score.sources)
        # The same frames as the detector was before the edge window and the depth model.
        for suffix, overrides in BEFORE[name]:
            params = detection_params("kinect2", overrides=overrides)
            score = evaluate_recording(path, params=params)
            out[f"{name}_recall_{suffix}"] = score.recall
            out[f"{name}_precision_{suffix}"] = score.precision
    recording = Recording(work / "crowd")
    sensor = recording.sensor_ids[0]
    sensor_info = recording.sensors[sensor]
    frames = [
        recording.load(sensor, entry)
        for _, entry in zip(range(FPS_FRAMES), recording.index(sensor), strict=False)
    ]
    detector = PeopleDetector(
        detection_params(sensor_info.model),
        sensor_id=sensor,
        world_T_camera=np.asarray(sensor_info.world_T_camera),
    )
    info(f"bench detection: timing {len(frames)} Kinect v2 frames on one core...")
    out.update(_pinned_fps(frames, detector))
    # OpenPTrack's own sampling factor for Kinects: faster, but far people fall apart.
    openptrack = {"sampling_factor": OPENPTRACK_KINECT_SAMPLING}
    detector = PeopleDetector(
        detection_params(sensor_info.model, overrides=openptrack),
        sensor_id=sensor,
        world_T_camera=np.asarray(sensor_info.world_T_camera),
    )
    fps = _pinned_fps(frames, detector)
    out["kinect2_fps_sampling_factor_4"] = fps["kinect2_fps"]
    out["kinect2_fps_cpu_sampling_factor_4"] = fps["kinect2_fps_cpu"]
    score = evaluate_recording(
        work / "crowd", params=detection_params(sensor_info.model, overrides=openptrack)
    )
    out["crowd_recall_sampling_factor_4"] = score.recall
    out["crowd_precision_sampling_factor_4"] = score.precision
    return out


def _edge(work: Path) -> dict[str, Any]:
    """People 30-60 % visible at the image's left or right border, on the edge scene of
    seed ``SIM_SEED`` (one Kinect v2 sensor), with and without the edge window."""
    from optrack.detection.evaluate import evaluate_edges
    from optrack.sim.edge import edge_scenario
    from optrack.sim.recorder import write_recording
    from optrack.sim.world import Simulation

    info(f"bench detection: simulating the edge scene ({EDGE_SECONDS:g} s, seed {SIM_SEED})...")
    path = work / "edge"
    scenario = edge_scenario(SIM_SEED, seconds=EDGE_SECONDS)
    write_recording(Simulation(scenario, seed=SIM_SEED), path)
    out: dict[str, Any] = {}
    for suffix, overrides in (("", None), ("_without_edge_window", WITHOUT_EDGE)):
        score = evaluate_edges(path, detection_params("kinect2", overrides=overrides))
        out[f"edge_recall{suffix}"] = score.recall
        out[f"edge_precision{suffix}"] = score.precision
        out[f"edge_position_error_m{suffix}"] = score.position_error
    out["edge_people"] = score.required
    return out


def _checkout() -> Path:
    """The project's checkout (where build/ is)."""
    import optrack

    return Path(optrack.__file__).resolve().parent.parent


def detection_bench(pcl_binary: str | Path | None = None) -> dict[str, Any]:
    """The figures of ``optrack bench detection`` (see the module docstring); with
    ``pcl_binary`` (PCL's harness; default build/pcl/people_bench where it is built),
    the pinned comparison with PCL's detector (:func:`pcl_comparison`)."""
    pcl_binary = Path(pcl_binary) if pcl_binary is not None else None
    if pcl_binary is not None and not os.access(pcl_binary, os.X_OK):
        raise UserError(f"{pcl_binary} is not an executable file: {PCL_BUILD}")
    if pcl_binary is None and (_checkout() / PCL_BINARY).is_file():
        pcl_binary = _checkout() / PCL_BINARY
    result: dict[str, Any] = {"five_people_ms": None, "kinect2_fps": None, "targets": TARGETS}
    data = shared_data()
    if (data / "pcl" / "five_people.pcd").is_file():
        info(f"bench detection: real frames from {data / 'pcl'} ({RUNS} timed runs)...")
        result.update(real_frame_figures(data))
        if pcl_binary is not None:
            info(
                f"bench detection: PCL's detector and this one, {PCL_ROUNDS} rounds on one core..."
            )
        result.update(pcl_comparison(pcl_binary, data))
    else:
        info(f"bench detection: no real data at {data}; the real-frame figures are null.")
    with tempfile.TemporaryDirectory(prefix="optrack-bench-detection-") as work:
        result.update(_simulated(Path(work)))
        result.update(_edge(Path(work)))
    result["targets_met"] = {
        key: result.get(key) is not None
        and (
            result[key] <= target  # type: ignore[operator]
            if key.endswith(("_ms", "_m", "_ratio_pcl"))
            else result[key] >= target  # type: ignore[operator]
        )
        for key, target in TARGETS.items()
    }
    return result
