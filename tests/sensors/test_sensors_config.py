"""`optrack sensors` on a headless computer: the line of each sensor's configuration
(/etc/optrack/sensors/<name>.env for optrack-node@<name>, or site.sensors)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from optrack.sensors.cli import _add_config, _usb_name

REPO = Path(__file__).resolve().parents[2]
SIM = "sim://mixed/1?seconds=1&seed=3"


def optrack(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "optrack.cli", *args],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=REPO,
    )


def test_opened_sensors_come_with_their_service_files_line():
    done = optrack("sensors", "--sensor", "openni://Dummy", "--sensor", SIM, "--json")
    assert done.returncode == 0, done.stderr
    dummy, sim = json.loads(done.stdout)["sensors"]
    assert dummy["id"] == "openni-Dummy"
    assert dummy["config"] == {
        "name": "openni-dummy",
        "file": "/etc/optrack/sensors/openni-dummy.env",
        "line": "OPTRACK_SENSOR=openni://Dummy",
    }
    assert sim["id"] == "kinect2_1" and sim["config"]["line"] == f"OPTRACK_SENSOR={SIM}"


def test_the_text_names_the_file_the_service_and_the_site_key():
    done = optrack("sensors", "--sensor", "openni://Dummy")
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert "  /etc/optrack/sensors/openni-dummy.env: OPTRACK_SENSOR=openni://Dummy" in lines
    assert "then: sudo systemctl enable --now optrack-node@openni-dummy" in lines
    assert lines[-2:] == ["  site:", "    sensors: openni://Dummy"]


def test_a_sensor_that_does_not_open_is_one_sentence():
    done = optrack("sensors", "--sensor", "openni://NOSUCHSERIAL")
    assert done.returncode != 0
    assert "Traceback" not in done.stderr and "NOSUCHSERIAL" in done.stderr


def test_usb_cameras_are_named_by_model_and_serial_each_once():
    devices = [
        {"uri": "openni://A1", "model": "Kinect v1", "serial": "A1"},
        {"uri": "openni://A1?id=front", "model": "Kinect v1", "serial": "A1"},
        {"uri": "openni://", "model": "Xtion PRO Live", "serial": None},
        {"uri": "openni://", "model": "Xtion PRO Live", "serial": None},
        {"uri": "", "model": "Kinect v2 (no optrack backend)", "serial": None},
    ]
    _add_config(devices, _usb_name)
    names = [d["config"]["name"] if "config" in d else None for d in devices]
    assert names == ["kinect-v1-a1", "front", "xtion-pro-live", "xtion-pro-live-2", None]
