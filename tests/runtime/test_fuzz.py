"""10,000 fuzzed bus messages and a UDP destination that does not exist: the tracker and
outputs nodes neither crash nor lose count, and keep working afterwards."""

from __future__ import annotations

import json
import math
import random
import socket
import threading
import time

import msgspec
import pytest

from optrack.net.bus import Bus
from optrack.net.config import BUS_PARAMS
from optrack.net.messages import (
    WIRE_VERSION,
    ClockRequest,
    DetectionsMessage,
    ParamsMessage,
    StatusMessage,
    TracksMessage,
    encode,
)
from optrack.outputs import OUTPUTS_PARAMS
from optrack.runtime.calibration_store import CalibrationStore
from optrack.runtime.config import NODE_PARAMS
from optrack.runtime.outputs_node import OutputsNode
from optrack.runtime.tracker_node import TrackerNode
from optrack.types import Detection, DetectionBatch, Track, TrackBatch

from .conftest import free_port

MESSAGES = 10_000
LIMIT = 64 * 1024


EXPECTED = {"detections": "detections", "tracks": "tracks", "params": "params"}


def belongs(message: msgspec.Struct, key: str) -> bool:
    """Whether a valid message is of the kind its key carries (then it is accepted)."""
    kind = type(message).__struct_config__.tag
    return key.split("/")[2] == kind


def corrupt(rng: random.Random, keys: list[str]) -> tuple[str, bytes, bool]:
    """One hostile payload, the key it goes to, and whether the bus should accept it
    (a valid message that happens to be of the kind its key carries)."""
    key = rng.choice(keys)
    kind = rng.randrange(9)
    t = time.time()
    if kind == 0:  # random bytes
        return key, rng.randbytes(rng.randrange(0, 2000)), False
    if kind == 1:  # a valid message with another wire version
        data = msgspec.to_builtins(
            DetectionsMessage(batch=DetectionBatch("cam0", t)),
        )
        data["v"] = rng.choice([0, WIRE_VERSION + 1, -7, 2**40])
        return key, msgspec.msgpack.encode(data), False
    if kind == 2:  # a valid message of a kind that does not belong on that key
        other = rng.choice(
            [
                StatusMessage(node="x", role="detector", state="running", stamp=t),
                ClockRequest(t0=t),
                TracksMessage(batch=TrackBatch(t)),
                DetectionsMessage(batch=DetectionBatch("cam0", t)),
                ParamsMessage(updates={"tracking": {"no_such": rng.random()}}),
            ]
        )
        return key, encode(other), belongs(other, key)
    if kind == 3:  # right kind, wrong field types
        data = msgspec.to_builtins(DetectionsMessage(batch=DetectionBatch("cam0", t)))
        data["batch"]["stamp"] = rng.choice(["yesterday", None, [1, 2], {"a": 1}])
        return key, msgspec.msgpack.encode(data), False
    if kind == 4:  # unknown fields
        data = msgspec.to_builtins(TracksMessage(batch=TrackBatch(t)))
        data["extra"] = rng.random()
        return key, msgspec.msgpack.encode(data), False
    if kind == 5:  # non-finite numbers
        bad = rng.choice([math.nan, math.inf, -math.inf])
        return (
            key,
            encode(
                DetectionsMessage(
                    batch=DetectionBatch("cam0", t, detections=[Detection(bad, 0, 0, 1.7, 1.0)])
                )
            ),
            False,
        )
    if kind == 6:  # truncated
        whole = encode(TracksMessage(batch=TrackBatch(t, tracks=[Track(2, 1.0, 1.0, 1.7)])))
        return key, whole[: rng.randrange(1, len(whole))], False
    if kind == 7:  # JSON, not MessagePack
        return key, json.dumps({"kind": "detections", "v": 1}).encode(), False
    # huge, over the node's limit
    return key, b"\x81" * rng.randrange(LIMIT + 1, 4 * LIMIT), False


@pytest.fixture
def target(tmp_path):
    """A tracker node and an outputs node (to a live receiver and a dead port) on a hub."""
    params = BUS_PARAMS.create(
        {"local_port": free_port(), "max_message_bytes": LIMIT, "connect_timeout_s": 10.0}
    )
    hub = Bus("fuzz", "tracker", params, host=True)
    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receiver.bind(("127.0.0.1", 0))
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        dead = probe.getsockname()[1]  # nobody listens there once closed
    tracker = TrackerNode(hub, NODE_PARAMS.create(), CalibrationStore(tmp_path / "tracker"))
    outputs = OutputsNode(
        hub,
        NODE_PARAMS.create(),
        OUTPUTS_PARAMS.create({"udp": f"127.0.0.1:{dead},127.0.0.1:{receiver.getsockname()[1]}"}),
    )
    thread = threading.Thread(target=tracker.run, daemon=True)
    thread.start()
    fuzzer = Bus("fuzz", "fuzzer", params)
    yield hub, tracker, outputs, fuzzer, receiver, dead
    fuzzer.close()
    tracker.stop()
    thread.join(5)
    outputs.close()
    hub.close()
    receiver.close()


def test_ten_thousand_fuzzed_messages_are_all_counted_and_nothing_stops(target):
    hub, tracker, outputs, fuzzer, receiver, dead = target
    keys = [
        hub.keys.detections("cam0"),
        hub.keys.detections("intruder"),
        hub.keys.tracks,
        hub.keys.calibration,
        hub.keys.params("tracker"),
        hub.keys.params("outputs"),
    ]
    rng = random.Random(7)
    time.sleep(0.3)
    valid = 0
    for i in range(MESSAGES):
        if i % 50 == 0:  # junk to the clock queryable as well
            fuzzer.session.get(hub.keys.clock, payload=rng.randbytes(40), timeout=0.5)
            continue
        key, payload, accepted = corrupt(rng, keys)
        fuzzer.put_raw(key, payload)
        valid += accepted
    # The hub's session also carries the tracks the tracker made from the valid detections.
    deadline = time.monotonic() + 20
    while (
        hub.stats.snapshot()["received"] < MESSAGES + tracker.published
        and time.monotonic() < deadline
    ):
        time.sleep(0.05)
    time.sleep(0.2)
    counts = hub.stats.snapshot()
    assert counts["received"] == MESSAGES + tracker.published
    assert counts["accepted"] == valid + tracker.published
    assert counts["handler_errors"] == 0
    reasons = {k: v for k, v in counts.items() if k.startswith("rejected_")}
    assert counts["rejected"] == MESSAGES - valid
    assert all(v > 0 for v in reasons.values()), reasons
    # Valid messages of the wrong sensor or with unknown parameters were refused by the nodes.
    assert tracker.refused > 0
    assert tracker.params_refused > 0
    # Still working: a real person goes in, JSON comes out.
    for k in range(40):
        t = time.time()
        fuzzer.publish(
            fuzzer.keys.detections("cam0"),
            DetectionsMessage(
                batch=DetectionBatch("cam0", t, detections=[Detection(0.03 * k, 0, 0.9, 1.7, 2.0)])
            ),
        )
        time.sleep(1 / 30)
    documents = []
    deadline = time.monotonic() + 1.0
    while (left := deadline - time.monotonic()) > 0:
        receiver.settimeout(left)
        try:
            documents.append(json.loads(receiver.recv(65536)))
        except TimeoutError:
            break
    assert any(d.get("tracks") for d in documents)
    dead_status = next(d for d in outputs.outputs.status() if d.address == f"127.0.0.1:{dead}")
    assert dead_status.errors > 0
    assert "nothing listens" in dead_status.last_error
    assert tracker.stopping is False and outputs.stopping is False
