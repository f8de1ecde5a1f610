"""RealSense: an optional extra; without pyrealsense2 it explains itself in one sentence."""

from __future__ import annotations

import importlib.util

import pytest

from optrack.params import REGISTRY
from optrack.sensors import SensorError
from optrack.sensors.realsense import RealSenseSensor, attached_devices

HAS_PYREALSENSE2 = importlib.util.find_spec("pyrealsense2") is not None


@pytest.mark.skipif(HAS_PYREALSENSE2, reason="pyrealsense2 is installed")
def test_missing_pyrealsense2_is_one_sentence_with_the_install_command():
    with pytest.raises(SensorError) as caught:
        RealSenseSensor("817612070123")
    message = str(caught.value)
    assert "pyrealsense2" in message and ".venv/bin/pip install pyrealsense2" in message
    assert message.count(". ") == 0 and message.endswith(".")


@pytest.mark.skipif(not HAS_PYREALSENSE2, reason="pyrealsense2 is not installed")
def test_unknown_serial_lists_what_librealsense_sees():
    if any(d["serial"] == "000000000000" for d in attached_devices()):
        pytest.skip("a camera with that serial is attached")
    with pytest.raises(SensorError, match="no RealSense camera with serial '000000000000'"):
        RealSenseSensor("000000000000").open()


def test_realsense_parameters_are_registered():
    schema = REGISTRY["realsense"]
    for name in ("width", "height", "fps", "color", "infrared", "align", "reconnect_timeout"):
        assert name in schema


def test_pyrealsense2_is_not_a_pinned_dependency():
    import tomllib
    from pathlib import Path

    project = tomllib.loads((Path(__file__).parents[2] / "pyproject.toml").read_text())
    assert not any("realsense" in d for d in project["project"]["dependencies"])
