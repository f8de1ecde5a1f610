"""A recording played as a live camera: real-time pace, the newest frame when behind
(skipped frames never decoded), capture-instant stamps on the node's clock, loops."""

from __future__ import annotations

import time

import pytest

from optrack.runtime.replay import LiveReplay
from optrack.sensors.base import SensorError


class FakeClock:
    """A clock the test moves by hand (sleeping advances it)."""

    def __init__(self, t: float = 1000.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


def test_frames_come_at_the_recorded_pace_stamped_when_due(venue):
    replay = LiveReplay(venue, "kinect2_0", streams=("depth",))
    replay.open()
    epoch = replay._epoch
    frames = [replay.read() for _ in range(4)]
    assert [f.seq for f in frames] == [0, 1, 2, 3]
    assert frames[3].timestamp - epoch == pytest.approx(replay.times[3], abs=1e-6)
    assert time.time() >= frames[3].timestamp
    assert replay.period == pytest.approx(1 / 30, rel=0.05)
    assert replay.skipped == 0


def test_a_consumer_that_falls_behind_gets_the_newest_frame(venue, monkeypatch):
    clock = FakeClock()
    replay = LiveReplay(venue, "kinect2_0", clock=clock, streams=("depth",))
    replay.open()
    first = replay.read()
    clock.t += 10.5 * replay.period  # busy for ten and a half frames
    loads = []
    original = replay.recording.load
    monkeypatch.setattr(
        replay.recording, "load", lambda *a, **k: loads.append(a[1].seq) or original(*a, **k)
    )
    second = replay.read()
    assert (first.seq, second.seq) == (0, 10)
    assert replay.skipped == 9
    assert loads == [10]  # the skipped frames were never decoded
    assert second.timestamp == pytest.approx(1000.0 + replay.times[10], abs=1e-6)


def test_without_loop_the_replay_ends(venue):
    clock = FakeClock()
    replay = LiveReplay(venue, "kinect2_1", clock=clock, streams=("depth",))
    replay.open()
    clock.t += replay.length + 1.0
    assert replay.read() is None


def test_with_loop_the_replay_goes_on_and_time_keeps_increasing(venue):
    clock = FakeClock()
    replay = LiveReplay(venue, "kinect2_1", loop=True, clock=clock, streams=("depth",))
    replay.open()
    count = len(replay.entries)
    clock.t += replay.length + 0.5 * replay.period
    frame = replay.read()
    assert frame.seq == count  # the first frame of the second loop
    assert frame.timestamp == pytest.approx(1000.0 + replay.length)


def test_only_the_streams_asked_for_are_decoded(venue):
    replay = LiveReplay(venue, "kinect2_0", streams=("depth", "color"))
    frame = replay.read()
    assert frame.color is not None and frame.infrared is None


def test_a_recording_with_several_sensors_needs_one_named(venue):
    with pytest.raises(SensorError, match="name one"):
        LiveReplay(venue)
    with pytest.raises(SensorError, match="has no sensor 'cam9'"):
        LiveReplay(venue, "cam9")
