"""Output smoothing, fixed-rate republishing, heartbeat and OpenPTrack's JSON messages."""

from __future__ import annotations

import json

import pytest

from optrack.evaluation.replay import replay
from optrack.tracking import (
    SMOOTHING_PARAMS,
    TRACKING_PARAMS,
    OutputSmoother,
    Tracker,
    heartbeat_message,
    tracks_message,
)
from optrack.types import Detection, DetectionBatch, Track, TrackBatch, TrackStatus


def _batch(
    t: float, *tracks: tuple[int, float], status: TrackStatus = TrackStatus.NORMAL
) -> TrackBatch:
    return TrackBatch(
        stamp=t,
        tracks=[Track(id=i, x=x, y=1.0, height=1.7, status=status) for i, x in tracks],
    )


def test_position_is_the_moving_average_of_the_last_five() -> None:
    smoother = OutputSmoother()
    for k in range(8):
        smoother.add(_batch(k * 0.01, (1, float(k))))
    (track,) = smoother.publish(0.08).tracks
    assert track.x == pytest.approx((3 + 4 + 5 + 6 + 7) / 5)
    assert track.y == pytest.approx(1.0)


def test_tracks_unseen_for_drop_after_leave_the_output() -> None:
    smoother = OutputSmoother()
    smoother.add(_batch(0.0, (1, 0.0), (2, 5.0)))
    smoother.add(_batch(0.1, (2, 5.0)))
    smoother.add(_batch(0.5, (2, 5.0)))
    smoother.add(_batch(0.55, (2, 5.0), status=TrackStatus.MISSING))  # predicted, not seen
    assert [t.id for t in smoother.publish(0.59).tracks] == [1, 2]
    assert [t.id for t in smoother.publish(0.61).tracks] == [2]
    assert [t.id for t in smoother.publish(1.11).tracks] == []


def test_republishing_runs_at_the_fixed_rate_in_stream_time() -> None:
    smoother = OutputSmoother(SMOOTHING_PARAMS.create({"rate": 30.0}))
    batches = [_batch(k * 0.013, (1, k * 0.01)) for k in range(77)]  # uneven 77 Hz, 1 s
    out = list(smoother.republish(batches))
    stamps = [b.stamp for b in out]
    assert len(out) == 30
    assert stamps == pytest.approx([k / 30 for k in range(30)])
    assert all(b.seq == k + 1 for k, b in enumerate(out))


def test_heartbeat_lists_the_alive_ids_and_the_largest_id_ever_given() -> None:
    smoother = OutputSmoother()
    smoother.add(_batch(0.0, (3, 0.0), (9, 1.0)))
    smoother.add(_batch(1.0, (3, 0.0)))
    beat = smoother.heartbeat(1.0)
    assert beat.alive_ids == [3]
    assert beat.max_id == 9


def test_messages_are_openptracks_json_documents() -> None:
    batch = TrackBatch(
        stamp=12.25, seq=7, tracks=[Track(id=4, x=1.5, y=-2.0, height=1.8, age=3.0, confidence=0.9)]
    )
    message = json.loads(json.dumps(tracks_message(batch)))
    assert message == {
        "header": {"seq": 7, "stamp": {"sec": 12, "nsec": 250000000}, "frame_id": "world"},
        "tracks": [{"id": 4, "x": 1.5, "y": -2.0, "height": 1.8, "age": 3.0, "confidence": 0.9}],
    }
    smoother = OutputSmoother()
    smoother.add(_batch(0.0, (2, 0.0), (5, 1.0)))
    beat = json.loads(json.dumps(heartbeat_message(smoother.heartbeat(0.5))))
    assert beat["header"]["frame_id"] == "heartbeat"
    assert beat["alive_IDs"] == [2, 5] and beat["max_ID"] == 5


def test_the_window_follows_a_live_parameter_change() -> None:
    smoother = OutputSmoother()
    for k in range(5):
        smoother.add(_batch(k * 0.01, (1, float(k))))
    smoother.params.window = 2
    smoother.add(_batch(0.05, (1, 5.0)))
    assert smoother.publish(0.06).tracks[0].x == pytest.approx(4.5)


def test_a_person_lost_at_the_images_edge_is_held_longer_in_the_output() -> None:
    """Tracker and smoother together, with the hold on (0.6 s): a person whose detections
    of the last 0.3 s were flagged out_of_view is shown sec_before_missing_out_of_view +
    drop_after after them (1.2 s), one lost in full view sec_before_missing + drop_after
    (0.8 s)."""

    def shown_until(flagged: bool) -> float:
        batches = []
        for k in range(91):  # 3 s at 30 Hz: walking for 1 s, then nobody
            t = k / 30
            people = (
                [
                    Detection(
                        x=1.0 + 0.5 * t,
                        y=0.0,
                        z=0.9,
                        height=1.7,
                        confidence=1.0,
                        out_of_view=flagged and t > 0.7,
                    )
                ]
                if t <= 1.0
                else []
            )
            batches.append(DetectionBatch(sensor_id="a", stamp=t, detections=people))
        times = [k / 100 for k in range(300)]
        params = TRACKING_PARAMS.create({"out_of_view_hold": "on"})
        result = replay(batches, times, Tracker(params))
        return max(t for t, out in zip(times, result.outputs, strict=True) if out.tracks)

    assert shown_until(False) == pytest.approx(1.0 + 0.8, abs=0.05)
    assert shown_until(True) == pytest.approx(1.0 + 1.2, abs=0.05)
