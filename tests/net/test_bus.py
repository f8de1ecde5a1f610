"""The bus on loopback: valid messages arrive; everything else is counted, logged once
per source, and never reaches the node or stops it."""

from __future__ import annotations

import logging
import threading
import time

import pytest

from optrack.net.bus import Bus, BusError
from optrack.net.config import BUS_PARAMS
from optrack.net.messages import (
    ClockReply,
    ClockRequest,
    DetectionsMessage,
    TracksMessage,
    encode,
)
from optrack.types import Detection, DetectionBatch, TrackBatch

from .conftest import free_port


class Inbox:
    def __init__(self) -> None:
        self.items: list[tuple[object, str]] = []
        self.event = threading.Event()

    def __call__(self, message: object, key: str) -> None:
        self.items.append((message, key))
        self.event.set()

    def wait(self, count: int, timeout: float = 3.0) -> None:
        deadline = time.monotonic() + timeout
        while len(self.items) < count and time.monotonic() < deadline:
            time.sleep(0.01)


def wait_until(predicate, timeout: float = 3.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.01)
    return predicate()


def batch(sensor: str = "cam0") -> DetectionsMessage:
    return DetectionsMessage(
        batch=DetectionBatch(sensor, time.time(), detections=[Detection(1, 2, 0.9, 1.7, 0.5)])
    )


def test_valid_message_reaches_the_subscriber_with_its_sender(hub, make_client):
    inbox = Inbox()
    hub.subscribe(hub.keys.detections(), DetectionsMessage, inbox)
    node = make_client("cam0")
    time.sleep(0.2)  # let the subscription propagate
    node.publish(node.keys.detections("cam0"), batch())
    inbox.wait(1)
    message, key = inbox.items[0]
    assert key == "optrack/test/detections/cam0"
    assert message.sender == "cam0"
    assert message.batch.detections[0].height == pytest.approx(1.7)
    assert hub.stats.snapshot()["accepted"] == 1


def test_bad_messages_are_counted_and_logged_once_per_source(hub, make_client, caplog):
    inbox = Inbox()
    hub.subscribe(hub.keys.detections(), DetectionsMessage, inbox)
    node = make_client("cam0")
    time.sleep(0.2)
    with caplog.at_level(logging.WARNING, logger="optrack.net"):
        for _ in range(5):
            node.put_raw(node.keys.detections("cam0"), b"not a message")
        node.put_raw(node.keys.detections("cam1"), encode(TracksMessage(batch=TrackBatch(1.0))))
        node.publish(node.keys.detections("cam0"), batch())
        assert wait_until(lambda: hub.stats.snapshot()["received"] == 7)
    counts = hub.stats.snapshot()
    assert counts["rejected_malformed"] == 5
    assert counts["rejected_kind"] == 1
    assert counts["accepted"] == 1
    assert len(inbox.items) == 1
    refusals = [r for r in caplog.records if "refused a message" in r.getMessage()]
    assert [r.getMessage().split(":")[0] for r in refusals] == [
        "refused a message on optrack/test/detections/cam0",
        "refused a message on optrack/test/detections/cam1",
    ]


def test_a_failing_subscriber_is_counted_and_the_next_message_still_arrives(hub, make_client):
    calls = []

    def fragile(message, key):
        calls.append(message)
        if len(calls) == 1:
            raise RuntimeError("boom")

    hub.subscribe(hub.keys.detections(), DetectionsMessage, fragile)
    node = make_client("cam0")
    time.sleep(0.2)
    node.publish(node.keys.detections("cam0"), batch())
    node.publish(node.keys.detections("cam0"), batch())
    assert wait_until(lambda: len(calls) == 2)
    assert hub.stats.snapshot()["handler_errors"] == 1


def test_message_over_the_size_limit_is_refused_unread(bus_params, make_client):
    small = BUS_PARAMS.create({**bus_params.as_dict(), "max_message_bytes": 1024})
    hub = Bus("test", "tracker", small, host=True)
    try:
        inbox = Inbox()
        hub.subscribe(hub.keys.detections(), DetectionsMessage, inbox)
        node = make_client("cam0")
        time.sleep(0.2)
        node.put_raw(node.keys.detections("cam0"), b"\x00" * 4096)
        assert wait_until(lambda: hub.stats.snapshot()["rejected_too_large"] == 1)
        assert inbox.items == []
    finally:
        hub.close()


def test_query_gets_the_queryables_reply(hub, make_client):
    hub.serve(
        hub.keys.clock,
        ClockRequest,
        lambda request: ClockReply(t0=request.t0, t1=request.t0 + 1, t2=request.t0 + 2),
    )
    node = make_client("cam0")
    time.sleep(0.2)
    replies = node.query(node.keys.clock, ClockRequest(t0=5.0), ClockReply, timeout=2.0)
    assert [(r.t0, r.t1, r.t2, r.sender) for r in replies] == [(5.0, 6.0, 7.0, "hub")]


def test_node_without_a_hub_gives_up_with_one_sentence():
    params = BUS_PARAMS.create({"local_port": free_port(), "connect_timeout_s": 0.3})
    started = time.monotonic()
    with pytest.raises(BusError, match="start the tracker node first"):
        Bus("test", "cam0", params)
    assert time.monotonic() - started < 3.0


def test_node_waits_for_a_hub_that_starts_later(bus_params):
    opened: dict[str, Bus] = {}

    def join() -> None:
        opened["node"] = Bus("test", "cam0", bus_params)

    thread = threading.Thread(target=join)
    thread.start()
    time.sleep(0.5)
    hub = Bus("test", "tracker", bus_params, host=True)
    thread.join(timeout=5.0)
    try:
        assert "node" in opened
    finally:
        opened["node"].close()
        hub.close()


def test_second_hub_on_the_same_port_is_refused(hub, bus_params):
    with pytest.raises(BusError, match="bus.local_port"):
        Bus("test", "tracker2", bus_params, host=True)


def test_closed_bus_drops_publications_quietly(hub):
    hub.close()
    hub.publish(hub.keys.detections("cam0"), batch())
    assert hub.closed


def test_a_program_that_forgets_to_close_its_buses_still_exits(bus_params):
    import subprocess
    import sys

    port = int(bus_params.local_port)
    script = f"""
from optrack.net.bus import Bus
from optrack.net.config import BUS_PARAMS
from optrack.net.messages import DetectionsMessage
params = BUS_PARAMS.create({{"local_port": {port}}})
hub = Bus("test", "hub", params, host=True)
node = Bus("test", "node", params)
for bus in (hub, node):
    bus.subscribe(bus.keys.detections(), DetectionsMessage, lambda m, k: None)
"""
    result = subprocess.run([sys.executable, "-c", script], timeout=60, capture_output=True)
    assert result.returncode == 0, result.stderr.decode()
