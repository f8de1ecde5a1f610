"""Recordings played back as sensors (file:// URIs)."""

from __future__ import annotations

import time

import numpy as np
import pytest

from optrack.sensors import SensorError, open_sensor
from optrack.sensors.playback import PLAYBACK_PARAMS, PlaybackSensor


def test_playback_gives_one_sensors_frames_in_time_order_then_ends(recording):
    with open_sensor(f"file://{recording}#b") as sensor:
        frames = list(sensor)
        assert sensor.read() is None
    assert [f.sensor_id for f in frames] == ["b"] * 10
    assert [int(f.depth[0, 0]) for f in frames] == list(range(1000, 1010))
    stamps = [f.timestamp for f in frames]
    assert stamps == sorted(stamps) and stamps[0] == pytest.approx(100.01)
    assert abs(int(frames[3].color[..., 1].mean()) - 30) <= 2  # JPEG: nearly the value written
    assert frames[3].color[..., 0].max() <= 2


def test_single_sensor_recording_needs_no_fragment_and_a_bare_path_works(single):
    with open_sensor(str(single)) as sensor:
        assert sensor.info.id == "cam" and sensor.info.uri == f"file://{single}"
        assert sum(1 for _ in sensor) == 6


def test_recording_with_several_sensors_asks_to_name_one(recording):
    with pytest.raises(SensorError, match=r"has sensors a, b; name one, e\.g\. file://.*#a"):
        open_sensor(f"file://{recording}")


def test_unknown_sensor_lists_the_recordings_sensors(recording):
    with pytest.raises(SensorError, match="has no sensor 'c' .*it has: a, b"):
        open_sensor(f"file://{recording}#c")


def test_missing_recording_is_one_sentence(tmp_path):
    with pytest.raises(SensorError, match="does not exist"):
        open_sensor(f"file://{tmp_path}/nothing")


def test_id_option_renames_the_played_sensor(recording):
    with open_sensor(f"file://{recording}?id=left#a") as sensor:
        assert sensor.info.id == "left"
        assert sensor.read().sensor_id == "left"


def test_realtime_playback_takes_the_recorded_time(single):
    with open_sensor(f"file://{single}?realtime=true&speed=2") as sensor:
        started = time.monotonic()
        count = sum(1 for _ in sensor)
        elapsed = time.monotonic() - started
    assert count == 6
    assert elapsed == pytest.approx(0.5 / 2, abs=0.1)  # 5 periods of 0.1 s at twice the pace


def test_looping_playback_keeps_times_increasing(single):
    params = PLAYBACK_PARAMS.create({"loop": True})
    sensor = PlaybackSensor(single, params=params)
    stamps = [sensor.read().timestamp for _ in range(14)]
    assert np.all(np.diff(stamps) > 0)
    np.testing.assert_allclose(np.diff(stamps), 0.1, atol=1e-6)
