"""Sensor URIs: parsing, options, errors, and the schemes that are not built yet."""

from __future__ import annotations

import importlib.util

import pytest

from optrack.params import load_config
from optrack.sensors import SensorError, open_sensor, parse_uri


def test_parse_splits_scheme_target_query_and_fragment():
    uri = parse_uri("file://recordings/s1?realtime=true&id=left#cam0")
    assert (uri.scheme, uri.target, uri.fragment) == ("file", "recordings/s1", "cam0")
    assert uri.options == {"realtime": "true", "id": "left"} and uri.sensor_id == "left"
    assert parse_uri("openni://1d27/0601@1/5").target == "1d27/0601@1/5"
    assert parse_uri("file:///abs/path").target == "/abs/path"
    assert parse_uri("OPENNI://Dummy").scheme == "openni"


def test_unknown_scheme_names_the_known_ones():
    with pytest.raises(SensorError, match="unknown scheme 'kinect'.*openni://, realsense://"):
        parse_uri("kinect://0")


def test_text_that_is_neither_uri_nor_recording_explains_the_forms(tmp_path):
    with pytest.raises(SensorError, match="not a sensor URI.*openni://Dummy"):
        parse_uri(str(tmp_path / "missing"))


def test_malformed_query_is_refused():
    with pytest.raises(SensorError, match="malformed query"):
        parse_uri("openni://Dummy?color")


def test_option_of_the_wrong_type_or_range_is_refused(single):
    with pytest.raises(SensorError, match="realtime must be true or false; got 'maybe'"):
        open_sensor(f"file://{single}?realtime=maybe")
    with pytest.raises(SensorError, match="playback.speed must be between"):
        open_sensor(f"file://{single}?speed=0")


def test_unknown_option_lists_the_schemes_parameters(single):
    with pytest.raises(SensorError, match="sets 'pace'.*it has: id, realtime, speed, loop"):
        open_sensor(f"file://{single}?pace=2")


def test_config_parameters_apply_and_the_uri_overrides_them(tmp_path, single):
    config_file = tmp_path / "site.yaml"
    config_file.write_text("playback:\n  loop: true\n  speed: 3.0\n", encoding="utf-8")
    config = load_config(config_file)
    with open_sensor(f"file://{single}?speed=2", config) as sensor:
        assert sensor.params.loop is True and sensor.params.speed == 2.0


def test_realsense_uri_without_pyrealsense2_says_how_to_install_it():
    if importlib.util.find_spec("pyrealsense2") is not None:
        pytest.skip("pyrealsense2 is installed")
    with pytest.raises(SensorError, match=r"pip install pyrealsense2"):
        open_sensor("realsense://817612070123")


def test_the_id_a_sensor_will_report_is_known_before_it_opens():
    """A site names each detector node by the id its sensor will report, so that the
    wizard and the simulated operator wait for the node that actually answers."""
    import optrack.sim.sensor  # noqa: F401 - registers sim://
    from optrack.sensors.uri import expected_sensor_id

    assert expected_sensor_id("sim://mixed/1") == "kinect2_1"
    assert expected_sensor_id("sim://mixed/0?sensors=2&model=kinect1") == "kinect1_0"
    assert expected_sensor_id("sim://mixed/0?id=cam0") == "cam0"
    assert expected_sensor_id("sim://mixed/99") is None  # no such sensor: only opening tells
    assert expected_sensor_id("file:///data/take#kinect2_0") == "kinect2_0"
    assert expected_sensor_id("openni://") is None  # a camera's id comes from its serial
    opened = optrack.sim.sensor.SimulatedSensor.from_uri("sim://mixed/1?realtime=false")
    assert opened.info.id == expected_sensor_id("sim://mixed/1")
