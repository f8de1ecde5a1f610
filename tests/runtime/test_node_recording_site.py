"""`optrack run --recording PATH`: a recording played through a whole site, headless (real
node processes on a loopback hub)."""

from __future__ import annotations

import os
import re
import signal
import time

import yaml

from optrack.cli import main
from optrack.recording import Recording
from optrack.runtime.node import send_command

from .conftest import free_port
from .sites import recording_detector


def test_optrack_run_plays_a_recording_on_every_sensor_and_stops_at_its_end(
    venue, processes, tmp_path
):
    config = tmp_path / "site.yaml"
    config.write_text(
        yaml.safe_dump(
            {
                "bus": {"local_port": free_port()},
                "site": {"name": "playtest", "report_s": 1.0},
                "node": {"state_dir": str(tmp_path / "state")},
                "outputs": {"udp": ""},
            }
        )
    )
    args = ["optrack.cli", "run", "--headless", "--config", str(config)]
    launcher = processes.start([*args, "--recording", str(venue), "--speed", "0.5"], "launcher")
    assert launcher.wait(240) == 0
    out = processes.output(launcher)
    assert f"playing {venue} on 3 sensor(s)" in out  # resumed together once all answered
    assert f"the recording {venue} has played to its end; stopping." in out
    processed = re.findall(r"the sensor has no more frames after (\d+)", out)
    assert len(processed) == 3 and all(int(n) > 0 for n in processed)


def test_a_playback_speed_out_of_range_is_one_sentence(tmp_path, capsys):
    code = main(["run", "--headless", "--recording", str(tmp_path), "--speed", "10"])
    assert code == 1
    assert capsys.readouterr().err.strip() == (
        "optrack run: --speed must be between 0.25 and 4; got 10."
    )


def test_a_node_killed_while_recording_leaves_every_frame_it_wrote_readable(
    venue, hub, make_client, processes, tmp_path
):
    client = make_client("observer")
    node, statuses = recording_detector(venue, hub, client, processes, tmp_path, tmp_path)
    deadline = time.monotonic() + 120
    take = tmp_path / "take"
    send_command(client, "kinect2_0", "record_start", {"folder": str(take)}, timeout=10)
    while time.monotonic() < deadline:
        if statuses and int(statuses[-1].values.get("recording.frames", 0)) >= 3:
            break
        time.sleep(0.05)
    seen = int(statuses[-1].values["recording.frames"])
    assert seen >= 3, processes.output(node)
    os.kill(node.pid, signal.SIGKILL)  # no chance to close anything
    node.wait(10)
    recording = Recording(take)
    assert recording.sensor_ids == ["kinect2_0"]
    assert recording.count("kinect2_0") >= seen
    frames = list(recording.frames())
    assert len(frames) == recording.count("kinect2_0")
