"""`optrack run` as a user runs it: a multi-process site on loopback whose UDP JSON, OSC and
WebSocket outputs test clients receive and parse; a killed detector node that restarts and
rejoins within 5 s while the tracker keeps tracking; Ctrl-C that stops everything."""

from __future__ import annotations

import json
import os
import signal
import socket
import threading
import time

import pytest
import yaml
from pythonosc.dispatcher import Dispatcher
from pythonosc.osc_server import ThreadingOSCUDPServer
from websockets.sync.client import connect

from optrack.net.bus import Bus
from optrack.net.config import BUS_PARAMS
from optrack.net.messages import DetectionsMessage, StatusMessage
from optrack.recording import Recording

from .conftest import VENUE_SECONDS, Processes, free_port

SENSORS = ("kinect2_0", "kinect2_1", "kinect2_2")


class Site:
    """A running `optrack run` and the clients listening to it."""

    def __init__(self, venue, tmp_path) -> None:
        self.udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.udp.bind(("127.0.0.1", 0))
        self.lock = threading.Lock()
        self.datagrams: list[tuple[float, bytes]] = []
        self.osc: list[tuple[float, str, tuple]] = []
        self.detections: list[tuple[float, str]] = []
        self.statuses: dict[str, StatusMessage] = {}
        dispatcher = Dispatcher()
        dispatcher.set_default_handler(
            lambda address, *args: self._add(self.osc, (time.time(), address, args))
        )
        self.osc_server = ThreadingOSCUDPServer(("127.0.0.1", 0), dispatcher)
        self.port = free_port()
        self.websocket_port = free_port()
        uris = ",".join(f"file://{venue}?loop=bounce#{s}" for s in SENSORS)
        config = tmp_path / "site.yaml"
        config.write_text(
            yaml.safe_dump(
                {
                    "bus": {"local_port": self.port},
                    "site": {
                        "name": "sitetest",
                        "sensors": uris,
                        "report_s": 2.0,
                        "restart_delay_s": 0.2,
                    },
                    "node": {"state_dir": str(tmp_path / "state"), "status_period_s": 0.5},
                    "outputs": {
                        "osc": f"127.0.0.1:{self.osc_server.server_address[1]}",
                        "websocket": f"127.0.0.1:{self.websocket_port}",
                    },
                }
            )
        )
        self.processes = Processes(tmp_path)
        self.launcher = self.processes.start(
            [
                "optrack.cli",
                "run",
                "--headless",
                "--seconds",
                "240",
                "--config",
                str(config),
                "--udp",
                f"127.0.0.1:{self.udp.getsockname()[1]}",
            ],
            "launcher",
        )
        self._stop = threading.Event()
        self._threads = [
            threading.Thread(target=self._receive, daemon=True),
            threading.Thread(target=self.osc_server.serve_forever, daemon=True),
        ]
        for thread in self._threads:
            thread.start()
        self.bus = Bus(
            "sitetest",
            "observer",
            BUS_PARAMS.create({"local_port": self.port, "connect_timeout_s": 120.0}),
        )
        self.bus.subscribe(
            self.bus.keys.detections(),
            DetectionsMessage,
            lambda m, k: self._add(self.detections, (time.time(), m.sender)),
        )
        self.bus.subscribe(self.bus.keys.status(), StatusMessage, self._on_status)

    def _add(self, where: list, item) -> None:
        with self.lock:
            where.append(item)

    def _on_status(self, message: StatusMessage, key: str) -> None:
        with self.lock:
            self.statuses[message.node] = message

    def _receive(self) -> None:
        self.udp.settimeout(0.2)
        while not self._stop.is_set():
            try:
                data = self.udp.recv(65536)
            except TimeoutError:
                continue
            except OSError:
                return
            self._add(self.datagrams, (time.time(), data))

    def documents(self, since: float = 0.0) -> list[tuple[float, dict]]:
        with self.lock:
            return [(t, json.loads(d)) for t, d in self.datagrams if t >= since]

    def wait(self, predicate, timeout: float, what: str) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            assert self.launcher.poll() is None, self.processes.output(self.launcher)[-3000:]
            if predicate():
                return
            time.sleep(0.05)
        raise AssertionError(
            f"{what} within {timeout} s\n{self.processes.output(self.launcher)[-3000:]}"
        )

    def close(self) -> None:
        self._stop.set()
        self.processes.stop_all()
        self.bus.close()
        self.osc_server.shutdown()
        self.osc_server.server_close()
        self.udp.close()


@pytest.fixture(scope="module")
def site(venue, tmp_path_factory):
    running = Site(venue, tmp_path_factory.mktemp("site"))
    try:
        running.wait(
            lambda: any(doc.get("tracks") for _, doc in running.documents()),
            timeout=120,
            what="no tracks on UDP",
        )
        yield running
    finally:
        running.close()


def test_udp_clients_parse_openptrack_json_with_tracks_and_heartbeats(site):
    site.wait(lambda: len(site.documents()) >= 20, 30, "fewer than 20 datagrams")
    with site.lock:
        raw = [d for _, d in site.datagrams]
    assert not any(d.endswith(b"\x00") for d in raw)
    documents = [json.loads(d) for d in raw]
    frames = [d for d in documents if d["header"]["frame_id"] == "world"]
    beats = [d for d in documents if d["header"]["frame_id"] == "heartbeat"]
    assert beats and frames
    with_tracks = [f for f in frames if f["tracks"]]
    assert with_tracks
    assert set(with_tracks[-1]["tracks"][0]) == {"id", "x", "y", "height", "age", "confidence"}
    assert {"alive_IDs", "max_ID"} <= set(beats[-1])


def test_osc_clients_receive_frame_bundles(site):
    site.wait(lambda: any(a == "/optrack/track" for _, a, _ in site.osc), 30, "no /optrack/track")
    with site.lock:
        messages = list(site.osc)
    addresses = {a for _, a, _ in messages}
    assert {"/optrack/frame", "/optrack/track", "/optrack/alive"} <= addresses
    track = next(args for _, a, args in messages if a == "/optrack/track")
    assert isinstance(track[0], int) and len(track) == 4


def test_websocket_clients_receive_the_same_json(site):
    with connect(f"ws://127.0.0.1:{site.websocket_port}", proxy=None, open_timeout=30) as client:
        documents = [json.loads(client.recv(timeout=10)) for _ in range(10)]
    kinds = {d["header"]["frame_id"] for d in documents}
    assert kinds <= {"world", "heartbeat"} and "world" in kinds


def test_the_site_shows_about_as_many_tracks_as_there_are_people(site, venue):
    """Three sensors replayed as live cameras, each detector dropping frames it cannot keep
    up with, looped through several turns: one track per person, not one per sensor or
    per loop (at most one spare, for a person being handed over)."""
    people = max(len(instant.people) for instant in Recording(venue).ground_truth())
    site.wait(lambda: len(site.documents()) >= 5, 30, "no datagrams")
    start = min(t for t, d in site.documents() if d.get("tracks")) + 2.0  # tracks confirmed
    cycle = 2 * VENUE_SECONDS  # forwards and backwards
    site.wait(lambda: site.documents()[-1][0] > start + 2 * cycle, 60, "too few loops")
    counts = [
        len(d["tracks"])
        for t, d in site.documents(since=start)
        if d["header"]["frame_id"] == "world"
    ]
    assert len(counts) > 20
    print(f"{people} people; tracks per frame: max {max(counts)}, counts {sorted(set(counts))}")
    assert max(counts) <= people + 1


def test_a_killed_detector_restarts_within_5s_while_the_tracker_keeps_tracking(site):
    site.wait(
        lambda: (
            all(s in site.statuses and site.statuses[s].fps > 0 for s in SENSORS)
            and "site" in site.statuses
        ),
        60,
        "not every detector running",
    )
    victim = "kinect2_1"
    old_pid = int(site.statuses["site"].values[f"pid.{victim}"])
    os.kill(old_pid, signal.SIGKILL)
    killed = time.time()

    def rejoined() -> bool:
        with site.lock:
            return any(t > killed + 0.2 and s == victim for t, s in site.detections)

    site.wait(rejoined, 30, f"{victim} did not publish detections again")
    with site.lock:
        back = min(t for t, s in site.detections if t > killed + 0.2 and s == victim)
        others = [t for t, s in site.detections if killed < t < back and s != victim]
    site.wait(
        lambda: int(site.statuses["site"].values.get(f"restarts.{victim}", 0)) >= 1,
        5,
        "the site status does not report the restart",
    )
    assert int(site.statuses["site"].values[f"pid.{victim}"]) != old_pid
    print(f"{victim} killed, rejoined the bus {back - killed:.2f} s later")
    assert back - killed <= 5.0
    # Meanwhile the other detectors went on and the tracker kept publishing tracks.
    assert len(others) > 10
    frames = [d for t, d in site.documents(since=killed) if t < back and d.get("tracks")]
    assert frames, "no tracks while the detector was down"


def test_ctrl_c_stops_every_node_and_the_launcher_exits_cleanly(site):
    pids = [int(v) for k, v in site.statuses["site"].values.items() if k.startswith("pid.")]
    site.launcher.send_signal(signal.SIGINT)
    assert site.launcher.wait(30) == 0
    output = site.processes.output(site.launcher)
    assert "stopping the site" in output
    assert "Traceback" not in output
    for pid in pids:
        assert not os.path.exists(f"/proc/{pid}") or _zombie(pid)


def _zombie(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().split()[2] == "Z"
    except FileNotFoundError:
        return True
