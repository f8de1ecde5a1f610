"""Per-frame detection accuracy against a recording's ground truth.

Each sensor's detections (world frame, from the recording's true poses)
are matched one to one (Hungarian, SciPy) with the true floor positions of
the people at the nearest ground-truth instant, within ``radius`` (0.5 m:
CLEAR MOT's radius in the ground plane, DESIGN.md). Recall counts the
people at least ``min_visible`` visible from that sensor; precision counts
a detection as right when it matches anyone in view (a person 30 % visible
who is found is not a false positive).
"""

from __future__ import annotations

import bisect
import collections
import dataclasses
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
from scipy.optimize import linear_sum_assignment

from optrack.detection.params import detection_params
from optrack.detection.pipeline import PeopleDetector
from optrack.geometry import invert
from optrack.params import Params
from optrack.recording import GroundTruth, PersonTruth, Recording
from optrack.types import DetectionBatch, Intrinsics

__all__ = [
    "DetectionScore",
    "EdgeScore",
    "at_the_border",
    "evaluate_edges",
    "evaluate_recording",
    "score_batch",
]

#: CLEAR MOT's match radius on the floor, metres (DESIGN.md, measurement contract).
MATCH_RADIUS = 0.5
#: "At least half visible" (issue 4's recall target).
MIN_VISIBLE = 0.5
#: People at the image's edge: visible fractions scored (issue 22: 30-60 %), and the
#: half width of a person's body at half their height, metres.
EDGE_VISIBLE = (0.3, 0.6)
EDGE_HALF_WIDTH = 0.25


@dataclasses.dataclass
class _Counts:
    """People to find and found; detections and right ones; recall and precision."""

    required: int = 0
    found: int = 0
    detections: int = 0
    correct: int = 0  # detections matched to someone in view

    @property
    def recall(self) -> float | None:
        return self.found / self.required if self.required else None

    @property
    def precision(self) -> float | None:
        return self.correct / self.detections if self.detections else None


@dataclasses.dataclass
class DetectionScore(_Counts):
    """Counts over frames (``required``: people at least min_visible visible, summed
    over frames; ``found``: of those, matched); recall and precision derived."""

    frames: int = 0
    ms: list[float] = dataclasses.field(default_factory=list)
    sources: collections.Counter[str] = dataclasses.field(default_factory=collections.Counter)

    @property
    def median_ms(self) -> float | None:
        return float(np.median(self.ms)) if self.ms else None

    def as_dict(self) -> dict[str, float | int | None]:
        return {
            "recall": self.recall,
            "precision": self.precision,
            "frames": self.frames,
            "people": self.required,
            "detections": self.detections,
            "ms": self.median_ms,
            "confidence_sources": dict(self.sources),
        }


def _matches(found: np.ndarray, truth: np.ndarray, radius: float) -> list[tuple[int, int]]:
    if len(found) == 0 or len(truth) == 0:
        return []
    cost = np.linalg.norm(found[:, None, :] - truth[None, :, :], axis=2)
    rows, cols = linear_sum_assignment(cost)
    return [(r, c) for r, c in zip(rows, cols, strict=True) if cost[r, c] <= radius]


def score_batch(
    batch: DetectionBatch,
    truth: GroundTruth,
    score: DetectionScore,
    min_visible: float = MIN_VISIBLE,
    radius: float = MATCH_RADIUS,
) -> None:
    """Add one frame of one sensor to ``score``."""
    sensor = batch.sensor_id
    in_view = [p for p in truth.people if p.visible.get(sensor, 0.0) > 0.0]
    required = [p.visible.get(sensor, 0.0) >= min_visible for p in in_view]
    found = np.array([(d.x, d.y) for d in batch.detections]).reshape(-1, 2)
    people = np.array([(p.x, p.y) for p in in_view]).reshape(-1, 2)
    matched = _matches(found, people, radius)
    score.frames += 1
    score.required += sum(required)
    score.found += sum(1 for _, c in matched if required[c])
    score.detections += len(found)
    score.correct += len(matched)
    score.ms.append(batch.processing_ms)


def _detected(
    path: str | Path, params: Params | None, frames: int | None
) -> Iterator[tuple[PeopleDetector, DetectionBatch, GroundTruth]]:
    """Each frame of a simulated recording detected (true poses as calibration), with the
    detector that saw it and the ground truth at the nearest instant."""
    recording = Recording(path)
    truths = list(recording.ground_truth())
    if not truths:
        raise ValueError(f"recording {path} has no ground truth to score against.")
    times = [t.t for t in truths]
    # A simulated sensor stamps frames on its own clock: true time + its offset.
    offsets = recording.manifest.extra.get("clock_offsets") or {}
    detectors: dict[str, PeopleDetector] = {}
    for count, frame in enumerate(recording.frames()):
        if frames is not None and count >= frames:
            break
        detector = detectors.get(frame.sensor_id)
        if detector is None:
            info = recording.sensors[frame.sensor_id]
            pose = np.asarray(info.world_T_camera) if info.world_T_camera is not None else None
            detector = PeopleDetector(
                params if params is not None else detection_params(info.model),
                sensor_id=frame.sensor_id,
                world_T_camera=pose,
            )
            detectors[frame.sensor_id] = detector
        batch = detector.process(frame)
        true_t = frame.timestamp - float(offsets.get(frame.sensor_id, 0.0))  # type: ignore[union-attr]
        i = bisect.bisect_left(times, true_t)
        nearest = min(
            (j for j in (i - 1, i) if 0 <= j < len(times)),
            key=lambda j: abs(times[j] - true_t),
        )
        yield detector, batch, truths[nearest]


def evaluate_recording(
    path: str | Path,
    params: Params | None = None,
    frames: int | None = None,
    min_visible: float = MIN_VISIBLE,
    radius: float = MATCH_RADIUS,
    progress: Callable[[int], None] | None = None,
) -> DetectionScore:
    """Detect in every frame of a simulated recording (true poses as calibration) and
    score against its ground truth. ``params`` default to each sensor model's."""
    score = DetectionScore()
    for count, (detector, batch, truth) in enumerate(_detected(path, params, frames)):
        score.sources.update(j.source for j in detector.last_judgements)
        score_batch(batch, truth, score, min_visible, radius)
        if progress is not None:
            progress(count + 1)
    return score


@dataclasses.dataclass
class EdgeScore(_Counts):
    """People at the image's left or right border, partly visible (see
    :func:`evaluate_edges`): how many, how many found, how far off; and every detection."""

    errors: list[float] = dataclasses.field(default_factory=list)
    out_of_view: int = 0  # found people whose detection is flagged out_of_view

    @property
    def position_error(self) -> float | None:
        """Mean floor distance of the found people from their true position, metres."""
        return float(np.mean(self.errors)) if self.errors else None


def at_the_border(
    person: PersonTruth, camera_T_world: np.ndarray, intrinsics: Intrinsics, half_width: float
) -> bool:
    """Whether the image's left or right border crosses the person: their width (2 x
    ``half_width``, at half their height) projected into the image."""
    center = (
        camera_T_world[:3, :3] @ np.array([person.x, person.y, person.height / 2.0])
        + camera_T_world[:3, 3]
    )
    if center[2] <= 0:
        return False
    u = intrinsics.fx * center[0] / center[2] + intrinsics.cx
    half = intrinsics.fx * half_width / center[2]
    return bool(u - half < -0.5 or u + half > intrinsics.width - 0.5)


def evaluate_edges(
    path: str | Path,
    params: Params | None = None,
    visible: tuple[float, float] = EDGE_VISIBLE,
    radius: float = MATCH_RADIUS,
) -> EdgeScore:
    """Detect in every frame of a simulated recording and score the people the image's
    left or right border cuts (:func:`at_the_border`) whose visible fraction is within
    ``visible`` (from, below): found when matched (Hungarian, ``radius``); a detection is
    right when it matches anyone in view."""
    recording = Recording(path)
    poses = {
        sensor: invert(np.asarray(info.world_T_camera))
        for sensor, info in recording.sensors.items()
        if info.world_T_camera is not None
    }
    score = EdgeScore()
    for _, batch, truth in _detected(path, params, None):
        sensor = batch.sensor_id
        intrinsics = recording.sensors[sensor].intrinsics
        in_view = [p for p in truth.people if p.visible.get(sensor, 0.0) > 0.0]
        edge = [
            visible[0] <= p.visible[sensor] < visible[1]
            and at_the_border(p, poses[sensor], intrinsics, EDGE_HALF_WIDTH)
            for p in in_view
        ]
        found = np.array([(d.x, d.y) for d in batch.detections]).reshape(-1, 2)
        people = np.array([(p.x, p.y) for p in in_view]).reshape(-1, 2)
        matched = _matches(found, people, radius)
        score.required += sum(edge)
        score.detections += len(found)
        score.correct += len(matched)
        for r, c in matched:
            if edge[c]:
                score.found += 1
                score.errors.append(float(np.linalg.norm(found[r] - people[c])))
                score.out_of_view += int(batch.detections[r].out_of_view)
    return score
