"""SimulatedSensor: one sensor of a simulated venue behind the Sensor interface, opened
by its sim:// URI from every entry point that takes a sensor URI."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from optrack.recording import Recording
from optrack.sensors import open_sensor, parse_uri
from optrack.sensors.base import Sensor, SensorError
from optrack.sim import Simulation
from optrack.sim.sensor import SimulatedSensor

#: A short simulated sensor rendered as fast as asked.
QUICK = "sim://crowd/0?realtime=false&seconds=0.2&id=cam"


def test_non_real_time_sensor_gives_every_frame_then_ends():
    sensor = SimulatedSensor("crowd", 0, seconds=0.5, real_time=False)
    assert isinstance(sensor, Sensor)
    with sensor:
        frames = list(sensor)
    assert len(frames) == Simulation("crowd", seconds=0.5).frame_count(0) >= 14
    assert [f.seq for f in frames] == list(range(len(frames)))
    assert sensor.read() is None
    stamps = np.array([f.timestamp for f in frames])
    assert np.median(np.diff(stamps)) == pytest.approx(1 / 30, abs=0.003)
    assert frames[0].depth.shape == (424, 512) and frames[0].infrared is not None


def test_real_time_sensor_delivers_frames_at_its_frame_rate():
    sensor = SimulatedSensor("distance", 0, seconds=0.6, sensor_model="sr4500")
    start = time.time()
    with sensor:
        frames = list(sensor)
    elapsed = time.time() - start
    assert 0.45 < elapsed < 1.5  # it waits for each frame, as a camera does
    stamps = np.array([f.timestamp for f in frames])
    assert abs(stamps[0] - start) < 1.0  # wall-clock stamps
    assert 4 <= len(frames) <= 8  # 13 fps for 0.6 s
    assert np.all(np.diff(stamps) > 1 / 13 * 0.5)


def test_simulated_sensor_matches_the_recorded_frames_of_the_same_seed():
    live = SimulatedSensor("mixed", 1, seed=2, seconds=0.2, real_time=False)
    sim = Simulation("mixed", seed=2, seconds=0.2)
    for n, frame in enumerate(live):
        state = sim.snapshot(sim.sensors[1].frame_time(n))
        expected = sim.frame(1, n, state)
        assert np.array_equal(frame.depth, expected.depth)
        assert frame.timestamp == expected.timestamp


def test_info_has_the_true_pose_and_truth_is_published():
    sensor = SimulatedSensor.from_uri("sim://mixed/2?seed=1&realtime=false&seconds=1&id=cam2")
    info = sensor.info
    assert info.id == "cam2" and info.uri.startswith("sim://mixed/2")
    assert np.array(info.world_T_camera)[2, 3] == pytest.approx(2.6)
    assert sensor.truth() is None
    frame = sensor.read()
    assert frame.sensor_id == "cam2"
    truth = sensor.truth()
    assert truth is not None and len(truth.people) >= 3
    assert abs(truth.t - Simulation("mixed", seed=1).sensors[2].frame_time(0)) < 1e-6


@pytest.mark.parametrize(
    ("uri", "message"),
    [
        ("sim://mixed", "sim://SCENARIO/N"),
        ("sim://mixed/7", "has 3 sensor"),
        ("sim://mixed/0?colour=red", "unknown option 'colour'"),
        ("sim://mixed/0?seed=abc", "seed must be a whole number"),
        ("sim://mixed/0?realtime=maybe", "true or false"),
        ("sim://nowhere/0", "unknown scenario"),
    ],
)
def test_bad_uris_say_what_is_wrong(uri, message):
    with pytest.raises((SensorError, ValueError), match=message):
        SimulatedSensor.from_uri(uri)


def test_open_sensor_opens_sim_uris():
    with open_sensor(QUICK) as sensor:
        assert isinstance(sensor, SimulatedSensor)
        frame = sensor.read()
    assert frame is not None and frame.sensor_id == "cam"


def test_sim_is_one_of_the_schemes_messages_name():
    with pytest.raises(SensorError, match=r"unknown scheme 'kinect'.*realsense://, sim://\."):
        parse_uri("kinect://0")
    with pytest.raises(SensorError, match=r"not a sensor URI.*or sim://SCENARIO/N\."):
        parse_uri("no-such-recording")


def _fresh(code: str, tmp_path: Path) -> subprocess.CompletedProcess:
    """``code`` run by a new interpreter (nothing imported yet: the scheme is registered
    only where the entry point itself does it)."""
    return subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
    )


ENTRY_POINTS = {
    "optrack detect": f"""
from optrack.cli import main
raise SystemExit(main(["detect", "{QUICK}", "--frames", "1", "--json"]))
""",
    "optrack record": f"""
from optrack.cli import main
raise SystemExit(main(["record", "--sensor", "{QUICK}", "--seconds", "2", "--out", "rec"]))
""",
    "detector node": f"""
import time
from optrack.runtime.config import load_node_config
from optrack.runtime.process import open_node_sensor
sensor = open_node_sensor("{QUICK}", load_node_config(None), time.monotonic)
print(json.dumps({{"sensor": type(sensor).__name__}}))
""",
    "site": f"""
from pathlib import Path
from optrack.runtime.config import load_node_config
from optrack.runtime.site import Site
site = Site(load_node_config(None, {{"site": {{"sensors": "{QUICK}"}}}}), headless=True)
children = site._children(["{QUICK}"], {{"detector": Path("d"), "tracker": Path("t")}})
print(json.dumps({{"sensor": children[0].name}}))
""",
}


@pytest.mark.parametrize("entry", list(ENTRY_POINTS))
def test_every_entry_point_opens_sim_uris_in_a_new_process(entry, tmp_path):
    done = _fresh("import json\n" + ENTRY_POINTS[entry], tmp_path)
    assert done.returncode == 0, done.stderr
    if entry == "optrack detect":
        assert json.loads(done.stdout)["frames"] == 1
    elif entry == "optrack record":
        assert Recording(tmp_path / "rec").sensor_ids == ["cam"]
    else:
        assert json.loads(done.stdout)["sensor"] in ("SimulatedSensor", "cam")


def test_a_new_process_without_the_simulator_names_the_schemes_it_has(tmp_path):
    code = f"""
from optrack.sensors import SensorError, parse_uri
try:
    parse_uri("{QUICK}")
except SensorError as error:
    print(error)
"""
    done = _fresh(code, tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == (
        f"sensor URI '{QUICK}' has an unknown scheme 'sim'; use one of file://, openni://, "
        "realsense://."
    )
