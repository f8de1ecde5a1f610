"""Training the depth-only person classifier on simulated recordings.

``optrack train depth-classifier`` (:func:`train_depth_classifier`). Each
scene is drawn from its seed (:func:`training_scenario`): a room of its own
size, two or three sensors of the four models (their own noise, quantisation
and holes), people of varied shapes (children among them) walking, standing,
in groups, crossing, entering and leaving, and clutter: partitions,
person-sized boxes and cabinets, pillars and tables. Every ``every``-th
frame of each sensor is detected on depth alone with the head check off (so
that boxes and partition ends become candidates too), and each candidate's
depth windows (:class:`~optrack.detection.pipeline.Judgement` ``windows``)
are labelled from the ground truth: a person when within ``POSITIVE_RADIUS``
of someone at least ``POSITIVE_VISIBLE`` visible from that sensor, not a
person when farther than ``NEGATIVE_RADIUS`` from everyone; the rest is left
out. Training windows are also mirrored, stretched sideways and given holes
(:func:`augmented`), as a real sensor's depth has.

Scenes split by seed: training (3 in 5), validation (1 in 5: the
regularisation, and the threshold, the lowest score keeping ``PRECISION`` of
the validation windows right) and held-out test (1 in 5, reported).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from scipy.optimize import minimize

from optrack.detection.classifier import HogClassifier
from optrack.detection.depth_classifier import (
    DESCRIPTOR_SIZE,
    DepthClassifier,
    depth_descriptor,
    feature_hog,
)
from optrack.detection.params import detection_params
from optrack.detection.pipeline import PeopleDetector
from optrack.errors import UserError
from optrack.sim.scenario import (
    Box,
    Door,
    Partition,
    PeopleSpec,
    Pillar,
    Scenario,
    SensorsSpec,
    Table,
    VenueSpec,
)

__all__ = [
    "augmented",
    "collect_windows",
    "fit_depth_classifier",
    "fit_logistic",
    "split_parts",
    "train_depth_classifier",
    "training_scenario",
]

POSITIVE_RADIUS = 0.35
POSITIVE_VISIBLE = 0.3
NEGATIVE_RADIUS = 0.8
PRECISION = 0.99
PARTS = ("train", "validation", "test")
REGULARISATIONS = (1e-5, 1e-4, 1e-3)
MODELS = ("kinect2", "kinect1", "stereo", "sr4500")
#: Frames are taken at this rate's every ``every``-th instant, all sensors at once.
FRAME_RATE = 30.0
#: Depth alone, and the head check off so that boxes and partitions become candidates.
COLLECTING = {"use_rgb": False, "max_head_ratio": 1.0, "depth_classifier": "trained"}
#: Sideways stretches of the training windows, and the share given holes.
STRETCHES = (1.4,)
HOLES = 0.3

Window = tuple[np.ndarray, np.ndarray]


def _obstacles(rng: np.random.Generator, half: np.ndarray) -> list[Any]:
    """Clutter on free floor: partitions, person-sized boxes, pillars, tables."""
    inner = half - 1.0

    def spot() -> tuple[float, float]:
        return (float(rng.uniform(-inner[0], inner[0])), float(rng.uniform(-inner[1], inner[1])))

    out: list[Any] = []
    for _ in range(int(rng.integers(1, 4))):
        x, y = spot()
        angle, length = rng.uniform(0, math.pi), rng.uniform(0.8, 2.0)
        dx, dy = 0.5 * length * math.cos(angle), 0.5 * length * math.sin(angle)
        out.append(
            Partition(start=(x - dx, y - dy), to=(x + dx, y + dy), height=rng.uniform(1.1, 2.0))
        )
    for _ in range(int(rng.integers(1, 4))):
        size = (rng.uniform(0.3, 0.8), rng.uniform(0.3, 0.6), rng.uniform(0.9, 2.0))
        out.append(Box(at=spot(), size=tuple(float(v) for v in size), yaw_deg=rng.uniform(0, 90)))
    for _ in range(int(rng.integers(0, 2))):
        out.append(Pillar(at=spot(), radius=float(rng.uniform(0.12, 0.3))))
    for _ in range(int(rng.integers(0, 2))):
        out.append(Table(at=spot(), size=(1.2, 0.7), yaw_deg=float(rng.uniform(0, 90))))
    return out


def training_scenario(seed: int, seconds: float = 6.0) -> Scenario:
    """A cluttered training scene drawn from ``seed`` (see the module docstring)."""
    rng = np.random.default_rng([seed, 22])
    size = (float(rng.uniform(7.0, 10.0)), float(rng.uniform(5.0, 8.0)))
    count = int(rng.integers(2, 4))
    first = int(rng.integers(len(MODELS)))
    return Scenario(
        name=f"depth-training-{seed}",
        description="people and clutter for the depth classifier",
        seconds=seconds,
        venue=VenueSpec(
            size=size,
            doors=[Door(wall="west", at=float(rng.uniform(-1.0, 1.0)))],
            obstacles=_obstacles(rng, np.array(size) / 2),
        ),
        sensors=SensorsSpec(
            count=count,
            models=[MODELS[(first + k) % len(MODELS)] for k in range(count)],  # type: ignore[misc]
            height=float(rng.uniform(2.2, 3.0)),
            tilt_deg=float(rng.uniform(15.0, 35.0)),
        ),
        people=PeopleSpec(
            count=int(rng.integers(3, 8)),
            children=0.2,
            standing=1,
            groups=[2],
            crossing=1,
            enter_leave=1,
            shapes="varied",
        ),
    )


def collect_windows(seed: int, seconds: float, every: int) -> tuple[list[Window], list[int]]:
    """The labelled depth windows of one training scene (label 1: a person)."""
    from optrack.sim.world import Simulation

    sim = Simulation(training_scenario(seed, seconds), seed=seed)
    neutral = DepthClassifier(np.zeros(DESCRIPTOR_SIZE), 0.0)  # collected, not judged
    detectors = [
        PeopleDetector(
            detection_params(sensor.model.name, overrides=COLLECTING),
            sensor_id=sensor.id,
            world_T_camera=sensor.world_T_camera,
            depth_model=neutral,
        )
        for sensor in sim.sensors
    ]
    windows: list[Window] = []
    labels: list[int] = []
    for n in range(int(sim.seconds * FRAME_RATE / every)):
        state = sim.snapshot(n * every / FRAME_RATE)  # every sensor at once, in time order
        truth = sim.truth(state)
        people = np.array([(p.x, p.y) for p in truth.people]).reshape(-1, 2)
        for index, (sensor, detector) in enumerate(zip(sim.sensors, detectors, strict=True)):
            detector.process(sim.frame(index, n, state))
            seen = np.array([p.visible.get(sensor.id, 0.0) for p in truth.people])
            for judgement in detector.last_judgements:
                label = _label(judgement.detection, people, seen)
                if label is not None:
                    windows.extend(judgement.windows)  # type: ignore[arg-type]
                    labels.extend([label] * len(judgement.windows))
    return windows, labels


def _label(detection: Any, people: np.ndarray, seen: np.ndarray) -> int | None:
    """1: near someone visible enough; 0: far from everyone; None: in between."""
    distance = np.linalg.norm(people - np.array([detection.x, detection.y]), axis=1)
    if np.any((distance < POSITIVE_RADIUS) & (seen >= POSITIVE_VISIBLE)):
        return 1
    if len(distance) == 0 or distance.min() > NEGATIVE_RADIUS:
        return 0
    return None


def _stretched(window: np.ndarray, factor: float, fill: int) -> np.ndarray:
    """The window stretched sideways by ``factor`` about its centre (cropped, or padded
    with ``fill``, back to its width)."""
    import cv2

    rows, cols = window.shape
    wide = max(1, round(cols * factor))
    stretched = cv2.resize(window, (wide, rows), interpolation=cv2.INTER_LINEAR)
    if wide >= cols:
        start = (wide - cols) // 2
        return np.ascontiguousarray(stretched[:, start : start + cols])
    out = np.full_like(window, fill)
    start = (cols - wide) // 2
    out[:, start : start + wide] = stretched
    return out


def _holed(pair: Window, rng: np.random.Generator) -> Window:
    """Depth missing in a few blobs (a real sensor's shadows, dark or shiny surfaces):
    no silhouette there, and as far as nothing in the relative depth."""
    silhouette, relative = pair[0].copy(), pair[1].copy()
    rows, cols = silhouette.shape
    for _ in range(int(rng.integers(1, 4))):
        h, w = int(rng.integers(4, 24)), int(rng.integers(3, 12))
        r, c = int(rng.integers(0, rows - h)), int(rng.integers(0, cols - w))
        silhouette[r : r + h, c : c + w] = 0
        relative[r : r + h, c : c + w] = 255
    return silhouette, relative


def augmented(
    windows: list[Window], labels: list[int], seed: int = 0
) -> tuple[list[Window], list[int]]:
    """Each window, its mirror image, both stretched by ``STRETCHES``; ``HOLES`` of them
    with holes."""
    rng = np.random.default_rng(seed)
    out: list[Window] = []
    out_labels: list[int] = []
    for (silhouette, relative), label in zip(windows, labels, strict=True):
        for s, r in ((silhouette, relative), (silhouette[:, ::-1], relative[:, ::-1])):
            views = [(np.ascontiguousarray(s), np.ascontiguousarray(r))]
            views += [(_stretched(s, f, 0), _stretched(r, f, 255)) for f in STRETCHES]
            for view in views:
                out.append(_holed(view, rng) if rng.random() < HOLES else view)
            out_labels.extend([label] * len(views))
    return out, out_labels


def _descriptors(windows: list[Window]) -> np.ndarray:
    hog, people = feature_hog(), HogClassifier()
    out = np.empty((len(windows), DESCRIPTOR_SIZE), dtype=np.float32)
    for k, (silhouette, relative) in enumerate(windows):
        out[k] = depth_descriptor(hog, people, silhouette, relative)
    return out


def fit_logistic(
    features: np.ndarray, labels: np.ndarray, regularisation: float
) -> tuple[np.ndarray, float]:
    """L2-regularised logistic regression (SciPy's L-BFGS on the mean log loss, both
    classes weighted equally): weights and bias."""
    x = np.asarray(features, dtype=np.float32)
    y = np.asarray(labels, dtype=np.float64)
    positives = max(float(y.sum()), 1.0)
    negatives = max(float(len(y) - y.sum()), 1.0)
    weight = np.where(y > 0, 0.5 / positives, 0.5 / negatives)
    sign = 2.0 * y - 1.0

    def loss(theta: np.ndarray) -> tuple[float, np.ndarray]:
        w, b = theta[:-1], theta[-1]
        margin = sign * ((x @ w.astype(np.float32)).astype(np.float64) + b)
        value = float(weight @ np.logaddexp(0.0, -margin)) + 0.5 * regularisation * float(w @ w)
        slope = -weight * sign / (1.0 + np.exp(np.clip(margin, -50.0, 50.0)))
        gradient = np.append(
            (x.T @ slope.astype(np.float32)).astype(np.float64) + regularisation * w, slope.sum()
        )
        return value, gradient

    result = minimize(
        loss, np.zeros(x.shape[1] + 1), jac=True, method="L-BFGS-B", options={"maxiter": 2000}
    )
    return result.x[:-1], float(result.x[-1])


def _rates(scores: np.ndarray, labels: np.ndarray, threshold: float) -> dict[str, Any]:
    kept = scores > threshold
    positives = int(labels.sum())
    true = int(np.count_nonzero(kept & (labels == 1)))
    return {
        "windows": len(labels),
        "people": positives,
        "recall": true / positives if positives else None,
        "precision": true / int(kept.sum()) if kept.any() else None,
    }


def _threshold(scores: np.ndarray, labels: np.ndarray) -> float:
    """The lowest score above which ``PRECISION`` of the windows are people."""
    if not labels.any():
        raise UserError("the validation scenes hold no person; give more or longer scenes.")
    order = np.argsort(-scores)
    right = np.cumsum(labels[order]) / np.arange(1, len(order) + 1)
    good = np.flatnonzero(right >= PRECISION)
    return float(scores[order][good.max()]) - 1e-6 if len(good) else float(scores.max())


def split_parts(count: int) -> list[str]:
    """Which part each of ``count`` scenes goes to: train, validation or test."""
    if count < 3:
        raise UserError(f"training needs at least 3 scenes (train, validate, test); got {count}.")
    if count < 5:  # too few for the pattern: the last two validate and test
        return ["train"] * (count - 2) + ["validation", "test"]
    return [("train", "train", "train", "validation", "test")[k % 5] for k in range(count)]


def fit_depth_classifier(
    windows: dict[str, list[Window]], labels: dict[str, list[int]]
) -> tuple[DepthClassifier, dict[str, Any]]:
    """Fit on the ``train`` windows for each regularisation, keep the one with the best
    validation recall at its threshold: the model and its scores on each part."""
    windows, labels = dict(windows), dict(labels)
    windows["train"], labels["train"] = augmented(windows["train"], labels["train"])
    features = {part: _descriptors(w) for part, w in windows.items()}
    truth = {part: np.asarray(y, dtype=np.int64) for part, y in labels.items()}
    best: tuple[float, DepthClassifier, float] | None = None
    for regularisation in REGULARISATIONS:
        weights, bias = fit_logistic(features["train"], truth["train"], regularisation)
        model = DepthClassifier(weights, bias, {"regularisation": regularisation})
        scores = model.scores(features["validation"])
        threshold = _threshold(scores, truth["validation"])
        recall = _rates(scores, truth["validation"], threshold)["recall"] or 0.0
        if best is None or recall > best[0]:
            best = (recall, model, threshold)
    assert best is not None
    _, model, threshold = best
    report = {
        "threshold": threshold,
        "regularisation": model.info["regularisation"],
        **{part: _rates(model.scores(features[part]), truth[part], threshold) for part in PARTS},
    }
    model.info.update(threshold=threshold, test=report["test"])
    return model, report


def train_depth_classifier(
    seeds: list[int], seconds: float, every: int, progress: Callable[[str], None] | None = None
) -> tuple[DepthClassifier, dict[str, Any]]:
    """Simulate ``seeds``' scenes, train on 3 in 5, choose on 1 in 5, test on 1 in 5:
    the model and its report (held-out scores, threshold, data, time)."""
    started = time.perf_counter()
    windows: dict[str, list[Window]] = {part: [] for part in PARTS}
    labels: dict[str, list[int]] = {part: [] for part in PARTS}
    for count, (seed, part) in enumerate(zip(seeds, split_parts(len(seeds)), strict=True)):
        scene_windows, scene_labels = collect_windows(seed, seconds, every)
        windows[part].extend(scene_windows)
        labels[part].extend(scene_labels)
        if progress is not None:
            progress(f"scene {count + 1}/{len(seeds)} (seed {seed}): {len(scene_labels)} windows")
    model, report = fit_depth_classifier(windows, labels)
    made = {"seeds": list(seeds), "seconds": seconds, "every": every}
    model.info.update(made)
    report.update(made)
    report["seconds_taken"] = time.perf_counter() - started
    return model, report
