"""Recording and playback on detector nodes, driven by bus commands over loopback: real
nodes on a real Zenoh hub, replaying the simulated venue; a recording reads back."""

from __future__ import annotations

import subprocess
import threading
import time
from pathlib import Path

import pytest

from optrack.detection.params import detection_params
from optrack.net.clock import CLOCK_PARAMS, ClockServer, ClockSync
from optrack.recording import Recording
from optrack.runtime.calibration_store import CalibrationStore
from optrack.runtime.config import NODE_PARAMS
from optrack.runtime.detector_node import DetectorNode
from optrack.runtime.node import CommandError, send_command
from optrack.runtime.node_recording import RecordingCommandError, SiteControl
from optrack.runtime.replay import LiveReplay
from optrack.types import DetectionBatch

SENSORS = ("kinect2_0", "kinect2_1")


class NobodyHere:
    """A detector that finds nobody: the node then keeps the replay's pace, so rates measure
    the playback and not the detector on a busy computer."""

    def process(self, frame):
        return DetectionBatch(sensor_id=frame.sensor_id, stamp=frame.timestamp)


def nobody(info, world_T_camera, params):
    return NobodyHere()


@pytest.fixture
def site(venue, hub, make_client, tmp_path):
    """Start detector nodes (in threads) replaying sensors of the venue."""
    ClockServer(hub)
    started: list[tuple[DetectorNode, threading.Thread]] = []

    def start(sensors=SENSORS, paused=True, loop="restart") -> dict[str, DetectorNode]:
        nodes = {}
        for sensor in sensors:
            bus = make_client(sensor)
            replay = LiveReplay(venue, sensor, loop=loop, paused=paused)
            replay.open()
            sync = ClockSync(bus, CLOCK_PARAMS.create())
            node = DetectorNode(
                bus,
                replay,
                detection_params("kinect2"),
                NODE_PARAMS.create(
                    {"preview_hz": 0.0, "status_period_s": 0.2, "data_folder": str(tmp_path)}
                ),
                sync,
                CalibrationStore(tmp_path / "state" / sensor),
                factory=nobody,
            )
            replay.streams = ("depth",)  # only what the tests look at
            thread = threading.Thread(target=node.run, daemon=True)
            thread.start()
            started.append((node, thread))
            nodes[sensor] = node
        time.sleep(0.3)  # the nodes' queryables reach the hub
        return nodes

    yield start
    for node, _ in started:
        node.stop()
    for _, thread in started:
        thread.join(10)


@pytest.fixture
def control(make_client) -> SiteControl:
    return SiteControl(make_client("gui"))


def wait_until(predicate, timeout: float = 5.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError("not reached in time")
        time.sleep(0.02)


def frames(nodes) -> dict[str, int]:
    return {name: node.frames for name, node in nodes.items()}


def test_pause_holds_every_sensor_and_a_step_gives_exactly_one_frame_each(site, control):
    nodes = site()
    time.sleep(0.5)
    assert sum(frames(nodes).values()) == 0  # started paused: nothing until resumed
    control.playback(nodes, "resume")
    wait_until(lambda: min(frames(nodes).values()) >= 10)
    paused = control.playback(nodes, "pause")
    assert all(state["paused"] for state in paused.values())
    assert len({round(s["played_s"], 6) for s in paused.values()}) == 1  # aligned playheads
    time.sleep(0.3)  # a frame already due when the pause came is still delivered
    held = frames(nodes)
    time.sleep(1.0)
    assert frames(nodes) == held  # paused: no new frame in 1 s
    control.playback(nodes, "step")
    wait_until(lambda: all(n.frames == held[k] + 1 for k, n in nodes.items()))
    time.sleep(0.5)
    assert frames(nodes) == {k: v + 1 for k, v in held.items()}  # exactly one per sensor
    # Each sensor gave its first frame after the common playhead (the simulated sensors,
    # like real ones, are not triggered together: their frames are a few ms apart).
    playhead = next(iter(paused.values()))["played_s"]
    period = max(node.sensor.period for node in nodes.values())
    stepped = control.playback(nodes, "state")
    assert all(playhead < s["played_s"] <= playhead + 1.2 * period for s in stepped.values())
    control.playback(nodes, "resume")
    wait_until(lambda: all(n.frames > held[k] + 5 for k, n in nodes.items()))


def test_twice_the_speed_gives_twice_the_frame_rate(site, control):
    """The rate of recorded frames played (sequence numbers per second, what a camera's
    frame rate is); frames a busy computer could not process are skipped, not slowed."""
    nodes = site(sensors=("kinect2_0",))
    node = nodes["kinect2_0"]

    def rate(seconds: float = 1.5) -> float:
        time.sleep(0.3)  # the new pace settles
        before, started = node.playback.last_frame, time.monotonic()
        time.sleep(seconds)
        return (node.playback.last_frame - before) / (time.monotonic() - started)

    control.playback(nodes, "resume")
    normal = rate()
    control.playback(nodes, "speed", value=2.0)
    double = rate()
    assert normal == pytest.approx(1 / node.sensor.period, rel=0.15)
    assert double / normal == pytest.approx(2.0, rel=0.15)
    assert node.status().values["playback.speed"] == 2.0


def test_a_recording_of_two_nodes_reads_back_as_one_take(site, control, tmp_path):
    nodes = site(paused=False)
    take = tmp_path / "take"
    started = control.start_recording(nodes, str(take))
    assert sorted(started) == list(SENSORS)
    wait_until(lambda: all(n.recorder.frames >= 3 for n in nodes.values()))
    during = Recording(take)  # readable while it is written (a crash loses nothing written)
    assert sorted(during.sensor_ids) == list(SENSORS)
    assert all(during.count(s) >= 3 for s in SENSORS)
    time.sleep(0.5)
    stopped = control.stop_recording(nodes)
    # A node answers within recorder.stop_wait_s; a busy disk may still be writing what was
    # queued, and the node's status gives the final count once closed.
    wait_until(lambda: all(n.recorder.result()["closed"] for n in nodes.values()), 20)
    recording = Recording(take)
    assert sorted(recording.sensor_ids) == list(SENSORS)
    for sensor, node in nodes.items():
        count = recording.count(sensor)
        assert 3 <= stopped[sensor]["frames"] <= count
        assert node.status().values["recording.frames"] == count
        assert node.status().values["recording"] is False
        stamps = [entry.t for entry in recording.index(sensor)]
        assert stamps == sorted(stamps)
        assert node.status().values["recording.seconds"] == pytest.approx(stamps[-1] - stamps[0])
    assert recording.manifest.extra["frames"] == {s: recording.count(s) for s in SENSORS}
    frame = next(recording.frames())
    assert frame.depth.shape == (424, 512)


def test_refusals_and_silence_come_back_as_sentences(site, control, tmp_path):
    nodes = site(sensors=("kinect2_0",))
    a_file = tmp_path / "notes.txt"
    a_file.write_text("not a folder")
    with pytest.raises(RecordingCommandError, match="is a file, not a recording directory"):
        control.start_recording(nodes, str(a_file))
    take = tmp_path / "take"
    control.start_recording(nodes, str(take))
    with pytest.raises(RecordingCommandError, match="already recording into"):
        control.start_recording(nodes, str(tmp_path / "other"))
    control.stop_recording(nodes)
    with pytest.raises(RecordingCommandError, match="already holds a recording of sensor"):
        control.start_recording(nodes, str(take))
    with pytest.raises(RecordingCommandError, match="between 0.25x and 4x"):
        control.playback(nodes, "speed", value=10.0)
    control.playback(nodes, "resume")
    with pytest.raises(RecordingCommandError, match="pause it before stepping"):
        control.playback(nodes, "step")
    with pytest.raises(CommandError, match="node 'camera9' did not answer"):
        send_command(control.bus, "camera9", "record_start", {"folder": str(take)}, timeout=0.3)
    with pytest.raises(RecordingCommandError, match="no detector node is running"):
        control.start_recording([], str(take))


@pytest.fixture
def small_disk(tmp_path) -> Path:
    """A 1 MB tmpfs (needs the right to mount, as root in a container has)."""
    mount = tmp_path / "small-disk"
    mount.mkdir()
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(mount)], capture_output=True
    )
    if done.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs to fill ({done.stderr.decode().strip()})")
    yield mount
    subprocess.run(["umount", "-l", str(mount)], check=False)


def test_a_full_disk_stops_the_recording_with_a_sentence_and_keeps_what_was_written(
    site, control, small_disk
):
    nodes = site(sensors=("kinect2_0",), paused=False)
    node = nodes["kinect2_0"]
    take = small_disk / "take"
    control.start_recording(nodes, str(take))
    wait_until(lambda: node.recorder.result()["closed"] and node.recorder.error != "")
    assert "is full" in node.recorder.error and "Free space" in node.recorder.error
    assert node.status().values["recording"] is False
    assert node.last_error == node.recorder.error
    written = node.recorder.frames
    assert written >= 1
    assert Recording(take).count("kinect2_0") == written
