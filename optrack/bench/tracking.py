"""``optrack bench tracking``: speed of the tracker, and accuracy against norfair.

* ``ms_per_update_20x10``: median time of one :meth:`Tracker.update` with 20
  people walking in a room watched by 10 sensors (every sensor's batches at
  30 Hz, so 300 updates a second), synthetic detections, default settings.
* Peer comparison: our tracker and norfair's Kalman point tracker on the same
  detection streams, scored with the same CLEAR MOT (0.5 m). Streams are
  synthetic scenes with known answers and the
  detector's output on short simulated recordings of the ``crowd``,
  ``distance`` and ``occlusions`` scenarios (made once and cached, see
  :func:`bench_cache`). Our tracker runs at its defaults, one configuration for
  every stream. norfair is run over a grid of its distance threshold, hit
  counter, initialisation delay and detection threshold on every stream, and
  reported twice:

  * ``norfair`` (the oracle): its best grid point on each stream, chosen on the
    very stream it is scored on (a setting per stream, which no operator could
    pick in advance: the most generous comparison);
  * ``norfair_single``: the one grid point with the best mean MOTA over all the
    bench's streams (then the fewest switches), the same for every stream: the
    discipline our single default configuration has.

  ``better_than_norfair`` compares with the oracle, ``better_than_norfair_single``
  with the single setting.

* Both tuned per stream: our tracker is also run over a (smaller) grid of its
  own knobs that play norfair's parts (:data:`OURS_GRID`: how long an unseen
  track is held, norfair's memory; whether weak detections flagged partly
  hidden start tracks as fast as confident ones, norfair's detection
  threshold and initialisation delay), and its best point on each stream is
  reported as ``ours_tuned``; ``better_tuned_than_norfair`` compares it with
  norfair's oracle: the same privilege for both.
"""

from __future__ import annotations

import dataclasses
import itertools
import os
import statistics
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import msgspec
import numpy as np

from optrack.bench.common import info
from optrack.errors import UserError
from optrack.evaluation.clear_mot import ClearMot, MotScore
from optrack.evaluation.replay import replay
from optrack.evaluation.run import Truth, detect_recording
from optrack.recording import Recording
from optrack.sim.detections import SceneTruth, crowd_scene, render
from optrack.tracking.params import TRACKING_PARAMS
from optrack.tracking.tracker import Tracker
from optrack.types import DetectionBatch

__all__ = [
    "BenchError",
    "BenchStream",
    "bench_cache",
    "run_norfair",
    "run_ours",
    "tracking_bench",
]

#: norfair settings searched (distance m, hit counter and delay in seconds of updates)
NORFAIR_DISTANCES = (0.4, 0.7, 1.0)
NORFAIR_MEMORY_S = (0.3, 1.0)
NORFAIR_DELAY_S = (0.0, 0.1)
NO_THRESHOLD = -100.0  # norfair's detection_threshold that keeps every detection

#: our settings searched when both trackers are tuned per stream (the defaults first)
OURS_GRID: dict[str, tuple[Any, ...]] = {
    "sec_before_missing": (0.2, 0.6),
    "explained_weak_detections": ("out_of_view", "out_of_view_or_occluded"),
}


class BenchError(UserError):
    """A bench setting that cannot be honoured."""


@dataclasses.dataclass
class BenchStream:
    """One detection stream with its ground truth (ids, positions, counted) per instant."""

    name: str
    source: str
    sensors: int
    batches: list[DetectionBatch]
    times: np.ndarray
    ids: list[np.ndarray]
    xy: list[np.ndarray]
    counted: list[np.ndarray]
    detections: str | None = None  # digest of the code that made cached detections

    @property
    def updates_per_second(self) -> float:
        span = self.batches[-1].stamp - self.batches[0].stamp if len(self.batches) > 1 else 1.0
        return len(self.batches) / max(span, 1e-9)


def _from_synthetic(
    name: str, batches: list[DetectionBatch], truth: SceneTruth, sensors: int
) -> BenchStream:
    return BenchStream(
        name, "synthetic", sensors, batches, truth.times, truth.ids, truth.xy, truth.visible
    )


def _score(stream: BenchStream, outputs: Sequence[Sequence[tuple[int, float, float]]]) -> MotScore:
    mot = ClearMot()
    for k, tracks in enumerate(outputs):
        mot.add(
            stream.ids[k],
            stream.xy[k],
            stream.counted[k],
            np.array([t[0] for t in tracks], dtype=np.int64),
            np.array([(t[1], t[2]) for t in tracks], dtype=np.float64).reshape(-1, 2),
        )
    return mot.score()


def run_ours(stream: BenchStream, settings: dict[str, Any] | None = None) -> tuple[MotScore, float]:
    """Our tracker (default settings) through the output smoother; score and median ms."""
    tracker = Tracker(TRACKING_PARAMS.create(settings or {}), sensors=stream.sensors)
    result = replay(stream.batches, stream.times, tracker)
    outputs = [[(t.id, t.x, t.y) for t in out.tracks] for out in result.outputs]
    return _score(stream, outputs), result.ms_per_update


def run_norfair(
    stream: BenchStream, distance: float, memory_s: float, delay_s: float, min_confidence: float
) -> tuple[MotScore, float]:
    """norfair's Tracker (Euclidean distance on floor points, its default Kalman filter), one
    update per detection batch; its active objects are sampled at each instant."""
    import norfair

    rate = stream.updates_per_second
    tracker = norfair.Tracker(
        distance_function="euclidean",
        distance_threshold=distance,
        hit_counter_max=max(1, round(memory_s * rate)),
        initialization_delay=round(delay_s * rate),
        detection_threshold=min_confidence,
        past_detections_length=0,
    )
    outputs: list[list[tuple[int, float, float]]] = []
    current: list[tuple[int, float, float]] = []
    times = stream.times
    k = 0
    update_ms = []
    for batch in stream.batches:
        while k < len(times) and times[k] < batch.stamp:
            outputs.append(current)
            k += 1
        detections = [
            norfair.Detection(points=np.array([[d.x, d.y]]), scores=np.array([d.confidence]))
            for d in batch.detections
        ]
        started = time.perf_counter()
        active = tracker.update(detections=detections)
        update_ms.append((time.perf_counter() - started) * 1000.0)
        current = [(o.id, float(o.estimate[0, 0]), float(o.estimate[0, 1])) for o in active]
    outputs.extend([current] * (len(times) - k))
    return _score(stream, outputs), statistics.median(update_ms)


def _norfair_grid(min_confidence: float) -> list[dict[str, float]]:
    """Every norfair setting the bench tries."""
    return [
        {"distance": distance, "memory_s": memory, "delay_s": delay, "min_confidence": threshold}
        for distance, memory, delay, threshold in itertools.product(
            NORFAIR_DISTANCES, NORFAIR_MEMORY_S, NORFAIR_DELAY_S, (NO_THRESHOLD, min_confidence)
        )
    ]


def _norfair_key(score: MotScore) -> tuple[float, int]:
    return (score.mota, -score.idsw)


def _norfair_runs(
    stream: BenchStream, grid: Sequence[dict[str, float]]
) -> list[tuple[MotScore, float]]:
    """norfair at every setting of the grid on one stream: (score, median ms) each."""
    return [run_norfair(stream, **setting) for setting in grid]


def _oracle_setting(runs: Sequence[tuple[MotScore, float]]) -> int:
    """Index of the best run on one stream (higher MOTA, then fewer switches; the first
    such in the grid's order)."""
    best = 0
    for k, (score, _) in enumerate(runs):
        if _norfair_key(score) > _norfair_key(runs[best][0]):
            best = k
    return best


def single_setting(runs: Sequence[Sequence[tuple[MotScore, float]]]) -> int:
    """Index of the one grid point best over all streams: the highest mean MOTA, then the
    fewest switches in all (``runs[stream][setting]``)."""
    settings = len(runs[0])
    keys = [
        (
            float(np.mean([stream[k][0].mota for stream in runs])),
            -sum(stream[k][0].idsw for stream in runs),
        )
        for k in range(settings)
    ]
    return max(range(settings), key=lambda k: (keys[k], -k))


def ours_grid() -> list[dict[str, Any]]:
    """Every setting of ours the bench tries when both are tuned per stream (the defaults
    first: the grid's first values are the parameters' defaults)."""
    names = list(OURS_GRID)
    return [
        dict(zip(names, values, strict=True)) for values in itertools.product(*OURS_GRID.values())
    ]


def _tuned_entry(score: MotScore, ms: float, setting: dict[str, Any]) -> dict[str, Any]:
    return {
        "mota": round(score.mota, 4),
        "idsw": score.idsw,
        "fp": score.fp,
        "fn": score.fn,
        "ms_per_update": round(ms, 4),
        "settings": setting,
    }


def _better(ours: MotScore, theirs: MotScore) -> bool:
    return ours.mota > theirs.mota and ours.idsw < theirs.idsw


def bench_cache() -> Path:
    """Where simulated bench recordings and their detections are kept between runs
    ($OPTRACK_CACHE, else $XDG_CACHE_HOME/optrack, else ~/.cache/optrack)."""
    root = os.environ.get("OPTRACK_CACHE")
    if root:
        return Path(root) / "bench"
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "optrack" / "bench"


#: simulated scenes of the comparison: (scenario, sensors, seconds)
SIM_SCENES = (
    ("crowd", 3, 20.0),
    ("distance", 3, 20.0),
    ("occlusions", 3, 20.0),
    ("occlusions", 1, 20.0),
)


def _source_digest() -> str:
    """A short digest of the simulator's and the detector's code: cached detections are
    made again whenever either changes, unless $OPTRACK_BENCH_DETECTIONS names the digest
    of detections already cached (to compare trackers on the same detections while the
    detector's code changes)."""
    import hashlib

    pinned = os.environ.get("OPTRACK_BENCH_DETECTIONS")
    if pinned:
        return pinned

    import optrack.detection
    import optrack.sim

    digest = hashlib.sha1()
    for package in (optrack.sim, optrack.detection):
        for file in sorted(Path(package.__file__).parent.glob("*.py")):
            digest.update(file.read_bytes())
    return digest.hexdigest()[:10]


def _sim_stream(scenario: str, sensors: int, seconds: float, seed: int) -> BenchStream:
    """Detections of a short simulated recording, made once and cached."""
    from optrack.sim.recorder import write_recording
    from optrack.sim.world import Simulation

    digest = _source_digest()
    key = f"{scenario}-{sensors}s-{seconds:g}-seed{seed}-{digest}"
    folder = bench_cache() / key
    batches_file = folder / "batches.msgpack"
    recording_dir = folder / "recording"
    if os.environ.get("OPTRACK_BENCH_DETECTIONS") and not batches_file.is_file():
        raise BenchError(
            f"no detections are cached in {folder} (OPTRACK_BENCH_DETECTIONS={digest}); "
            f"name a digest that ends a folder name in {bench_cache()}, or unset it."
        )
    if not batches_file.is_file():
        folder.mkdir(parents=True, exist_ok=True)
        if not (recording_dir / "manifest.yaml").is_file():
            info(f"bench tracking: simulating {scenario} ({seconds:g} s, {sensors} sensors) once")
            sim = Simulation(scenario, seed=seed, sensors=sensors, seconds=seconds)
            write_recording(sim, recording_dir)
        recording = Recording(recording_dir)
        poses = {s: np.asarray(i.world_T_camera) for s, i in recording.sensors.items()}
        info(f"bench tracking: detecting people in {key} once")
        batches = list(detect_recording(recording, poses))
        batches_file.write_bytes(msgspec.msgpack.encode(batches))
    recording = Recording(recording_dir)
    batches = msgspec.msgpack.decode(batches_file.read_bytes(), type=list[DetectionBatch])
    truth = Truth.from_instants(list(recording.ground_truth()), recording.sensor_ids)
    counted = [truth.counted(k, recording.sensor_ids, 0.2) for k in range(len(truth.times))]
    return BenchStream(
        f"sim-{scenario}-{sensors}",
        "sim",
        sensors,
        batches,
        truth.times,
        truth.ids,
        truth.xy,
        counted,
        digest,
    )


def _synthetic_streams(seed: int, seconds: float = 30.0) -> list[BenchStream]:
    out = []
    for name, people, sensors in (
        ("synthetic-crowd-3", 7, 3),
        ("synthetic-crowd-1", 7, 1),
        ("synthetic-dense-4", 15, 4),
    ):
        scene = crowd_scene(people, sensors, seconds, seed=seed)
        batches, truth = render(scene, seed=seed)
        out.append(_from_synthetic(name, batches, truth, sensors))
    return out


def speed_20x10(seconds: float = 20.0, seed: int = 0) -> dict[str, float]:
    """Median and 90th percentile of one update, 20 people seen by 10 sensors (wall clock;
    also the thread's CPU time, which other programs on the machine disturb less)."""
    scene = crowd_scene(20, 10, seconds, seed=seed)
    batches, truth = render(scene, seed=seed)
    tracker = Tracker(sensors=10)
    times, cpu = [], []
    for batch in batches:
        started, started_cpu = time.perf_counter(), time.thread_time()
        tracker.update(batch)
        cpu.append((time.thread_time() - started_cpu) * 1000.0)
        times.append((time.perf_counter() - started) * 1000.0)
    return {
        "ms_per_update_20x10": round(statistics.median(times), 4),
        "ms_per_update_20x10_p90": round(float(np.percentile(times, 90)), 4),
        "cpu_ms_per_update_20x10": round(statistics.median(cpu), 4),
        "load_average": round(os.getloadavg()[0], 2) if hasattr(os, "getloadavg") else None,
        "updates_20x10": len(times),
        "detections_per_update_20x10": round(
            float(np.mean([len(b.detections) for b in batches])), 2
        ),
    }


def _compare(
    streams: Sequence[BenchStream], min_confidence: float, norfair_ok: bool
) -> dict[str, Any]:
    """Per stream: ours, norfair's oracle setting (``norfair``) and its single setting
    (``norfair_single``); the single setting itself and its mean MOTA come under the key
    ``_single``, which :func:`tracking_bench` takes out."""
    out: dict[str, Any] = {}
    ours_scores: dict[str, MotScore] = {}
    grid = _norfair_grid(min_confidence)
    ours_settings = ours_grid()
    all_runs: list[list[tuple[MotScore, float]]] = []
    for stream in streams:
        ours, ours_ms = run_ours(stream)
        ours_scores[stream.name] = ours
        entry: dict[str, Any] = {
            "source": stream.source,
            "sensors": stream.sensors,
            "frames": ours.frames,
            "objects": ours.objects,
            **({"detections": stream.detections} if stream.detections else {}),
            "ours": {
                "mota": round(ours.mota, 4),
                "idsw": ours.idsw,
                "fp": ours.fp,
                "fn": ours.fn,
                "ms_per_update": round(ours_ms, 4),
            },
        }
        line = f"bench tracking: {stream.name}: ours MOTA {ours.mota:.3f}, {ours.idsw} switches"
        if norfair_ok:
            runs = _norfair_runs(stream, grid)
            all_runs.append(runs)
            k = _oracle_setting(runs)
            theirs, theirs_ms = runs[k]
            entry["norfair"] = _tuned_entry(theirs, theirs_ms, grid[k])
            entry["better_than_norfair"] = _better(ours, theirs)
            line += f"; norfair (oracle) MOTA {theirs.mota:.3f}, {theirs.idsw} switches"
            ours_runs = [(ours, ours_ms)] + [run_ours(stream, s) for s in ours_settings[1:]]
            j = _oracle_setting(ours_runs)
            tuned, tuned_ms = ours_runs[j]
            entry["ours_tuned"] = _tuned_entry(tuned, tuned_ms, ours_settings[j])
            entry["better_tuned_than_norfair"] = _better(tuned, theirs)
            line += f"; ours (tuned) MOTA {tuned.mota:.3f}, {tuned.idsw} switches"
        out[stream.name] = entry
        info(line)
    if norfair_ok and streams:
        k = single_setting(all_runs)
        for stream, runs in zip(streams, all_runs, strict=True):
            entry = out[stream.name]
            theirs, theirs_ms = runs[k]
            entry["norfair_single"] = _tuned_entry(theirs, theirs_ms, grid[k])
            entry["better_than_norfair_single"] = _better(ours_scores[stream.name], theirs)
            info(
                f"bench tracking: {stream.name}: norfair (single setting) MOTA "
                f"{theirs.mota:.3f}, {theirs.idsw} switches"
            )
        out["_single"] = {
            "settings": grid[k],
            "mean_mota": round(float(np.mean([runs[k][0].mota for runs in all_runs])), 4),
        }
    return out


def tracking_bench() -> dict[str, Any]:
    """The figures of ``optrack bench tracking`` (see the module docstring)."""
    result: dict[str, Any] = {}
    result.update(speed_20x10())
    try:
        import norfair

        result["norfair_version"] = norfair.__version__
        norfair_ok = True
    except ImportError:
        result["norfair_version"] = None
        result["norfair_missing"] = "norfair is not installed: pip install norfair (no deps)"
        norfair_ok = False
    min_confidence = float(TRACKING_PARAMS.create().min_confidence_initialization)
    streams = _synthetic_streams(seed=1)
    for scenario, sensors, seconds in SIM_SCENES:
        streams.append(_sim_stream(scenario, sensors, seconds, seed=1))
    scenarios = _compare(streams, min_confidence, norfair_ok)
    single = scenarios.pop("_single", None)
    result["scenarios"] = scenarios
    if norfair_ok:
        result["norfair_protocols"] = {
            "norfair": "oracle: the best grid setting of each scene, chosen on that scene",
            "norfair_single": "one grid setting for every scene: the best mean MOTA over all "
            "scenes (as our tracker, which runs its defaults everywhere)",
            "ours_tuned": "our best setting of each scene, chosen on that scene from a grid of "
            "our own knobs (ours_grid), to compare with norfair's oracle: both tuned per scene",
        }
        result["ours_grid"] = {k: list(v) for k, v in OURS_GRID.items()}
        result["better_tuned_than_norfair_everywhere"] = all(
            e["better_tuned_than_norfair"] for e in scenarios.values()
        )
        result["better_than_norfair_everywhere"] = all(
            e["better_than_norfair"] for e in scenarios.values()
        )
        result["better_than_norfair_single_everywhere"] = all(
            e["better_than_norfair_single"] for e in scenarios.values()
        )
        if single is not None:
            result["norfair_single_setting"] = single["settings"]
            result["norfair_single_mean_mota"] = single["mean_mota"]
    return result
