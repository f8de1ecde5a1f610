"""`optrack run` as a user runs it: a multi-process site on loopback whose UDP JSON, OSC and
WebSocket outputs test clients receive and parse; a killed detector node that restarts and
rejoins within 5 s while the tracker keeps tracking; Ctrl-C that stops everything."""

from __future__ import annotations

import json
import os
import signal
import time
from pathlib import Path

import pytest
from websockets.sync.client import connect

from optrack.net.messages import DetectionsMessage
from optrack.recording import Recording

from .conftest import VENUE_SECONDS, free_port
from .sites import RunningSite, venue_sensors

SENSORS = ("kinect2_0", "kinect2_1", "kinect2_2")


class Site(RunningSite):
    """A running `optrack run` on the venue's three sensors with every output, and the
    detections on its bus."""

    def __init__(self, venue, tmp_path) -> None:
        self.websocket_port = free_port()
        self.detections: list[tuple[float, str]] = []
        values = {
            "site": {
                "name": "sitetest",
                "sensors": venue_sensors(venue, SENSORS),
                "report_s": 2.0,
                "restart_delay_s": 0.2,
            },
            "node": {"state_dir": str(tmp_path / "state"), "status_period_s": 0.5},
            "outputs": {"websocket": f"127.0.0.1:{self.websocket_port}"},
        }
        super().__init__(tmp_path, values)
        self.bus.subscribe(
            self.bus.keys.detections(),
            DetectionsMessage,
            lambda m, k: self._add(self.detections, (time.time(), m.sender)),
        )


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


def test_every_node_runs_numpys_blas_on_one_thread(site):
    # The nodes are processes of their own: BLAS threads in each would spin against the
    # others (OPENBLAS_NUM_THREADS=1 unless the user set it).
    site.wait(lambda: "site" in site.statuses, 60, "no site status")
    values = site.statuses["site"].values
    pids = {k[4:]: int(v) for k, v in values.items() if k.startswith("pid.") and int(v) > 0}
    assert set(SENSORS) <= set(pids) and "tracker" in pids
    for name, pid in pids.items():
        environ = (Path("/proc") / str(pid) / "environ").read_bytes().split(b"\0")
        assert b"OPENBLAS_NUM_THREADS=1" in environ, name


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
