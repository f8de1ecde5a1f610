"""The tracker on detection streams with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from optrack.sim.detections import Path, Scene, ScenePerson, SyntheticSensor, crowd_scene, render
from optrack.tracking import Tracker, TrackingError
from optrack.types import Detection, DetectionBatch
from tests.tracking.scenes import RED, crossing_scene, ids_of, run


@pytest.mark.parametrize("appearance", ["on", "off"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_two_people_crossing_keep_their_ids(appearance: str, seed: int) -> None:
    scene = crossing_scene()
    score, _, outputs = run(scene, seed, appearance=appearance)
    _, truth = render(scene, seed)
    for person in scene.people:
        ids = ids_of(person, outputs, truth.times)
        assert len(ids) > 150, "the person must be tracked most of the time"
        assert len(set(ids)) == 1, f"person {person.id} had tracks {sorted(set(ids))}"
    assert score.idsw == 0


def _one_person_two_sensors(offset: tuple[float, float], phase: float) -> Scene:
    person = ScenePerson(1, Path((0.0, 8.0), ((1.0, 1.0), (7.0, 4.0))), histogram=RED)
    sensors = (
        SyntheticSensor("left", -1.0, 2.5, 0.0, max_range=10.0),
        SyntheticSensor("right", 9.0, 2.5, math.pi, max_range=10.0, offset=offset, phase=phase),
    )
    return Scene((person,), sensors, 8.0, false_alarms_per_frame=0.0)


@pytest.mark.parametrize("phase", [0.0, 0.013])
def test_two_sensors_seeing_one_person_give_one_track(phase: float) -> None:
    """Both see her at the same moments (phase 0) or interleaved; their calibrations
    disagree by 14 cm."""
    scene = _one_person_two_sensors(offset=(0.1, -0.1), phase=phase)
    score, tracker, outputs = run(scene, seed=0)
    assert tracker.next_id == 2, "exactly one track was ever started"
    assert max(len(out.tracks) for out in outputs) == 1
    assert score.idsw == 0 and score.fp == 0
    assert sorted(tracker.status().sensors) == ["left", "right"]


def _person_at(t: float, x: float) -> Detection:
    return Detection(x=x, y=0.0, z=0.9, height=1.7, confidence=1.0)


def test_a_late_batch_within_max_detection_delay_is_used_and_an_older_one_is_dropped() -> None:
    tracker = Tracker()
    for k in range(61):  # sensor a: someone walking at 1 m/s for 2 s
        t = k / 30
        tracker.update(DetectionBatch("a", t, detections=[_person_at(t, t)]))
    track = tracker.tracks[0]
    before = track.detections
    late = tracker.update(DetectionBatch("b", 1.5, detections=[_person_at(1.5, 1.5)]))
    assert late is not None
    assert track.detections == before + 1
    assert "b" in track.sensors
    assert track.last_detection == pytest.approx(2.0)  # a late detection does not turn time back
    assert track.x[0] == pytest.approx(2.0, abs=0.1)
    assert tracker.status().dropped_batches == 0

    dropped = tracker.update(DetectionBatch("b", 2.0 - 2.05, detections=[_person_at(0, -0.05)]))
    assert dropped is None
    assert track.detections == before + 1
    status = tracker.status()
    assert status.dropped_batches == 1
    assert status.dropped_by_sensor == {"b": 1}
    assert any("late" in w for w in status.warnings)


def test_batches_arriving_out_of_order_track_as_well_as_in_order() -> None:
    """Each batch arrives up to 0.1 s after its stamp, so sensors interleave out of order.
    (No false alarms here: the order of arrival is what is under test.)"""
    scene = crowd_scene(people=5, sensors=3, seconds=20.0, seed=4, false_alarms_per_frame=0.0)
    in_order, _, _ = run(scene, seed=4)
    shuffled, tracker, _ = run(scene, seed=4, arrival_jitter=0.1)
    assert tracker.batches == 3 * 600  # every batch used
    assert tracker.status().dropped_batches == 0
    assert shuffled.mota >= in_order.mota - 0.02
    assert shuffled.idsw <= in_order.idsw + 1


def test_a_silent_sensor_raises_a_warning_in_the_status() -> None:
    tracker = Tracker()
    for k in range(120):
        t = k / 30
        tracker.update(DetectionBatch("a", t))
        if t < 1.0:
            tracker.update(DetectionBatch("b", t))
        if k == 60:
            assert tracker.status().silent_sensors == []
    status = tracker.status()
    assert status.silent_sensors == ["b"]
    assert any("sensor 'b'" in w for w in status.warnings)


def test_detections_in_the_camera_frame_are_refused_with_a_sentence() -> None:
    with pytest.raises(TrackingError, match="sensor 'k1'.*calibration"):
        Tracker().update(DetectionBatch("k1", 0.0, frame_id="camera"))


def test_appearance_is_on_for_one_sensor_and_off_for_networks_unless_set() -> None:
    assert Tracker(sensors=1).appearance_enabled
    assert not Tracker(sensors=3).appearance_enabled
    tracker = Tracker(sensors=3)
    tracker.params.appearance = "on"
    assert tracker.appearance_enabled


def test_a_synthetic_crowd_is_tracked_with_few_errors() -> None:
    scene = crowd_scene(people=7, sensors=3, seconds=30.0, seed=11)
    score, _, outputs = run(scene, seed=11)
    assert score.mota >= 0.93
    assert score.idsw <= 5
    assert score.motp < 0.15
    assert len({t.id for out in outputs for t in out.tracks}) <= 12


def test_tracks_come_out_in_the_world_frame_with_velocity_and_sensors() -> None:
    tracker = Tracker()
    for k in range(30):
        t = k / 30
        out = tracker.update(DetectionBatch("a", t, detections=[_person_at(t, 2.0 + t)]))
    (track,) = out.tracks
    assert out.frame_id == "world"
    assert track.x == pytest.approx(2.0 + 29 / 30, abs=0.05)
    assert track.vx == pytest.approx(1.0, abs=0.3)
    assert track.sensors == ["a"]
    assert track.height == pytest.approx(1.7)
    assert np.isclose(track.age, 29 / 30)
