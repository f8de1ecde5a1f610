"""Small scenes with known answers for the tracker's tests, and a scorer."""

from __future__ import annotations

import math

import numpy as np

from optrack.evaluation.clear_mot import ClearMot, MotScore
from optrack.evaluation.replay import replay
from optrack.sim.detections import (
    Path,
    Scene,
    ScenePerson,
    SyntheticSensor,
    person_histogram,
    render,
)
from optrack.tracking import TRACKING_PARAMS, Tracker

RED = person_histogram([0.0, 0.0], [0.9, 0.3], [0.6, 0.4])
BLUE = person_histogram([0.6, 0.6], [0.8, 0.2], [0.6, 0.4])
GREEN = person_histogram([0.33, 0.1], [0.8, 0.5], [0.6, 0.4])

#: the tests use the default settings
SETTINGS: dict[str, object] = {}


def run(
    scene: Scene, seed: int = 0, arrival_jitter: float = 0.0, **settings
) -> tuple[MotScore, Tracker, list]:
    """Track a scene; return its CLEAR MOT score, the tracker, and the sampled outputs."""
    batches, truth = render(scene, seed=seed, arrival_jitter=arrival_jitter)
    tracker = Tracker(TRACKING_PARAMS.create({**SETTINGS, **settings}), sensors=len(scene.sensors))
    result = replay(batches, truth.times, tracker)
    mot = ClearMot()
    for k, out in enumerate(result.outputs):
        mot.add(
            truth.ids[k],
            truth.xy[k],
            truth.visible[k],
            np.array([t.id for t in out.tracks]),
            np.array([(t.x, t.y) for t in out.tracks]),
        )
    return mot.score(), tracker, result.outputs


def ids_of(person: ScenePerson, outputs: list, times: np.ndarray, radius: float = 0.5) -> list[int]:
    """Track ids found within ``radius`` of a person at each instant (in order)."""
    found = []
    for t, out in zip(times, outputs, strict=True):
        where = person.path.at(float(t))
        if where is None:
            continue
        near = [(math.dist(where, (tr.x, tr.y)), tr.id) for tr in out.tracks]
        near = [n for n in near if n[0] <= radius]
        if near:
            found.append(min(near)[1])
    return found


def crossing_scene() -> Scene:
    """Two people crossing diagonally in front of one sensor, 0.7 s apart at the crossing;
    both come from and go out of its view."""
    a = ScenePerson(1, Path((0.0, 9.6), ((1.0, 2.0), (9.0, 8.4))), histogram=RED)
    b = ScenePerson(2, Path((0.7, 10.3), ((1.0, 6.0), (9.0, -0.4))), histogram=BLUE)
    sensor = SyntheticSensor("cam", 3.5, -1.0, math.pi / 2, max_range=9.0)
    return Scene((a, b), (sensor,), 9.0)


def pillar_scene() -> Scene:
    """Red walks behind a pillar, waits there 3 s and walks back; meanwhile blue comes in
    on the far side, where red would be had she walked on. Green stands at the back."""
    red = ScenePerson(
        1,
        Path(
            (0.0, 2.5, 5.5, 7.7, 12.0), ((2.5, 3.0), (5.0, 3.0), (5.0, 3.0), (2.8, 3.0), (2.8, 3.0))
        ),
        histogram=RED,
    )
    blue = ScenePerson(
        2,
        Path((4.0, 5.5, 7.0, 12.0), ((8.0, 3.5), (6.5, 3.5), (6.5, 5.0), (6.5, 5.0))),
        histogram=BLUE,
    )
    green = ScenePerson(3, Path((0.0, 12.0), ((3.0, 6.0), (3.0, 6.0))), histogram=GREEN)
    sensor = SyntheticSensor("cam", 5.0, -1.0, math.pi / 2, max_range=9.0)
    return Scene((red, blue, green), (sensor,), 12.0, pillars=((5.0, 1.5, 0.3),))
