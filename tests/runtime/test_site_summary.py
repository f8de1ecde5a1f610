"""The launcher's periodic summary line names an output's missing receiver once, not at
every report, and says once when a receiver starts listening (real sockets on loopback)."""

from __future__ import annotations

import socket
import time

from optrack.net.messages import StatusMessage
from optrack.outputs.udp import Destination
from optrack.runtime.config import load_node_config
from optrack.runtime.site import Site


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _report(site: Site, destination: Destination) -> str:
    site.statuses["outputs"] = StatusMessage(
        node="outputs",
        role="outputs",
        state="running",
        stamp=time.time(),
        destinations=[destination.status()],
    )
    return site.summary()


def _send_until_refused(destination: Destination) -> None:
    before = destination.errors
    deadline = time.monotonic() + 5.0
    while destination.errors == before and time.monotonic() < deadline:
        destination.send(b"{}")
        time.sleep(0.01)
    assert destination.errors > before, "loopback never refused a datagram to a closed port"


def test_the_summary_says_no_receiver_once_then_that_one_listens():
    port = _free_port()
    site = Site(load_node_config(None, {"site": {"name": "summary"}}))
    destination = Destination("udp", "127.0.0.1", port)
    try:
        _send_until_refused(destination)
        first = _report(site, destination)
        assert f"udp 127.0.0.1:{port} sent" in first
        assert f"no receiver on 127.0.0.1:{port} yet" in first
        assert "errors" not in first
        _send_until_refused(destination)
        second = _report(site, destination)
        assert f"udp 127.0.0.1:{port} sent" in second
        assert "no receiver" not in second and "errors" not in second  # said once
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as receiver:
            receiver.bind(("127.0.0.1", port))
            receiver.settimeout(5.0)
            for _ in range(3):
                assert destination.send(b"{}")
                assert receiver.recv(64) == b"{}"
            third = _report(site, destination)
            assert f"a receiver listens on 127.0.0.1:{port} now" in third
            assert "no receiver" not in _report(site, destination)  # said once too
        _send_until_refused(destination)  # the receiver went away: said again, once
        assert f"no receiver on 127.0.0.1:{port} yet" in _report(site, destination)
    finally:
        destination.close()
