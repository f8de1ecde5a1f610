"""UDP datagrams to a list of destinations: unicast, broadcast or multicast.

One connected, non-blocking socket per destination, so that an error
(nobody listening, no route, a full buffer) is counted against the
destination it belongs to and logged once, and never stalls or stops the
node. On Linux a connected UDP socket learns from the ICMP reply that
nothing listens at a destination and reports it on a later send.
"""

from __future__ import annotations

import errno
import ipaddress
import logging
import socket
import threading
from collections.abc import Iterable

from optrack.errors import UserError
from optrack.net.messages import DestinationStatus

__all__ = [
    "Destination",
    "OutputError",
    "UdpSender",
    "join_destinations",
    "no_receiver_note",
    "parse_address",
    "parse_destinations",
    "resolve_destination",
    "split_destinations",
]

log = logging.getLogger("optrack.outputs")

MODES = ("unicast", "broadcast", "multicast")


class OutputError(UserError):
    """An output destination that cannot be used."""


def parse_address(
    text: str, default_port: int, what: str, any_port: bool = False
) -> tuple[str, int]:
    """``HOST:PORT``, ``HOST``, ``:PORT`` or ``[IPv6]:PORT`` as (host, port).
    ``any_port`` also accepts port 0 (a server picks any free port)."""
    text = text.strip()
    host, port_text = text, ""
    if text.startswith("["):
        host, _, rest = text[1:].partition("]")
        port_text = rest[1:] if rest.startswith(":") else rest
    elif text.count(":") == 1:
        host, _, port_text = text.partition(":")
    if not host:
        host = "127.0.0.1"
    if port_text:
        low = 0 if any_port else 1
        if not port_text.isdigit() or not low <= int(port_text) < 65536:
            raise OutputError(
                f"{what} '{text}' has a bad port '{port_text}'; write HOST:PORT with a port "
                f"between {low} and 65535."
            )
        port = int(port_text)
    else:
        port = default_port
    return host, port


def split_destinations(text: str) -> list[str]:
    """The addresses of a destination list as the ``outputs`` stage writes it (separated by
    commas; empty means none)."""
    return [item.strip() for item in str(text).split(",") if item.strip()]


def join_destinations(addresses: Iterable[str]) -> str:
    """A list of addresses written as the ``outputs`` stage takes it."""
    return ",".join(address.strip() for address in addresses)


def parse_destinations(text: str, default_port: int, what: str) -> list[tuple[str, int]]:
    """Comma-separated addresses (see :func:`parse_address`); empty means none."""
    return [parse_address(item, default_port, what) for item in split_destinations(text)]


def resolve_destination(kind: str, host: str, port: int) -> tuple[int, tuple]:
    """The address family and socket address of a ``kind`` destination (one sentence when
    the host is unknown)."""
    address = f"[{host}]:{port}" if ":" in host else f"{host}:{port}"
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)
    except (socket.gaierror, UnicodeError):
        raise OutputError(
            f"{kind} destination {address}: the host '{host}' is unknown; give an IP "
            "address or a name this computer can resolve."
        ) from None
    family, _, _, _, sockaddr = infos[0]
    return family, sockaddr


class Destination:
    """One socket, and what happened to the datagrams sent through it."""

    def __init__(
        self,
        kind: str,
        host: str,
        port: int,
        mode: str = "unicast",
        ttl: int = 1,
        interface: str = "",
    ) -> None:
        self.kind = kind
        self.address = f"[{host}]:{port}" if ":" in host else f"{host}:{port}"
        self.sent = 0
        self.errors = 0
        self.last_error = ""
        self._logged: set[int] = set()
        family, sockaddr = resolve_destination(kind, host, port)
        ip = ipaddress.ip_address(sockaddr[0])
        if mode == "multicast" and not ip.is_multicast:
            raise OutputError(
                f"{kind} destination {self.address} is not a multicast group; use an address in "
                "224.0.0.0/4 (e.g. 239.255.0.1) or set the mode to unicast."
            )
        self.sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            if mode == "broadcast":
                self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
            elif mode == "multicast":
                if family == socket.AF_INET6:
                    self.sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_MULTICAST_HOPS, ttl)
                    self.sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_MULTICAST_LOOP, 1)
                else:
                    self.sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, ttl)
                    self.sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
                    if interface:
                        self.sock.setsockopt(
                            socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton(interface)
                        )
            self.sock.setblocking(False)
            self.sock.connect(sockaddr)
        except OSError as error:
            self.sock.close()
            raise OutputError(
                f"{kind} destination {self.address} cannot be used ({error.strerror or error}); "
                "check the address, the mode and the interface."
            ) from None

    def send(self, datagram: bytes) -> bool:
        try:
            self.sock.send(datagram)
        except OSError as error:
            self.errors += 1
            self.last_error = _describe(error, self.address)
            code = error.errno or -1
            if code not in self._logged:
                self._logged.add(code)
                log.warning(
                    "%s output: %s (further such errors are only counted)",
                    self.kind,
                    self.last_error,
                )
            return False
        self.sent += 1
        return True

    def status(self) -> DestinationStatus:
        return DestinationStatus(
            kind=self.kind,
            address=self.address,
            sent=self.sent,
            errors=self.errors,
            last_error=self.last_error,
        )

    def close(self) -> None:
        self.sock.close()


NOTHING_LISTENS = "nothing listens at"


def no_receiver_note(address: str, last_error: str) -> str:
    """``no receiver on ADDRESS yet`` when a destination's last datagram found no program
    listening there (connection refused): a state, not a fault of the site; else ''."""
    return f"no receiver on {address} yet" if last_error.startswith(NOTHING_LISTENS) else ""


def _describe(error: OSError, address: str) -> str:
    if error.errno == errno.ECONNREFUSED:
        return f"{NOTHING_LISTENS} {address} (connection refused)"
    if error.errno in (errno.EAGAIN, errno.EWOULDBLOCK, errno.ENOBUFS):
        return f"a datagram to {address} was dropped (send buffer full)"
    if error.errno in (errno.ENETUNREACH, errno.EHOSTUNREACH):
        return f"{address} cannot be reached (no route)"
    if error.errno == errno.EMSGSIZE:
        return f"a datagram to {address} is too large for UDP"
    return f"sending to {address} failed ({error.strerror or error})"


class UdpSender:
    """Sends each datagram to every destination; thread-safe."""

    def __init__(self, destinations: list[Destination]) -> None:
        self.destinations = destinations
        self._lock = threading.Lock()

    def send(self, datagram: bytes) -> None:
        with self._lock:
            for destination in self.destinations:
                destination.send(datagram)

    def status(self) -> list[DestinationStatus]:
        with self._lock:
            return [d.status() for d in self.destinations]

    def close(self) -> None:
        with self._lock:
            for destination in self.destinations:
                destination.close()
