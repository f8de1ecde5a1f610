"""UDP destinations: datagrams on loopback, errors counted per destination, socket options
for broadcast and multicast (set, never sent: tests stay on loopback)."""

from __future__ import annotations

import logging
import socket

import pytest

from optrack.outputs.udp import Destination, OutputError, UdpSender, parse_destinations


def test_unicast_datagrams_arrive_one_by_one(receiver):
    destination = Destination("udp", "127.0.0.1", receiver.port)
    try:
        assert destination.send(b'{"a":1}')
        assert destination.send(b'{"b":2}')
        assert receiver.datagrams(0.3) == [b'{"a":1}', b'{"b":2}']
        assert destination.status().sent == 2
    finally:
        destination.close()


def test_a_destination_nobody_listens_on_is_counted_never_raised(closed_port, caplog):
    destination = Destination("udp", "127.0.0.1", closed_port)
    try:
        with caplog.at_level(logging.WARNING, logger="optrack.outputs"):
            results = [destination.send(b"{}") for _ in range(20)]
        status = destination.status()
        assert status.sent + status.errors == 20
        assert status.errors >= 1 and results.count(False) == status.errors
        assert "nothing listens at" in status.last_error
        assert len([r for r in caplog.records if "nothing listens" in r.getMessage()]) == 1
    finally:
        destination.close()


def test_broadcast_mode_enables_broadcast_on_the_socket():
    destination = Destination("udp", "127.0.0.1", 21234, mode="broadcast")
    try:
        assert destination.sock.getsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST) == 1
    finally:
        destination.close()


def test_unicast_mode_leaves_broadcast_off():
    destination = Destination("udp", "127.0.0.1", 21234)
    try:
        assert destination.sock.getsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST) == 0
    finally:
        destination.close()


def test_multicast_mode_sets_ttl_loop_and_interface():
    destination = Destination(
        "udp", "239.255.0.1", 21234, mode="multicast", ttl=3, interface="127.0.0.1"
    )
    try:
        sock = destination.sock
        assert sock.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL) == 3
        assert sock.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP) == 1
        interface = sock.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, 4)
        assert socket.inet_ntoa(interface) == "127.0.0.1"
    finally:
        destination.close()


def test_multicast_mode_refuses_an_address_that_is_not_a_group():
    with pytest.raises(OutputError, match="not a multicast group"):
        Destination("udp", "127.0.0.1", 21234, mode="multicast")


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("127.0.0.1:9000", [("127.0.0.1", 9000)]),
        ("127.0.0.1", [("127.0.0.1", 21234)]),
        (":9000", [("127.0.0.1", 9000)]),
        ("[::1]:9000, 10.0.0.2:1", [("::1", 9000), ("10.0.0.2", 1)]),
        ("", []),
    ],
)
def test_destinations_are_parsed_with_the_default_port(text, expected):
    assert parse_destinations(text, 21234, "outputs.udp destination") == expected


@pytest.mark.parametrize("text", ["127.0.0.1:0", "127.0.0.1:70000", "127.0.0.1:port"])
def test_a_bad_port_is_refused_with_one_sentence(text):
    with pytest.raises(OutputError, match="bad port"):
        parse_destinations(text, 21234, "outputs.udp destination")


def test_sender_goes_on_to_the_next_destination_after_a_failing_one(receiver, closed_port):
    sender = UdpSender(
        [
            Destination("udp", "127.0.0.1", closed_port),
            Destination("udp", "127.0.0.1", receiver.port),
        ]
    )
    try:
        for _ in range(10):
            sender.send(b"{}")
        assert len(receiver.datagrams(0.3)) == 10
        failing, working = sender.status()
        assert failing.errors >= 1 and working.sent == 10 and working.errors == 0
    finally:
        sender.close()
