"""`optrack sensors` and `optrack record`, run as the user runs them (subprocesses)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from optrack.recording import Recording
from optrack.sensors import usb

REPO = Path(__file__).resolve().parents[2]


def optrack(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "optrack.cli", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=REPO,
    )


def test_sensors_json_lists_devices_as_one_object():
    done = optrack("sensors", "--json")
    assert done.returncode == 0, done.stderr
    payload = json.loads(done.stdout)  # exactly one JSON document
    assert isinstance(payload["devices"], list)
    for device in payload["devices"]:
        assert {"uri", "model", "vendor_id", "product_id", "serial", "access"} <= set(device)
        assert usb.lookup(int(device["vendor_id"], 16), int(device["product_id"], 16))
    if not Path("/dev/bus/usb").exists():
        assert payload["devices"] == []


def test_sensors_udev_rules_prints_the_shipped_file():
    done = optrack("sensors", "--udev-rules")
    assert done.returncode == 0
    assert done.stdout == (REPO / usb.UDEV_RULES_FILE).read_text(encoding="utf-8")


def test_record_dummy_for_three_seconds(tmp_path):
    out = tmp_path / "dummy"
    done = optrack(
        "record", "--sensor", "openni://Dummy", "--seconds", "3", "--out", str(out), "--json"
    )
    assert done.returncode == 0, done.stderr
    payload = json.loads(done.stdout)
    assert payload["frames"] >= 75
    assert payload["sensors"][0]["id"] == "openni-Dummy"
    assert payload["sensors"][0]["frames"] == payload["frames"]
    assert "recording 1.0/3 s: openni-Dummy" in done.stderr  # the progress line

    recording = Recording(out)
    assert recording.sensor_ids == ["openni-Dummy"]
    assert recording.count("openni-Dummy") == payload["frames"]
    assert recording.manifest.extra["frames"] == {"openni-Dummy": payload["frames"]}
    frames = list(recording.frames())
    assert frames[0].depth.shape == (240, 320) and frames[0].color.shape == (240, 320, 3)
    assert np.all(np.diff([f.timestamp for f in frames]) > 0)
    span = frames[-1].timestamp - frames[0].timestamp
    assert abs(span - (len(frames) - 1) / 30) < 0.05


def test_record_two_sources_counts_frames_per_sensor(tmp_path, recording):
    out = tmp_path / "two"
    done = optrack(
        "record",
        "--sensor", f"file://{recording}#a",
        "--sensor", "openni://Dummy?color=false&id=live",
        "--seconds", "1",
        "--out", str(out),
        "--json",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    payload = json.loads(done.stdout)
    per_sensor = {s["id"]: s["frames"] for s in payload["sensors"]}
    assert per_sensor["a"] == 10  # the whole recording, played as fast as it loads
    assert 20 <= per_sensor["live"] <= 32
    assert payload["frames"] == sum(per_sensor.values())
    assert Recording(out).count("live") == per_sensor["live"]


def test_record_with_an_unattached_camera_fails_in_one_line(tmp_path):
    done = optrack(
        "record", "--sensor", "openni://A00366", "--seconds", "1", "--out", str(tmp_path / "x")
    )
    assert done.returncode == 1
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "no OpenNI2 camera with serial or URI 'A00366'" in lines[0]
    assert done.stdout == ""
    assert not (tmp_path / "x").exists()


def test_record_refuses_two_sensors_with_the_same_id(tmp_path, recording):
    uri = f"file://{recording}#a"
    done = optrack(
        "record", "--sensor", uri, "--sensor", uri, "--seconds", "1", "--out", str(tmp_path / "x")
    )
    assert done.returncode == 1
    assert "two sensors have the id 'a'" in done.stderr
