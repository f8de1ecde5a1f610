"""The plain-Python site client against real nodes on a real Zenoh bus (loopback), no Qt."""

from __future__ import annotations

import queue
import socket
import threading
import time
from collections.abc import Callable
from typing import Any

import pytest

from optrack.client import EVENTS, SiteClient
from optrack.errors import UserError
from optrack.net import BUS_PARAMS, ParamsMessage, StatusMessage, TracksMessage
from optrack.outputs.streams import OUTPUTS_PARAMS
from optrack.runtime.config import NODE_PARAMS
from optrack.runtime.node import Node
from optrack.runtime.outputs_node import OutputsNode
from optrack.types import Track, TrackBatch

from .conftest import free_port


def wait_until(condition: Callable[[], Any], timeout: float = 10.0, step: float = 0.02) -> Any:
    """``condition()`` once it is true; fails the test after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        time.sleep(step)
    raise AssertionError(f"still false after {timeout:g} s: {condition}")


class Events:
    """Every event of a client, in the order it came."""

    def __init__(self, client: SiteClient) -> None:
        self.got: queue.Queue[tuple[str, tuple[Any, ...]]] = queue.Queue()
        self.seen: list[tuple[str, tuple[Any, ...]]] = []
        for event in EVENTS:
            client.on(event, lambda *args, event=event: self.got.put((event, args)))

    def next(self, event: str, timeout: float = 10.0) -> tuple[Any, ...]:
        """The arguments of the next ``event`` (others are kept in ``seen``)."""
        deadline = time.monotonic() + timeout
        while True:
            name, args = self.got.get(timeout=max(0.0, deadline - time.monotonic()))
            self.seen.append((name, args))
            if name == event:
                return args


@pytest.fixture
def site(hub, bus_params):
    """A client joined to the hub's site; its events recorded from the start."""
    client = SiteClient("test", bus_params, node="tool")
    events = Events(client)
    client.start()
    assert client.wait_connected(10.0)
    yield client, events
    client.close()


def test_joining_reports_the_site_and_tracks_arrive_by_callback_and_polling(hub, site):
    client, events = site
    assert events.next("connection") == ("Site 'test' on this computer",)
    assert events.next("log") == (
        "info",
        "Joined Site 'test' on this computer; waiting for its nodes.",
    )
    batch = TrackBatch(stamp=12.5, seq=3, tracks=[Track(4, 1.0, -2.0, 1.7, age=2.0)])
    wait_until(
        lambda: hub.publish(hub.keys.tracks, TracksMessage(batch=batch)) or client.latest_tracks
    )
    assert client.latest_tracks == batch
    assert events.next("tracks") == (batch,)


def test_statuses_stages_and_a_parameter_change_to_the_node_that_runs_the_stage(
    hub, site, make_client
):
    client, events = site
    detector = Node(make_client("door"), "door", NODE_PARAMS.create(), {"detection": _params()})
    detector.role = "detector"
    detector.state = "running"
    wait_until(lambda: detector.publish_status() or client.nodes_running("detection"))
    assert client.nodes_running("detection") == ["door"]
    assert client.detector_nodes() == ["door"]
    schemas, values = events.next("schemas")
    assert list(schemas) == ["detection"] and values["detection"]["voxel_size"] == 0.06
    assert list(client.schemas()) == ["detection"]
    node, status = events.next("status")
    assert node == "door" and status["role"] == "detector"
    assert client.statuses()["door"]["params"]["detection"]["voxel_size"] == 0.06

    client.set_params("detection", {"voxel_size": 0.08})
    wait_until(lambda: detector.apply_params())
    assert detector.live["detection"].voxel_size == 0.08
    assert detector.request.startswith("tool-")

    client.set_params("tracking", {"gate": 2.0})
    level, sentence = events.next("log")
    assert (level, sentence) == (
        "warning",
        "No node of Site 'test' on this computer runs the tracking stage yet; "
        "tracking.gate was not sent.",
    )
    detector.close()


def _params():
    from optrack.detection.params import detection_params

    params = detection_params(None)
    params.update({"voxel_size": 0.06})
    return params


def test_a_node_with_a_stage_of_another_version_is_one_warning(hub, site):
    client, _ = site
    said: list[tuple[str, str]] = []
    statuses: list[str] = []
    client.on("log", lambda level, sentence: said.append((level, sentence)))
    client.on("status", lambda node, values: statuses.append(node))
    status = StatusMessage(
        node="odd", role="detector", state="running", stamp=1.0, params={"warp": {"x": 1}}
    )
    wait_until(lambda: hub.publish(hub.keys.status("odd"), status) or statuses)
    hub.publish(hub.keys.status("odd"), status)
    wait_until(lambda: len(statuses) >= 2)
    assert said == [
        (
            "warning",
            "node odd runs stages this window does not know (warp); "
            "run the same optrack version everywhere.",
        )
    ]
    assert client.schemas() == {}  # nothing this optrack could build controls for


@pytest.fixture
def outputs(hub, make_client):
    """A real outputs node on the site (statuses every 0.1 s, a heartbeat every 0.05 s)."""
    node = OutputsNode(
        make_client("outputs"),
        NODE_PARAMS.create({"status_period_s": 0.1}),
        OUTPUTS_PARAMS.create({"udp": "", "heartbeat_s": 0.05}),
    )
    node.start_status()
    yield node
    node.stop()
    node.close()


@pytest.fixture
def receivers():
    """UDP sockets on free loopback ports: address -> socket."""
    opened: dict[str, socket.socket] = {}

    def make() -> str:
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.bind(("127.0.0.1", 0))
        s.settimeout(0.2)
        address = f"127.0.0.1:{s.getsockname()[1]}"
        opened[address] = s
        return address

    yield make, opened
    for s in opened.values():
        s.close()


def test_outputs_are_lists_of_destinations_added_removed_turned_off_and_on(
    site, outputs, receivers
):
    client, events = site
    make, sockets = receivers
    first, second = make(), make()
    wait_until(lambda: client.nodes_running("outputs"))
    client.add_output("udp", first)
    wait_until(lambda: client.outputs("udp") == [first])
    client.add_output("udp", second)
    wait_until(lambda: client.outputs("udp") == [first, second])
    assert outputs.outputs.params.udp == f"{first},{second}"  # the stage's own format
    assert sockets[second].recv(65536)  # the heartbeat reaches both
    assert sockets[first].recv(65536)

    # Turned off: the site stops it, the client still lists it (off), and turns it on again.
    client.enable_output("udp", first, False)
    wait_until(lambda: client.outputs("udp") == [second])
    off = wait_until(
        lambda: [d for d in client.destinations() if d["address"] == first and not d["enabled"]]
    )
    assert off == [{"kind": "udp", "address": first, "enabled": False, "sent": 0}]
    client.enable_output("udp", first, True)
    wait_until(lambda: client.outputs("udp") == [second, first])

    # The same destination written another way is still the one removed.
    client.remove_output("udp", first.replace("127.0.0.1", ""))
    wait_until(lambda: client.outputs("udp") == [second])
    # A turned-off destination is only forgotten: the site runs nothing else because of it.
    client.enable_output("udp", second, False)
    wait_until(lambda: client.outputs("udp") == [])
    client.remove_output("udp", second)
    wait_until(lambda: not [d for d in client.destinations() if d["address"] == second])

    # One WebSocket server: adding one replaces the other.
    port_a, port_b = free_port(), free_port()
    client.add_output("websocket", f"127.0.0.1:{port_a}")
    wait_until(lambda: client.outputs("websocket") == [f"127.0.0.1:{port_a}"])
    client.add_output("websocket", f"127.0.0.1:{port_b}")
    wait_until(lambda: client.outputs("websocket") == [f"127.0.0.1:{port_b}"])


def test_each_destination_has_its_packet_rate(site, outputs, receivers):
    client, events = site
    make, _ = receivers
    address = make()
    wait_until(lambda: client.nodes_running("outputs"))
    client.add_output("udp", address)

    def rate() -> float | None:
        for d in client.destinations():
            if d["address"] == address and d.get("packets_per_s"):
                return d["packets_per_s"]
        return None

    packets_per_s = wait_until(rate)
    assert 5.0 < packets_per_s < 60.0  # a heartbeat every 0.05 s: about 20 a second
    node, values = events.next("status")
    while node != "outputs" or not values["destinations"]:
        node, values = events.next("status")
    assert values["destinations"][0]["error"] == ""


def test_recording_commands_reach_every_detector_node_and_come_back(hub, site, make_client):
    client, events = site
    camera = Node(make_client("cam1"), "cam1", NODE_PARAMS.create(), {})
    camera.role = "detector"
    folders: list[str] = []

    def start(args: dict[str, Any]) -> dict[str, Any]:
        folders.append(args["folder"])
        return {"folder": args["folder"]}

    def stop(args: dict[str, Any]) -> dict[str, Any]:
        raise UserError("cam1 is not recording.")

    camera.add_command("record_start", start)
    camera.add_command("record_stop", stop)
    wait_until(lambda: camera.publish_status() or client.detector_nodes())
    worker = client.start_recording("/tmp/take")
    assert isinstance(worker, threading.Thread)
    worker.join(10.0)
    assert events.next("command_reply") == (
        "record_start",
        True,
        "",
        {"cam1": {"folder": "/tmp/take"}},
    )
    assert folders == ["/tmp/take"]
    client.stop_recording().join(10.0)
    action, ok, sentence, result = events.next("command_reply")
    assert (action, ok, result) == ("record_stop", False, {})
    assert "cam1 is not recording." in sentence
    camera.close()


def test_without_a_detector_node_a_command_is_refused_in_a_sentence(site):
    client, events = site
    client.playback("pause").join(10.0)
    action, ok, sentence, _ = events.next("command_reply")
    assert (action, ok) == ("pause", False)
    assert (
        sentence
        == "no detector node is running, so nothing can pause the playback; start the site first."
    )


def test_no_hub_is_one_sentence_and_nothing_is_sent():
    params = BUS_PARAMS.create({"local_port": free_port(), "connect_timeout_s": 0.5})
    client = SiteClient("test", params)
    events = Events(client)
    client.start()
    level, sentence = events.next("log")
    assert level == "error" and "cannot reach the local site's hub" in sentence
    assert not client.wait_connected(0.1)
    assert client.start_recording("/tmp/take") is None
    assert events.next("command_reply") == (
        "record_start",
        False,
        "Not connected to Site 'test' on this computer yet; try again shortly.",
        {},
    )
    client.close()


def test_an_unknown_event_is_refused():
    client = SiteClient("test", BUS_PARAMS.create())
    with pytest.raises(ValueError, match="unknown site event 'track'"):
        client.on("track", print)


def test_a_parameter_update_carries_the_clients_name(hub, site):
    client, events = site
    received: list[ParamsMessage] = []
    hub.subscribe(hub.keys.params("door"), ParamsMessage, lambda m, _: received.append(m))
    status = StatusMessage(
        node="door", role="detector", state="running", stamp=1.0, params={"detection": {}}
    )
    wait_until(
        lambda: hub.publish(hub.keys.status("door"), status) or client.nodes_running("detection")
    )
    wait_until(lambda: client.set_params("detection", {"voxel_size": 0.07}) or received)
    assert received[0].updates == {"detection": {"voxel_size": 0.07}}
    assert received[0].sender == "tool"


def test_held_events_keep_the_newest_batch_and_each_nodes_newest_status(hub, bus_params):
    """A client that delivers later (a window's thread): a flood of tracks and statuses
    wakes it once, and what it delivers is the newest batch and each node's newest status
    (with its running counts), every other event in order."""
    client = SiteClient("test", bus_params, node="tool")
    events = Events(client)
    wakes = []
    client.deliver_later(lambda: wakes.append(time.monotonic()))
    client.start()
    try:
        assert client.wait_connected(10.0)
        wait_until(lambda: wakes)  # the joining's connection and log
        client.deliver()
        assert [name for name, _ in [events.got.get(timeout=1) for _ in range(2)]] == [
            "connection",
            "log",
        ]
        wakes.clear()
        probe = TrackBatch(stamp=0.0, seq=0)  # until Zenoh routes the new subscription
        probe_message = TracksMessage(batch=probe)  # reliable, as every batch after it
        wait_until(lambda: hub.publish(hub.keys.tracks, probe_message, realtime=False) or wakes)
        last = 1000
        for seq in range(1, last + 1):
            batch = TrackBatch(stamp=float(seq), seq=seq, tracks=[Track(1, seq * 0.001, 0.0, 1.7)])
            hub.publish(hub.keys.tracks, TracksMessage(batch=batch), realtime=False)
            for node in ("door", "hall"):
                status = StatusMessage(
                    node=node, role="detector", state="running", stamp=seq, counters={"n": seq}
                )
                hub.publish(hub.keys.status(node), status, realtime=False)
        wait_until(lambda: client.latest_tracks is not None and client.latest_tracks.seq == last)
        wait_until(lambda: {s["counters"]["n"] for s in client.statuses().values()} == {last})
        assert len(wakes) == 1  # nothing delivered meanwhile: woken once
        assert events.got.empty()  # nothing called back before deliver()
        delivered = client.deliver()
        got = [events.got.get_nowait() for _ in range(delivered)]
        tracks = [args[0] for name, args in got if name == "tracks"]
        assert [batch.seq for batch in tracks] == [last]
        statuses = {args[0]: args[1] for name, args in got if name == "status"}
        assert {node: s["counters"]["n"] for node, s in statuses.items()} == {
            "door": last,
            "hall": last,
        }
        assert [name for name, _ in got].count("schemas") <= 1
        assert client.replaced >= 2 * last
        assert events.got.empty() and client.deliver() == 0
    finally:
        client.close()
