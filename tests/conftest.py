"""Shared fixtures: the real data beside the project, buses on free loopback ports."""

from __future__ import annotations

import socket
from collections.abc import Iterator
from pathlib import Path

import pytest

from optrack.net.bus import Bus
from optrack.net.config import BUS_PARAMS

REPO = Path(__file__).resolve().parent.parent
SHARED_DATA = REPO.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """../shared/data (real PCL and OpenCV data); tests using it skip only where it is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real test data not found at {SHARED_DATA} (it sits beside the project in CI)")
    return SHARED_DATA


def free_port(kind: int = socket.SOCK_STREAM) -> int:
    """A loopback port nobody listens on (for a bus, a UDP output, a WebSocket server)."""
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture
def bus_params():
    """Local-site bus parameters on a free loopback port."""
    return BUS_PARAMS.create({"local_port": free_port(), "connect_timeout_s": 10.0})


@pytest.fixture
def hub(bus_params) -> Iterator[Bus]:
    """The bus that hosts the site (real Zenoh, loopback only)."""
    bus = Bus("test", "hub", bus_params, host=True)
    yield bus
    bus.close()


@pytest.fixture
def make_client(bus_params):
    """Open more buses on the hub's port (closed at the end); ``changes`` alter their params."""
    opened: list[Bus] = []

    def make(node: str = "client", **changes) -> Bus:
        params = BUS_PARAMS.create({**bus_params.as_dict(), **changes})
        bus = Bus("test", node, params)
        opened.append(bus)
        return bus

    yield make
    for bus in opened:
        bus.close()
