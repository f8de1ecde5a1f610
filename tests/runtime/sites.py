"""A site as a user runs it: `optrack run --headless` from a config file, with a UDP and
an OSC receiver on loopback and an observer on its bus that keeps every node's status.
The site tests (test_site.py, test_skeleton_site.py) start theirs from here."""

from __future__ import annotations

import json
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

import yaml
from pythonosc.dispatcher import Dispatcher
from pythonosc.osc_server import ThreadingOSCUDPServer

from optrack.bench.site_process import DatagramReceiver
from optrack.net.bus import Bus
from optrack.net.clock import ClockServer
from optrack.net.config import BUS_PARAMS
from optrack.net.messages import StatusMessage

from .conftest import Processes, free_port


def recording_detector(
    venue: Path, hub: Bus, client: Bus, processes: Processes, folder: Path, data_folder: Path
) -> tuple[subprocess.Popen[bytes], list[StatusMessage]]:
    """A detector node (`optrack node detect`, its own process; its configuration and
    state in ``folder``) playing sensor kinect2_0 of ``venue`` in a loop on ``hub``'s site
    'test' (which answers the clock), recording only inside ``data_folder``, its status 5
    times a second; returns it once its first status reached ``client``, and the list its
    statuses keep arriving in."""
    ClockServer(hub)
    config = folder / "node.yaml"
    endpoint = f"tcp/127.0.0.1:{int(client.params.local_port)}"
    node = {"state_dir": str(folder / "state"), "status_period_s": 0.2}
    bus = {"mode": "client", "connect": endpoint, "multicast_scouting": False}
    config.write_text(
        yaml.safe_dump({"bus": bus, "node": {**node, "data_folder": str(data_folder)}})
    )
    statuses: list[StatusMessage] = []
    client.subscribe(
        client.keys.status("kinect2_0"), StatusMessage, lambda m, k: statuses.append(m)
    )
    sensor = f"file://{venue}?loop=restart#kinect2_0"
    process = processes.start(
        ["optrack.cli", "node", "detect", "--sensor", sensor, "--site", "test"]
        + ["--config", str(config)],
        "node",
    )
    deadline = time.monotonic() + 120
    while not statuses:
        assert process.poll() is None, processes.output(process)[-3000:]
        assert time.monotonic() < deadline, processes.output(process)[-3000:]
        time.sleep(0.05)
    return process, statuses


def venue_sensors(venue: Path, sensors: tuple[str, ...]) -> str:
    """``site.sensors`` playing ``sensors`` of the recorded ``venue``, forwards and back."""
    return ",".join(f"file://{venue}?loop=bounce#{s}" for s in sensors)


class RunningSite:
    """`optrack run --headless --seconds 240` with ``values`` in its config file (its bus
    port and OSC destination added), ``args`` on its command line; what reaches the
    receivers and the bus is kept with its arrival time."""

    def __init__(
        self, tmp_path: Path, values: dict[str, dict[str, Any]], args: tuple[str, ...] = ()
    ) -> None:
        self.lock = threading.Lock()
        self._documents: list[tuple[float, dict]] = []  # the datagrams, parsed once
        self.osc: list[tuple[float, str, tuple]] = []
        self.statuses: dict[str, StatusMessage] = {}
        self.udp = DatagramReceiver()
        dispatcher = Dispatcher()
        dispatcher.set_default_handler(
            lambda address, *args: self._add(self.osc, (time.time(), address, args))
        )
        self.osc_server = ThreadingOSCUDPServer(("127.0.0.1", 0), dispatcher)
        self.port = free_port()
        self.name = str(values["site"]["name"])
        values = {stage: dict(stage_values) for stage, stage_values in values.items()}
        values["bus"] = {"local_port": self.port}
        values.setdefault("outputs", {})["osc"] = f"127.0.0.1:{self.osc_server.server_address[1]}"
        config = tmp_path / "site.yaml"
        config.write_text(yaml.safe_dump(values))
        self.processes = Processes(tmp_path)
        command = ["optrack.cli", "run", "--headless", "--seconds", "240"]
        command += ["--config", str(config), "--udp", self.udp.address]
        self.launcher = self.processes.start([*command, *args], "launcher")
        self.udp.start()
        threading.Thread(target=self.osc_server.serve_forever, daemon=True).start()
        self.bus = Bus(
            self.name,
            "observer",
            BUS_PARAMS.create({"local_port": self.port, "connect_timeout_s": 120.0}),
        )
        self.bus.subscribe(self.bus.keys.status(), StatusMessage, self._on_status)

    def _add(self, where: list, item: Any) -> None:
        with self.lock:
            where.append(item)

    def _on_status(self, message: StatusMessage, key: str) -> None:
        with self.lock:
            self.statuses[message.node] = message

    @property
    def datagrams(self) -> list[tuple[float, bytes]]:
        """Every UDP datagram received, with its arrival time (time.time())."""
        return self.udp.arrivals

    def documents(self, since: float = 0.0) -> list[tuple[float, dict]]:
        """The UDP JSON documents received since ``since`` (time.time()), parsed."""
        with self.lock:
            arrivals = self.udp.arrivals[len(self._documents) :]
            self._documents += [(t, json.loads(data)) for t, data in arrivals]
            return [(t, d) for t, d in self._documents if t >= since]

    def counted(self, node: str, key: str) -> bool:
        """The node's latest status counts something under ``key``."""
        with self.lock:
            status = self.statuses.get(node)
        return status is not None and status.values.get(key, 0) > 0

    def wait(self, predicate, timeout: float, what: str) -> None:
        """Until ``predicate()``; fails saying ``what`` (and the launcher's output) after
        ``timeout`` s or as soon as the launcher ends."""
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
        self.processes.stop_all()
        self.bus.close()
        self.osc_server.shutdown()
        self.osc_server.server_close()
        self.udp.close()
