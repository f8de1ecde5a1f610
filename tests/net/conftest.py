"""Bus fixtures: real Zenoh sessions on loopback ports nobody else uses."""

from __future__ import annotations

import socket
from collections.abc import Iterator

import pytest

from optrack.net.bus import Bus
from optrack.net.config import BUS_PARAMS


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture
def bus_params():
    """Local-site bus parameters on a free loopback port."""
    return BUS_PARAMS.create({"local_port": free_port(), "connect_timeout_s": 5.0})


@pytest.fixture
def hub(bus_params) -> Iterator[Bus]:
    bus = Bus("test", "tracker", bus_params, host=True)
    yield bus
    bus.close()


@pytest.fixture
def make_client(bus_params):
    opened: list[Bus] = []

    def make(node: str = "client", **changes) -> Bus:
        params = BUS_PARAMS.create({**bus_params.as_dict(), **changes})
        bus = Bus("test", node, params)
        opened.append(bus)
        return bus

    yield make
    for bus in opened:
        bus.close()
