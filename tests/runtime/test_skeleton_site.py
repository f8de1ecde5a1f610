"""`optrack run --skeleton` as a user runs it: the simulated venue's site with the skeleton
stage on; skeletons of the tracked people arrive over UDP (OpenPTrack v2's pose message)
and OSC on loopback, and the skeleton node reports on the bus."""

from __future__ import annotations

import json
import socket
import threading
import time

import yaml
from pythonosc.dispatcher import Dispatcher
from pythonosc.osc_server import ThreadingOSCUDPServer

from optrack.net.bus import Bus
from optrack.net.config import BUS_PARAMS
from optrack.net.messages import StatusMessage

from .conftest import Processes, free_port

SENSORS = ("kinect2_0", "kinect2_1")


def test_a_site_with_skeletons_sends_them_over_udp_and_osc(venue, tmp_path):
    lock = threading.Lock()
    documents: list[dict] = []
    osc: list[tuple[str, tuple]] = []
    statuses: dict[str, StatusMessage] = {}
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    udp.bind(("127.0.0.1", 0))
    udp.settimeout(0.2)
    dispatcher = Dispatcher()
    dispatcher.set_default_handler(lambda address, *args: osc.append((address, args)))
    osc_server = ThreadingOSCUDPServer(("127.0.0.1", 0), dispatcher)
    stop = threading.Event()

    def receive() -> None:
        while not stop.is_set():
            try:
                data = udp.recv(65536)
            except TimeoutError:
                continue
            except OSError:
                return
            with lock:
                documents.append(json.loads(data))

    port = free_port()
    config = tmp_path / "site.yaml"
    config.write_text(
        yaml.safe_dump(
            {
                "bus": {"local_port": port},
                "site": {
                    "name": "skeletonsite",
                    "sensors": ",".join(f"file://{venue}?loop=bounce#{s}" for s in SENSORS),
                    "report_s": 2.0,
                },
                "node": {"state_dir": str(tmp_path / "state"), "status_period_s": 0.5},
                "outputs": {"osc": f"127.0.0.1:{osc_server.server_address[1]}"},
                "skeleton": {"particles": 200, "init_layers": 6},
            }
        )
    )
    processes = Processes(tmp_path)
    launcher = processes.start(
        [
            "optrack.cli",
            "run",
            "--headless",
            "--skeleton",
            "--seconds",
            "240",
            "--config",
            str(config),
            "--udp",
            f"127.0.0.1:{udp.getsockname()[1]}",
        ],
        "launcher",
    )
    threads = [
        threading.Thread(target=receive, daemon=True),
        threading.Thread(target=osc_server.serve_forever, daemon=True),
    ]
    for thread in threads:
        thread.start()
    bus = Bus(
        "skeletonsite",
        "observer",
        BUS_PARAMS.create({"local_port": port, "connect_timeout_s": 120.0}),
    )
    bus.subscribe(bus.keys.status(), StatusMessage, lambda m, k: statuses.__setitem__(m.node, m))

    def skeletons() -> list[dict]:
        with lock:
            return [
                s for d in documents for s in d.get("pose_tracks", []) if len(s["joints"]) >= 10
            ]

    try:
        deadline = time.monotonic() + 200
        while time.monotonic() < deadline and not (
            skeletons() and any(a.startswith("/optrack/skeleton/") for a, _ in list(osc))
        ):
            assert launcher.poll() is None, processes.output(launcher)[-3000:]
            time.sleep(0.2)
        found = skeletons()
        assert found, f"no skeletons over UDP\n{processes.output(launcher)[-3000:]}"
        tracked_ids = {t["id"] for d in list(documents) for t in d.get("tracks", [])}
        assert {s["id"] for s in found} <= tracked_ids  # a skeleton is a track's
        first = found[0]
        assert {"HEAD", "NECK", "LEFT_WRIST", "RIGHT_ANKLE"} <= set(first["joints"])
        assert 0.5 < first["joints"]["HEAD"]["z"] < 2.3
        addresses = [a for a, _ in list(osc) if a.startswith("/optrack/skeleton/")]
        assert addresses, "no skeleton joints over OSC"
        _, args = next(m for m in list(osc) if m[0] == addresses[0])
        assert len(args) == 3
        status = statuses.get("skeleton")
        assert status is not None and status.values["enabled"] is True
        assert status.values["updates"] > 0
        for sensor in SENSORS:  # the detectors keep detecting
            assert statuses[sensor].values["frames"] > 0
    finally:
        stop.set()
        processes.stop_all()
        bus.close()
        osc_server.shutdown()
        osc_server.server_close()
        udp.close()
