"""Detect and track a recording, score it against its ground truth (``optrack eval``).

Every frame of every sensor goes through that sensor's people detector (in
the world frame: the recording's true poses, or ``--calibration``), the
batches go through the central tracker and its output smoother, and the
smoothed tracks are scored at every ground-truth instant with CLEAR MOT in
the ground plane (0.5 m). A person counts in an instant when at least one
sensor sees at least 20 % of them within its range; people nobody can see
are "don't care". Scores come overall (all sensors into one tracker) and per
sensor (that sensor's batches alone, same tracker settings).

Detection runs again on every evaluation (nothing is cached), so a config
file's ``detection`` section (values for every sensor, and per sensor model
under the model's name) is scored like its tracking stages.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from optrack.errors import UserError
from optrack.evaluation.clear_mot import ClearMot, MotScore
from optrack.evaluation.replay import replay
from optrack.params import REGISTRY, Param, ParamError, Params, Schema, register
from optrack.recording import GroundTruth, Recording
from optrack.tracking import APPEARANCE_PARAMS, SMOOTHING_PARAMS, TRACKING_PARAMS, Tracker
from optrack.tracking.smoothing import OutputSmoother
from optrack.types import DetectionBatch

__all__ = ["EVALUATION_PARAMS", "EvalError", "Truth", "detect_recording", "evaluate", "score"]

EVALUATION_PARAMS = register(
    Schema(
        "evaluation",
        [
            Param(
                "match_radius",
                0.5,
                min=0.05,
                max=5.0,
                step=0.05,
                unit="m",
                help="A track matches a person within this distance on the floor (CLEAR MOT).",
            ),
            Param(
                "min_visible",
                0.2,
                min=0.0,
                max=1.0,
                step=0.05,
                help="A person counts when some sensor sees at least this fraction of them.",
            ),
        ],
        help="How tracking is scored against ground truth.",
    )
)


class EvalError(UserError):
    """A recording or option that cannot be evaluated."""


@dataclasses.dataclass
class Truth:
    """Ground truth per instant: ids, floor positions, and each sensor's visible fraction."""

    times: np.ndarray
    ids: list[np.ndarray]
    xy: list[np.ndarray]
    visible: list[dict[str, np.ndarray]]

    @classmethod
    def from_instants(cls, instants: list[GroundTruth], sensors: list[str]) -> Truth:
        times, ids, xy, visible = [], [], [], []
        for instant in instants:
            times.append(instant.t)
            ids.append(np.array([p.id for p in instant.people], dtype=np.int64))
            xy.append(
                np.array([(p.x, p.y) for p in instant.people], dtype=np.float64).reshape(-1, 2)
            )
            visible.append(
                {
                    s: np.array([p.visible.get(s, 0.0) for p in instant.people], dtype=np.float64)
                    for s in sensors
                }
            )
        return cls(np.asarray(times, dtype=np.float64), ids, xy, visible)

    def counted(self, k: int, sensors: list[str], min_visible: float) -> np.ndarray:
        """Whether each person counts at instant k for these sensors."""
        seen = np.zeros(len(self.ids[k]), dtype=bool)
        for s in sensors:
            seen |= self.visible[k][s] >= min_visible
        return seen


def _config(path: str | None) -> dict[str, Mapping[str, Any]]:
    if not path:
        return {}
    file = Path(path)
    try:
        data = yaml.safe_load(file.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise EvalError(f"config file {file} does not exist; check the path.") from None
    except (OSError, yaml.YAMLError):
        raise EvalError(
            f"config file {file} cannot be read as YAML; fix it or leave it out."
        ) from None
    if data is None:
        return {}
    if not isinstance(data, dict) or not all(isinstance(v, dict | None) for v in data.values()):
        raise EvalError(f"config file {file} must map stage names to parameters.")
    from optrack.detection.params import check_config_section  # registers the stage

    try:
        check_config_section(data.get("detection") or {})
    except ParamError as error:
        raise EvalError(f"config file {file}: {error}") from None
    unknown = sorted(set(data) - set(REGISTRY))
    if unknown:
        raise EvalError(
            f"config file {file} names unknown stages {', '.join(unknown)} "
            f"(known: {', '.join(sorted(REGISTRY))})."
        )
    return {k: v or {} for k, v in data.items()}


def _create(schema: Schema, values: Mapping[str, Any], path: str | None) -> Params:
    try:
        return schema.create(values)
    except ParamError as error:
        raise EvalError(f"config file {path}: {error}") from None


def detect_recording(
    recording: Recording,
    poses: Mapping[str, np.ndarray],
    overrides: Mapping[str, Any] | None = None,
    progress: bool = False,
) -> Iterator[DetectionBatch]:
    """Every frame of the recording through its sensor's detector, in time order."""
    from optrack.detection import PeopleDetector
    from optrack.detection.params import detection_params

    detectors: dict[str, Any] = {}
    for sid in recording.sensor_ids:
        info = recording.sensors[sid]
        try:
            params = detection_params(info.model or None, overrides=overrides)
        except ParamError as error:
            raise EvalError(f"detection parameters: {error}") from None
        detectors[sid] = PeopleDetector(params, sensor_id=sid, world_T_camera=poses[sid])
    total = sum(recording.count(s) for s in recording.sensor_ids) if progress else 0
    for done, frame in enumerate(recording.frames(), start=1):
        yield detectors[frame.sensor_id].process(frame)
        if progress and (done % 100 == 0 or done == total):
            print(f"\reval: detected {done}/{total} frames", end="", file=sys.stderr, flush=True)
    if progress:
        print(file=sys.stderr, flush=True)


def score(
    batches: list[DetectionBatch],
    truth: Truth,
    sensors: list[str],
    tracking: Params,
    appearance: Params,
    smoothing: Params,
    evaluation: Params,
    sensor_count: int,
) -> tuple[MotScore, Tracker, float]:
    """Track the batches of ``sensors`` and score the smoothed output; also the median
    update time (ms)."""
    chosen = set(sensors)
    tracker = Tracker(tracking, appearance, sensors=sensor_count)
    result = replay(
        (b for b in batches if b.sensor_id in chosen),
        truth.times,
        tracker,
        OutputSmoother(smoothing),
    )
    mot = ClearMot(radius=evaluation.match_radius)
    for k, out in enumerate(result.outputs):
        mot.add(
            truth.ids[k],
            truth.xy[k],
            truth.counted(k, sensors, evaluation.min_visible),
            np.array([t.id for t in out.tracks], dtype=np.int64),
            np.array([(t.x, t.y) for t in out.tracks], dtype=np.float64).reshape(-1, 2),
        )
    return mot.score(), tracker, result.ms_per_update


def _poses(recording: Recording, calibration: str | None) -> dict[str, np.ndarray]:
    if calibration:
        from optrack.calibration.files import load_network

        network = load_network(calibration)
        return {sid: network.pose(sid) for sid in recording.sensor_ids}
    poses = {}
    for sid, sensor in recording.sensors.items():
        if sensor.world_T_camera is None:
            raise EvalError(
                f"recording {recording.path} does not know where sensor '{sid}' is; give "
                "--calibration FILE (from 'optrack calibrate network')."
            )
        poses[sid] = np.asarray(sensor.world_T_camera, dtype=np.float64)
    return poses


def _rounded(score: MotScore) -> dict[str, Any]:
    return {k: (round(v, 4) if isinstance(v, float) else v) for k, v in score.as_dict().items()}


def evaluate(
    path: str | Path,
    calibration: str | None = None,
    config_file: str | None = None,
    appearance: str | None = None,
    progress: bool = False,
) -> tuple[dict[str, Any], MotScore]:
    """Every frame of the recording at ``path`` detected, tracked and scored (see the
    module docstring): the figures ``optrack eval`` reports, and the overall score.
    ``calibration``: a calibration file (default: the recording's true poses);
    ``config_file``: a YAML parameter file; ``appearance``: auto, on or off (default:
    the config's)."""
    recording = Recording(path)
    if not recording.has_ground_truth:
        raise EvalError(
            f"recording {recording.path} has no ground truth to score against; make one with "
            "'optrack sim' or give a recording that has ground_truth.jsonl."
        )
    config = _config(config_file)
    tracking = _create(TRACKING_PARAMS, config.get("tracking", {}), config_file)
    appearance_params = _create(APPEARANCE_PARAMS, config.get("appearance", {}), config_file)
    smoothing = _create(SMOOTHING_PARAMS, config.get("smoothing", {}), config_file)
    evaluation = _create(EVALUATION_PARAMS, config.get("evaluation", {}), config_file)
    if appearance:
        tracking.appearance = appearance
    poses = _poses(recording, calibration)
    sensors = recording.sensor_ids
    truth = Truth.from_instants(list(recording.ground_truth()), sensors)
    if not len(truth.times):
        raise EvalError(f"recording {recording.path} has an empty ground truth file.")

    started = time.perf_counter()
    batches = list(detect_recording(recording, poses, config.get("detection"), progress=progress))
    detect_s = time.perf_counter() - started
    started = time.perf_counter()
    settings = (tracking, appearance_params, smoothing, evaluation, len(sensors))
    overall, tracker, ms_per_update = score(batches, truth, sensors, *settings)
    track_s = time.perf_counter() - started
    per_sensor = {}
    if len(sensors) > 1:
        for sid in sensors:
            alone, _, _ = score(batches, truth, [sid], *settings)
            per_sensor[sid] = _rounded(alone)
    else:
        per_sensor[sensors[0]] = _rounded(overall)
    result: dict[str, Any] = {
        "recording": str(recording.path),
        **_rounded(overall),
        "fps": round(len(batches) / max(detect_s + track_s, 1e-9), 2),
        "sensor_frames": len(batches),
        "sensors": per_sensor,
        "tracks_started": tracker.next_id - 1,
        "appearance": tracker.appearance_enabled,
        "out_of_view_hold": tracker.out_of_view_hold,
        "dropped_batches": tracker.dropped,
        "ms_per_update": round(ms_per_update, 4),
        "detection_ms": round(float(np.median([b.processing_ms for b in batches])), 2)
        if batches
        else 0.0,
        "calibration": calibration or "recording",
    }
    return result, overall
