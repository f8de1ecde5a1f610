"""Score skeletons against a recording's joint truth (``optrack eval RECORDING --skeleton``).

The skeleton runs at the rate of the recording's first sensor (of those
chosen): at each of its frames, every sensor's frame stamped nearest, within
half a frame period, is turned into world points (the recording's true poses,
or ``--calibration``), and each person of the ground truth instant nearest in
time gets their cloud (:func:`optrack.skeleton.fusion.fuse_person`, around
their true floor position and height: the skeleton is scored alone, not the
people tracker's positions) and their own :class:`SkeletonTracker`.

Scored are the paper's markers (MDCA's Table I: both wrists and ankles): a
marker's error is the distance from its estimate to its true position, every
frame of every person counts from their first frame on (initialisation
included); a marker without an estimate (no cloud yet) counts as lost.
``mean_error_m`` is the mean over the four markers and the frames that have
an estimate; ``pct_under_*`` are the shares of marker-frames under 0.10,
0.15 and 0.20 m; ``lost_pct`` the share at 0.2 m or more (lost). ``fps`` is
person-frames per second of the skeleton stage's time: backprojection (of
each person's image rectangle), crop, decimation and the tracker's update
(reading and decoding the images is not counted).

``initialisation`` says how soon each person is tracked after they appear:
``init_s`` is the time from a person's first frame to the first frame from
which their error (the mean of the four markers; a marker without an
estimate counts as lost) stays under 0.1 m for :data:`INIT_HOLD_S` (or to
the end of their frames, if sooner); ``None`` (not counted as within 1 s)
where it never does. ``init_s_median`` and ``init_s_max`` are over the
people tracked, ``init_within_1s`` the share of all people tracked within
1 s (the issue's target).
"""

from __future__ import annotations

import dataclasses
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from optrack.evaluation.run import EvalError, _config, _create, _poses
from optrack.params import Params
from optrack.recording import GroundTruth, Recording
from optrack.skeleton.fusion import FUSION_PARAMS, nearest_frames, person_cloud
from optrack.skeleton.joints import MARKERS
from optrack.skeleton.params import SKELETON_PARAMS
from optrack.skeleton.tracker import JOINTS, SkeletonTracker

__all__ = [
    "SkeletonRun",
    "evaluate_skeleton",
    "initialisation_times",
    "marker_errors",
    "run_skeleton",
    "score_initialisation",
    "score_markers",
]

_MARKER_INDEX = [JOINTS.index(m) for m in MARKERS]
THRESHOLDS = (0.10, 0.15, 0.20)
LOST_M = 0.20
INIT_ERROR_M = 0.10  # a person is tracked once their error stays under this...
INIT_HOLD_S = 0.5  # ...for this long
INIT_TARGET_S = 1.0  # the target: tracked within this of their first frame


def marker_errors(truth: np.ndarray, estimate: np.ndarray) -> np.ndarray:
    """Each marker's error (F, len(MARKERS)), metres, from true and estimated positions
    (F, len(MARKERS), 3); NaN where the estimate is (no estimate)."""
    truth = np.asarray(truth, dtype=np.float64).reshape(-1, len(MARKERS), 3)
    estimate = np.asarray(estimate, dtype=np.float64).reshape(-1, len(MARKERS), 3)
    return np.linalg.norm(estimate - truth, axis=2)


def score_markers(errors: np.ndarray) -> dict[str, Any]:
    """The figures of marker errors ``errors`` (F, len(MARKERS)) in metres, NaN where a
    marker has no estimate (counted as lost); see the module docstring."""
    errors = np.asarray(errors, dtype=np.float64).reshape(-1, len(MARKERS))
    seen = np.isfinite(errors)
    total = errors.size
    worst = np.where(seen, errors, np.inf)

    def pct(mask: np.ndarray, of: int) -> float:
        return round(100.0 * float(np.count_nonzero(mask)) / of, 3) if of else 0.0

    def mean(values: np.ndarray) -> float | None:
        return round(float(np.mean(values)), 4) if values.size else None

    markers = {
        name: {
            "mean_error_m": mean(errors[seen[:, k], k]),
            "lost_pct": pct(worst[:, k] >= LOST_M, len(errors)),
        }
        for k, name in enumerate(MARKERS)
    }
    figures: dict[str, Any] = {"mean_error_m": mean(errors[seen]), "markers": markers}
    for threshold in THRESHOLDS:
        figures[f"pct_under_{threshold:.2f}".replace(".", "_")] = pct(worst < threshold, total)
    figures["lost_pct"] = pct(worst >= LOST_M, total)
    figures["frames"] = len(errors)
    return figures


def initialisation_times(
    errors: np.ndarray, people: np.ndarray, stamps: np.ndarray
) -> dict[int, float | None]:
    """Each person's ``init_s`` (see the module docstring) from their person-frames' marker
    errors (F, len(MARKERS)), person ids (F,) and stamps (F,), in time order per person."""
    errors = np.asarray(errors, dtype=np.float64).reshape(-1, len(MARKERS))
    frame_error = np.where(np.isfinite(errors), errors, np.inf).mean(axis=1)
    people, stamps = np.asarray(people), np.asarray(stamps, dtype=np.float64)
    out: dict[int, float | None] = {}
    for pid in dict.fromkeys(people.tolist()):
        mine = people == pid
        t, good = stamps[mine] - stamps[mine][0], frame_error[mine] < INIT_ERROR_M
        # bad_after[k]: the first bad frame at or after k (len(t) if none)
        bad = np.flatnonzero(~good)
        first_bad = np.searchsorted(bad, np.arange(len(t)))
        bad_after = np.append(bad, len(t))[first_bad]
        ends = np.searchsorted(t, t + INIT_HOLD_S, side="right")
        held = good & (bad_after >= ends)
        out[int(pid)] = round(float(t[np.argmax(held)]), 4) if held.any() else None
    return out


def score_initialisation(times: Mapping[int, float | None]) -> dict[str, Any]:
    """``init_s`` per person (keyed by id, as strings for JSON), their median and maximum
    over the people tracked, and ``init_within_1s``: the share of all people tracked within
    :data:`INIT_TARGET_S`."""
    found = [t for t in times.values() if t is not None]
    within = sum(t <= INIT_TARGET_S for t in found)
    return {
        "init_s": {str(pid): t for pid, t in times.items()},
        "init_s_median": round(float(np.median(found)), 4) if found else None,
        "init_s_max": round(float(np.max(found)), 4) if found else None,
        "init_within_1s": round(within / len(times), 4) if times else None,
    }


@dataclasses.dataclass
class SkeletonRun:
    """What a run of the skeleton over a recording gives: each person-frame's marker errors
    (F, len(MARKERS)), cloud size (F,), person id (F,) and stamp (F,, s); each skeleton
    frame's wall and CPU time (ms, all its people, the CPU time of every thread of the
    process) and number of people."""

    errors: np.ndarray
    points: np.ndarray
    frame_ms: np.ndarray
    frame_cpu_ms: np.ndarray
    frame_people: np.ndarray
    people: int
    sensors: list[str]
    person_ids: np.ndarray
    stamps: np.ndarray

    def speed(self, skip: int = 0) -> float:
        """Person-frames per second of the skeleton stage, the first ``skip`` frames left
        out (to leave out initialisation)."""
        spent = float(np.sum(self.frame_ms[skip:])) / 1000.0
        done = int(np.sum(self.frame_people[skip:]))
        return round(done / spent, 2) if spent > 0 else 0.0

    @property
    def fps(self) -> float:
        """Person-frames per second of the skeleton stage, every frame counted."""
        return self.speed(0)

    def initialisation(self) -> dict[str, Any]:
        """:func:`score_initialisation` of the run's people."""
        return score_initialisation(initialisation_times(self.errors, self.person_ids, self.stamps))

    def figures(self) -> dict[str, Any]:
        """:func:`score_markers` of the run, with its initialisation, fps, people and
        sensors."""
        out = score_markers(self.errors)
        out["initialisation"] = self.initialisation()
        out["fps"] = self.fps
        out["people"] = self.people
        out["sensors"] = list(self.sensors)
        return out


class _Frames:
    """Each chosen sensor's index (stamps ascending) and frame period."""

    def __init__(self, recording: Recording, sensors: Sequence[str]) -> None:
        self.recording = recording
        self.entries = {s: list(recording.index(s)) for s in sensors}
        self.stamps = {s: np.array([e.t for e in self.entries[s]]) for s in sensors}
        self.periods = {}
        for s in sensors:
            fps = recording.sensors[s].fps
            gaps = np.diff(self.stamps[s])
            self.periods[s] = 1.0 / fps if fps else float(np.median(gaps)) if len(gaps) else 1.0

    def depth_at(self, t: float) -> dict[str, Any]:
        """Each sensor's frame nearest ``t`` (within half its period), depth only."""
        chosen = nearest_frames(self.stamps, t, self.periods)
        return {
            s: self.recording.load(s, self.entries[s][i], streams=("depth",))
            for s, i in chosen.items()
        }


def _people(instant: GroundTruth) -> dict[int, tuple[np.ndarray, float, np.ndarray]]:
    """Each person with joint truth: floor position, height, markers (len(MARKERS), 3)."""
    out = {}
    for person in instant.people:
        if all(m in person.joints for m in MARKERS):
            markers = np.array([person.joints[m] for m in MARKERS], dtype=np.float64)
            out[person.id] = (np.array([person.x, person.y]), float(person.height), markers)
    return out


def run_skeleton(
    recording: Recording,
    poses: Mapping[str, np.ndarray],
    sensors: Sequence[str] | None = None,
    skeleton: Params | None = None,
    fusion: Params | None = None,
    progress: bool = False,
    seed: int = 0,
) -> SkeletonRun:
    """The skeleton over the recording with ``sensors`` (default: all); see the module
    docstring."""
    sensors = list(sensors) if sensors is not None else recording.sensor_ids
    skeleton = skeleton if skeleton is not None else SKELETON_PARAMS.create()
    fusion = fusion if fusion is not None else FUSION_PARAMS.create()
    instants = list(recording.ground_truth())
    truth_times = np.array([g.t for g in instants])
    frames = _Frames(recording, sensors)
    rng = np.random.default_rng(seed)
    trackers: dict[int, SkeletonTracker] = {}
    errors: list[np.ndarray] = []
    points: list[int] = []
    person_ids: list[int] = []
    stamps: list[float] = []
    frame_ms: list[float] = []
    frame_cpu_ms: list[float] = []
    frame_people: list[int] = []
    reference = frames.stamps[sensors[0]]
    for k, t in enumerate(reference):
        depth = frames.depth_at(float(t))
        people = _people(instants[int(np.argmin(np.abs(truth_times - t)))])
        started, cpu = time.perf_counter(), time.process_time()
        for pid, (xy, height, markers) in people.items():
            others = [p[0] for q, p in people.items() if q != pid]
            cloud = person_cloud(depth, poses, xy, height, fusion, rng, others)
            if pid not in trackers:
                trackers[pid] = SkeletonTracker(skeleton, seed=seed + pid)
            estimate = trackers[pid].update(cloud, float(t))
            points.append(len(cloud))
            person_ids.append(pid)
            stamps.append(float(t))
            errors.append(marker_errors(markers, estimate.joints[_MARKER_INDEX])[0])
        frame_ms.append((time.perf_counter() - started) * 1000.0)
        frame_cpu_ms.append((time.process_time() - cpu) * 1000.0)
        frame_people.append(len(people))
        if progress and ((k + 1) % 10 == 0 or k + 1 == len(reference)):
            print(f"\reval: skeleton frame {k + 1}/{len(reference)}", end="", file=sys.stderr)
    if progress:
        print(file=sys.stderr, flush=True)
    shaped = np.array(errors).reshape(-1, len(MARKERS))
    return SkeletonRun(
        shaped,
        np.array(points),
        np.array(frame_ms),
        np.array(frame_cpu_ms),
        np.array(frame_people),
        len(trackers),
        sensors,
        np.array(person_ids, dtype=np.int64),
        np.array(stamps),
    )


def evaluate_skeleton(
    path: str | Path,
    calibration: str | None = None,
    config_file: str | None = None,
    progress: bool = False,
) -> dict[str, Any]:
    """The ``skeleton`` figures ``optrack eval --skeleton`` reports for the recording at
    ``path`` (its ``skeleton`` and ``skeleton_fusion`` stages from ``config_file``)."""
    recording = Recording(path)
    instants = recording.ground_truth() if recording.has_ground_truth else iter(())
    if not any(p.joints for instant in instants for p in instant.people):
        raise EvalError(
            f"recording {recording.path} has no joint positions in its ground truth to score "
            "skeletons against; make one with 'optrack sim mocap'."
        )
    config = _config(config_file)
    skeleton = _create(SKELETON_PARAMS, config.get("skeleton", {}), config_file)
    fusion = _create(FUSION_PARAMS, config.get("skeleton_fusion", {}), config_file)
    run = run_skeleton(
        recording, _poses(recording, calibration), None, skeleton, fusion, progress=progress
    )
    figures = run.figures()
    figures["particles"] = int(skeleton.particles)
    figures["positions"] = "ground truth"
    return figures
