"""`optrack run` with skeletons as a user runs it, on the simulated venue: with
`--skeleton`, skeletons of the tracked people arrive over UDP (OpenPTrack v2's pose
message) and OSC on loopback; without it nothing about skeletons is sent until the stage
is switched on live, and then the site starts its skeleton node and they arrive."""

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
from optrack.net.messages import ParamsMessage, StatusMessage

from .conftest import Processes, free_port

SENSORS = ("kinect2_0", "kinect2_1")


class SkeletonSite:
    """A running `optrack run` on two sensors of the venue, and its UDP and OSC receivers."""

    def __init__(self, venue, tmp_path, skeleton: bool) -> None:
        self.lock = threading.Lock()
        self.documents: list[dict] = []
        self.osc: list[tuple[str, tuple]] = []
        self.statuses: dict[str, StatusMessage] = {}
        self.udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.udp.bind(("127.0.0.1", 0))
        self.udp.settimeout(0.2)
        dispatcher = Dispatcher()
        dispatcher.set_default_handler(lambda address, *args: self.osc.append((address, args)))
        self.osc_server = ThreadingOSCUDPServer(("127.0.0.1", 0), dispatcher)
        self._stop = threading.Event()
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
                    "outputs": {"osc": f"127.0.0.1:{self.osc_server.server_address[1]}"},
                    "skeleton": {"particles": 200, "init_layers": 6},
                }
            )
        )
        self.processes = Processes(tmp_path)
        args = ["optrack.cli", "run", "--headless", "--seconds", "240", "--config", str(config)]
        args += ["--udp", f"127.0.0.1:{self.udp.getsockname()[1]}"]
        self.launcher = self.processes.start(args + (["--skeleton"] if skeleton else []), "run")
        for target in (self._receive, self.osc_server.serve_forever):
            threading.Thread(target=target, daemon=True).start()
        self.bus = Bus(
            "skeletonsite",
            "observer",
            BUS_PARAMS.create({"local_port": port, "connect_timeout_s": 120.0}),
        )
        self.bus.subscribe(self.bus.keys.status(), StatusMessage, self._on_status)

    def _on_status(self, message: StatusMessage, key: str) -> None:
        with self.lock:
            self.statuses[message.node] = message

    def _receive(self) -> None:
        while not self._stop.is_set():
            try:
                data = self.udp.recv(65536)
            except TimeoutError:
                continue
            except OSError:
                return
            with self.lock:
                self.documents.append(json.loads(data))

    def skeletons(self) -> list[dict]:
        """Every skeleton with joints received over UDP."""
        with self.lock:
            return [s for d in self.documents for s in d.get("pose_tracks", []) if s["joints"]]

    def osc_joints(self) -> list[tuple[str, tuple]]:
        return [(a, args) for a, args in list(self.osc) if a.startswith("/optrack/skeleton/")]

    def wait(self, predicate, timeout: float, what: str) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            assert self.launcher.poll() is None, self.processes.output(self.launcher)[-3000:]
            if predicate():
                return
            time.sleep(0.2)
        raise AssertionError(
            f"{what} within {timeout} s\n{self.processes.output(self.launcher)[-3000:]}"
        )

    def check_skeletons(self) -> None:
        """Skeletons over UDP and OSC, each a track's, with v2's joint names."""
        self.wait(lambda: self.skeletons() and self.osc_joints(), 200, "no skeletons")
        with self.lock:
            tracked = {t["id"] for d in self.documents for t in d.get("tracks", [])}
        found = self.skeletons()
        assert {s["id"] for s in found} <= tracked  # a skeleton is a track's
        assert {"HEAD", "NECK", "LEFT_WRIST", "RIGHT_ANKLE"} <= set(found[0]["joints"])
        assert 0.5 < found[0]["joints"]["HEAD"]["z"] < 2.3
        assert len(self.osc_joints()[0][1]) == 3  # x y z
        # statuses come once a second: the one seen may predate the first skeleton
        self.wait(lambda: self._counted("skeleton", "updates"), 30, "no skeleton updates counted")
        for sensor in SENSORS:  # the detectors keep detecting
            self.wait(lambda s=sensor: self._counted(s, "frames"), 30, f"no frames from {sensor}")

    def _counted(self, node: str, key: str) -> bool:
        with self.lock:
            status = self.statuses.get(node)
        return status is not None and status.values.get(key, 0) > 0

    def close(self) -> None:
        self._stop.set()
        self.processes.stop_all()
        self.bus.close()
        self.osc_server.shutdown()
        self.osc_server.server_close()
        self.udp.close()


def test_a_site_run_with_skeleton_sends_them_over_udp_and_osc(venue, tmp_path):
    site = SkeletonSite(venue, tmp_path, skeleton=True)
    try:
        site.check_skeletons()
    finally:
        site.close()


def test_skeletons_switched_on_live_start_the_skeleton_node(venue, tmp_path):
    site = SkeletonSite(venue, tmp_path, skeleton=False)
    try:
        site.wait(
            lambda: any(d.get("tracks") for d in list(site.documents)), 200, "no tracks on UDP"
        )
        time.sleep(2.0)
        assert site.skeletons() == [] and site.osc_joints() == []  # off: nothing about them
        assert "skeleton" not in site.statuses
        for sensor in SENSORS:
            site.bus.publish(
                site.bus.keys.params(sensor),
                ParamsMessage(updates={"skeleton_live": {"enabled": True}}),
            )
        site.check_skeletons()
    finally:
        site.close()
