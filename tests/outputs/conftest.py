"""Receivers on loopback for the outputs' tests."""

from __future__ import annotations

import json
import socket
import time
from collections.abc import Iterator

import pytest


class UdpReceiver:
    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.port = int(self.sock.getsockname()[1])
        self.address = f"127.0.0.1:{self.port}"

    def datagrams(self, seconds: float) -> list[bytes]:
        """Everything that arrives within ``seconds``."""
        found = []
        deadline = time.monotonic() + seconds
        while (left := deadline - time.monotonic()) > 0:
            self.sock.settimeout(left)
            try:
                found.append(self.sock.recv(65536))
            except TimeoutError:
                break
        return found

    def documents(self, seconds: float) -> list[dict]:
        return [json.loads(d) for d in self.datagrams(seconds)]


@pytest.fixture
def receiver() -> Iterator[UdpReceiver]:
    r = UdpReceiver()
    yield r
    r.sock.close()


@pytest.fixture
def closed_port() -> int:
    """A loopback UDP port nobody listens on."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])
