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
    clock.t += replay.length + replay.times[0] + 0.5 * replay.period
    frame = replay.read()
    assert frame.seq == count  # the first frame of the second loop
    assert frame.timestamp == pytest.approx(1000.0 + replay.length + replay.times[0])


def test_only_the_streams_asked_for_are_decoded(venue):
    replay = LiveReplay(venue, "kinect2_0", streams=("depth", "color"))
    frame = replay.read()
    assert frame.color is not None and frame.infrared is None


def test_a_recording_with_several_sensors_needs_one_named(venue):
    with pytest.raises(SensorError, match="name one"):
        LiveReplay(venue)
    with pytest.raises(SensorError, match="has no sensor 'cam9'"):
        LiveReplay(venue, "cam9")


def test_a_bounce_loop_plays_backwards_without_a_jump(venue):
    clock = FakeClock()
    replay = LiveReplay(venue, "kinect2_0", loop="bounce", clock=clock, streams=("depth",))
    replay.open()
    n = len(replay.entries)
    shown, stamps = [], []
    for k in range(2 * n + 3):  # a whole cycle and a bit: forwards, backwards, forwards
        clock.t = replay._due(k)
        frame = replay.read()
        shown.append(replay.cycle_index[frame.seq % len(replay.cycle_index)])
        stamps.append(frame.timestamp)
    assert shown[: n + 2] == [*range(n), n - 2, n - 3]
    assert max(abs(a - b) for a, b in zip(shown, shown[1:], strict=False)) == 1  # no jump
    assert all(b > a for a, b in zip(stamps, stamps[1:], strict=False))
    assert replay.skipped == 0


def test_locked_replays_of_one_recording_show_the_same_instant(venue):
    """Detector nodes started at different moments (and one whose clock is off by 0.25 s)
    replay their sensors at the same instant of the scene, in site time."""
    clock_a, clock_b = FakeClock(5000.0), FakeClock(5000.0 + 0.25)  # b's clock runs ahead
    a = LiveReplay(venue, "kinect2_0", loop="bounce", clock=clock_a, streams=("depth",))
    b = LiveReplay(venue, "kinect2_2", loop="bounce", clock=clock_b, streams=("depth",))
    a.lock_phase(0.0)
    clock_a.t += 0.6
    clock_b.t += 0.6
    b.lock_phase(-0.25)  # started 0.6 s later; site time = its clock - 0.25 s
    for _ in range(5):
        clock_a.t += 0.4
        clock_b.t += 0.4
        fa, fb = a.read(), b.read()
        scene_a = a.cycle_times[fa.seq % len(a.cycle_times)]
        scene_b = b.cycle_times[fb.seq % len(b.cycle_times)]
        # the same recording instant, to within a frame period (their frames interleave)
        assert abs(scene_a - scene_b) <= 1.5 * a.period
        assert fb.timestamp - 0.25 == pytest.approx(fa.timestamp, abs=1.5 * a.period)


def test_an_unknown_loop_mode_is_refused(venue):
    with pytest.raises(SensorError, match="loop must be one of"):
        LiveReplay(venue, "kinect2_0", loop="sideways")


def test_a_frame_already_too_old_is_skipped_for_the_next_one(venue):
    clock = FakeClock()
    replay = LiveReplay(venue, "kinect2_0", clock=clock, streams=("depth",))
    replay.max_age_s = 0.01
    replay.open()
    assert replay.read().seq == 0
    clock.t = replay._due(5) + 0.02  # the detector was busy: frame 5 became due 20 ms ago
    frame = replay.read()
    assert frame.seq == 6  # the next one, waited for (decoded meanwhile)
    assert frame.timestamp == pytest.approx(replay._due(6))
    assert replay.skipped == 5
    clock.t = replay._due(9) + 0.005  # 5 ms old: fresh enough
    assert replay.read().seq == 9


def test_paused_a_replay_holds_and_a_step_gives_the_next_frame(venue):
    clock = FakeClock()
    replay = LiveReplay(venue, "kinect2_0", clock=clock, streams=("depth",))
    replay.open()
    clock.t = replay._due(3)
    assert replay.read().seq == 3
    replay.pause()
    clock.t += 5.0  # paused time does not move the playhead
    assert replay.held and replay.playhead() == pytest.approx(replay.times[3], abs=1e-6)
    replay.step()
    assert not replay.held
    assert replay.read().seq == 4
    assert replay.held  # one frame a step
    with pytest.raises(SensorError, match="pause it before seeking"):
        LiveReplay(venue, "kinect2_0", clock=clock, streams=("depth",)).seek(1.0)


def test_a_seek_shows_a_lagging_replay_the_frame_at_the_new_playhead(venue):
    """A detector node busy with its first frame while its peers played on: pausing aligns
    every playhead on the furthest one, and the lagging node is then given the frame at
    that instant (not left showing its first), and the frame after it on the next step."""
    clock = FakeClock()
    replay = LiveReplay(venue, "kinect2_1", clock=clock, streams=("depth",))
    replay.open()
    assert replay.read().seq == 0
    clock.t += 1.2
    replay.pause()
    furthest = replay.times[30] + 0.1 * replay.period  # the peers' playhead
    replay.seek(furthest)
    assert not replay.held
    shown = replay.read()
    assert shown.seq == 30
    assert replay.held
    replay.step()
    assert replay.read().seq == 31


def test_a_seek_to_the_frame_already_shown_delivers_nothing_again(venue):
    clock = FakeClock()
    replay = LiveReplay(venue, "kinect2_2", clock=clock, streams=("depth",))
    replay.open()
    clock.t = replay._due(12) + 0.2 * replay.period
    assert replay.read().seq == 12
    replay.pause()
    replay.seek(replay.playhead())  # the furthest node: already at its playhead
    assert replay.held
    replay.step()
    assert replay.read().seq == 13
