"""What each node of a running site accepts: recordings only inside the site's data folder,
detections only from sensors of the current calibration, a peer bus only with keys (or
--insecure, said in every status), the WebSocket output's origins and token as output
parameters."""

from __future__ import annotations

import logging
import threading
import time

import numpy as np
import pytest
import websockets.exceptions
import yaml
from websockets.sync.client import connect

from optrack.cli import main
from optrack.net.bus import Bus
from optrack.net.config import BUS_PARAMS
from optrack.net.messages import DetectionsMessage, StatusMessage
from optrack.outputs import OUTPUTS_PARAMS, Outputs
from optrack.runtime.calibration_store import CalibrationStore
from optrack.runtime.config import NODE_PARAMS
from optrack.runtime.node import CommandError, send_command
from optrack.runtime.tracker_node import TrackerNode
from optrack.types import (
    Detection,
    DetectionBatch,
    NetworkCalibration,
    SensorCalibration,
    as_matrix4,
)
from tests.runtime.conftest import free_port
from tests.runtime.sites import recording_detector


def node_config(tmp_path, bus: dict, outputs: dict | None = None, **node) -> str:
    """A node's configuration file: its bus, its state in ``tmp_path``, statuses 5 a second."""
    path = tmp_path / "node.yaml"
    values = {"bus": bus, "node": {"state_dir": str(tmp_path / "state"), "status_period_s": 0.2}}
    values["node"].update(node)
    if outputs:
        values["outputs"] = outputs
    path.write_text(yaml.safe_dump(values))
    return str(path)


def wait_until(condition, timeout=60.0):
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.05)


def test_a_record_start_outside_the_sites_data_folder_is_refused_and_counted(
    venue, hub, make_client, processes, tmp_path
):
    data = tmp_path / "data"
    client = make_client("operator")
    _, statuses = recording_detector(venue, hub, client, processes, tmp_path, data)
    for folder in (tmp_path / "elsewhere", data / ".." / "escaped"):
        with pytest.raises(CommandError, match="records only inside the site's data folder"):
            send_command(client, "kinect2_0", "record_start", {"folder": str(folder)}, timeout=10)
        assert not folder.exists()
    wait_until(lambda: statuses[-1].values.get("recording.refused") == 2)
    # Inside the data folder it records.
    result = send_command(
        client, "kinect2_0", "record_start", {"folder": str(data / "take")}, timeout=10
    )
    assert result["folder"] == str(data / "take")
    send_command(client, "kinect2_0", "record_stop", timeout=10)
    assert (data / "take").is_dir()


def person(sensor: str, x: float) -> DetectionsMessage:
    return DetectionsMessage(
        batch=DetectionBatch(sensor, time.time(), detections=[Detection(x, 0.5, 0.9, 1.75, 2.0)])
    )


def test_detections_from_a_sensor_outside_the_calibration_are_refused_and_counted(
    hub, make_client, tmp_path, caplog
):
    store = CalibrationStore(tmp_path / "tracker")
    store.save(
        NetworkCalibration(
            sensors={"cam0": SensorCalibration(world_T_camera=as_matrix4(np.eye(4)))}
        )
    )
    tracker = TrackerNode(hub, NODE_PARAMS.create({"status_period_s": 0.2}), store)
    thread = threading.Thread(target=tracker.run, daemon=True)
    thread.start()
    camera = make_client("cams")
    try:
        with caplog.at_level(logging.WARNING, logger="optrack.runtime.tracker"):
            deadline = time.monotonic() + 30
            x = 0.0
            while tracker.foreign < 5 or tracker.batches < 5:  # realtime puts may drop
                assert time.monotonic() < deadline, "timed out"
                camera.publish(camera.keys.detections("intruder"), person("intruder", 3.0))
                camera.publish(camera.keys.detections("cam0"), person("cam0", x))
                x += 0.02
                time.sleep(0.03)
        values = tracker.status().values
        assert values["foreign_sensor_batches"] == tracker.foreign >= 5
        assert values["batches"] == tracker.batches >= 5  # cam0's, used
        assert "hz.intruder" not in values and "hz.cam0" in values
        said = [r.getMessage() for r in caplog.records if "intruder" in r.getMessage()]
        assert said == [
            "detections of sensor 'intruder' are not used: the current calibration has no "
            "such sensor (it has: cam0); calibrate it to add it to the site. (further "
            "refusals from it are only counted)"
        ]
    finally:
        tracker.stop()
        thread.join(5)


def peer_config(tmp_path, port: int):
    links = {"listen": f"tcp/127.0.0.1:{port}", "multicast_scouting": False, "gossip": False}
    return node_config(tmp_path, {"mode": "peer", **links}, outputs={"udp": ""})


def insecure_observer(port: int) -> tuple[Bus, list[StatusMessage]]:
    """A peer without keys joined to the insecure site 'lab' on loopback ``port``, and the
    list every status it hears arrives in."""
    statuses: list[StatusMessage] = []
    links = {"connect": f"tcp/127.0.0.1:{port}", "multicast_scouting": False, "gossip": False}
    client = Bus(
        "lab",
        "observer",
        BUS_PARAMS.create({"mode": "peer", **links, "insecure": True, "connect_timeout_s": 60.0}),
    )
    client.subscribe(client.keys.status(), StatusMessage, lambda m, k: statuses.append(m))
    return client, statuses


def test_peer_mode_without_keys_refuses_to_start_and_insecure_says_so_in_every_status(
    tmp_path, capsys, processes
):
    port = free_port()
    config = peer_config(tmp_path, port)
    code = main(["node", "track", "--site", "lab", "--config", config])
    assert code == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("optrack node track: bus.mode peer without site keys")
    assert "--insecure" in err and len(err.splitlines()) == 1

    node = processes.start(
        ["optrack.cli", "node", "track", "--site", "lab", "--config", config, "--insecure"],
        "tracker",
    )
    client, statuses = insecure_observer(port)
    try:
        wait_until(
            lambda: {"tracker", "outputs"} <= {s.node for s in statuses} or node.poll() is not None,
            60,
        )
        assert node.poll() is None, processes.output(node)
        assert all(s.values["insecure"] is True for s in statuses)
    finally:
        client.close()


def test_an_insecure_peer_site_runs_its_nodes_on_the_hubs_transport_and_says_so(
    venue, tmp_path, processes
):
    """`optrack run --insecure` in peer mode without keys: the hub listens on plain tcp, so
    its nodes must join it without TLS (not with this computer's local keys), and every
    status, the launcher's included, says insecure."""
    port = free_port()
    config = tmp_path / "site.yaml"
    links = {"listen": f"tcp/127.0.0.1:{port}", "multicast_scouting": False, "gossip": False}
    config.write_text(
        yaml.safe_dump(
            {
                "site": {"name": "lab", "sensors": f"file://{venue}?loop=restart#kinect2_0"},
                "bus": {"mode": "peer", "local_port": port, **links},
                "node": {"state_dir": str(tmp_path / "state"), "status_period_s": 0.2},
                "outputs": {"udp": ""},
            }
        )
    )
    launcher = processes.start(
        ["optrack.cli", "run", "--headless", "--insecure", "--config", str(config)], "launcher"
    )
    client, statuses = insecure_observer(port)
    try:
        nodes = {"site", "tracker", "outputs", "kinect2_0"}
        heard = lambda: {s.node for s in statuses}  # noqa: E731
        wait_until(lambda: nodes <= heard() or launcher.poll() is not None, 120)
        assert nodes <= heard(), processes.output(launcher)[-3000:]
        assert all(s.values.get("insecure") is True for s in statuses)
        site = [s for s in statuses if s.node == "site"][-1]
        assert site.values["restarts.tracker"] == site.values["restarts.kinect2_0"] == 0
    finally:
        client.close()


def test_the_websocket_outputs_origins_and_token_are_output_parameters():
    outputs = Outputs(
        OUTPUTS_PARAMS.create(
            {
                "udp": "",
                "websocket": "127.0.0.1:0",
                "websocket_origins": "http://venue.example",
                "websocket_token": "s3cret",
            }
        )
    )
    try:
        url = f"ws://127.0.0.1:{outputs.websocket_port}/"
        with pytest.raises(websockets.exceptions.InvalidStatus):
            with connect(url + "?token=s3cret", origin="http://localhost", open_timeout=5):
                pass
        with pytest.raises(websockets.exceptions.InvalidStatus):
            with connect(url, origin="http://venue.example", open_timeout=5):
                pass
        with connect(url + "?token=s3cret", origin="http://venue.example", open_timeout=5):
            pass
        outputs.configure({"websocket_origins": "null,http://localhost", "websocket_token": ""})
        url = f"ws://127.0.0.1:{outputs.websocket_port}/"
        with connect(url, origin="http://localhost", open_timeout=5):
            pass
        (status,) = outputs.status()
        assert status.kind == "websocket"
    finally:
        outputs.close()


def test_the_nodes_and_window_of_an_insecure_peer_launcher_join_its_hub_without_keys(tmp_path):
    """What `optrack run --insecure` in peer mode writes for what it starts: every node and
    the window join its loopback hub as clients without TLS (the window presenting the
    file's bus.identity), and its own status says insecure."""
    from optrack.runtime.config import load_node_config
    from optrack.runtime.site import Site

    port = free_port()
    bus = {"mode": "peer", "listen": f"tcp/127.0.0.1:{port}", "local_port": port}
    bus |= {"multicast_scouting": False, "insecure": True, "identity": "op1"}
    site = Site(load_node_config(None, {"bus": bus, "site": {"name": "lab"}}), headless=False)
    site.host()
    try:
        configs = site._write_configs(tmp_path)
        joined = {role: yaml.safe_load(path.read_text())["bus"] for role, path in configs.items()}
        assert set(joined) == {"detector", "tracker", "skeleton", "gui"}
        for role, values in joined.items():
            assert values["mode"] == "client" and values["insecure"] is True, role
            assert values["connect"] == f"tcp/127.0.0.1:{port}" and not values["listen"], role
            assert values.get("identity") == ("op1" if role == "gui" else None), role
        assert site.status().values["insecure"] is True
    finally:
        site.hub.close()
    # A local site is never insecure: its nodes present this user's keys whatever the file.
    local = {"local_port": free_port(), "insecure": True}
    site = Site(load_node_config(None, {"bus": local, "site": {"name": "lab"}}), headless=False)
    site.host()
    try:
        configs = site._write_configs(tmp_path)
        assert "gui" not in configs  # the window reads the user's file, as before
        assert yaml.safe_load(configs["detector"].read_text())["bus"]["insecure"] is False
        assert "insecure" not in site.status().values
    finally:
        site.hub.close()
