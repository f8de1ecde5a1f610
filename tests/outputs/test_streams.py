"""All outputs together: tracks to every destination, the heartbeat every 0.25 s, and
destinations changed while running."""

from __future__ import annotations

import json
import statistics
import time

import numpy as np
import pytest
from websockets.sync.client import connect

from optrack.outputs import OUTPUTS_PARAMS, OutputError, Outputs
from optrack.types import Track, TrackBatch


def tracks(*ids: int, stamp: float | None = None) -> TrackBatch:
    return TrackBatch(
        stamp=time.time() if stamp is None else stamp,
        tracks=[Track(i, float(i), 0.0, 1.7, age=1.0, confidence=0.8) for i in ids],
    )


def outputs(**values) -> Outputs:
    return Outputs(OUTPUTS_PARAMS.create({"udp": "", **values}))


def test_default_destination_is_openptracks_port():
    assert OUTPUTS_PARAMS.create().udp == "127.0.0.1:21234"


def test_heartbeat_comes_every_quarter_second_with_alive_and_max_ids(receiver):
    out = outputs(udp=receiver.address)
    try:
        out.publish(tracks(2, 5))
        documents = receiver.documents(1.1)
    finally:
        out.close()
    beats = [d for d in documents if d["header"]["frame_id"] == "heartbeat"]
    assert len(beats) >= 3
    assert [b["header"]["seq"] for b in beats] == list(range(1, len(beats) + 1))
    stamps = [b["header"]["stamp"]["sec"] + b["header"]["stamp"]["nsec"] * 1e-9 for b in beats]
    assert statistics.median(np.diff(stamps)) == pytest.approx(0.25, abs=0.02)
    assert beats[0]["alive_IDs"] == []  # sent as the outputs start, before any track
    assert beats[1]["alive_IDs"] == [2, 5]
    assert beats[1]["max_ID"] == 5
    frames = [d for d in documents if d["header"]["frame_id"] == "world"]
    assert [t["id"] for t in frames[0]["tracks"]] == [2, 5]


def test_nobody_is_alive_once_tracks_stop_coming(receiver):
    out = outputs(udp=receiver.address, heartbeat_s=0.05, stale_s=0.2)
    try:
        out.publish(tracks(4))
        time.sleep(0.4)
        out.heartbeat()
        last = receiver.documents(0.1)[-1]
    finally:
        out.close()
    assert last["alive_IDs"] == []
    assert last["max_ID"] == 4


def test_the_same_document_goes_to_udp_and_websocket(receiver):
    out = outputs(udp=receiver.address, websocket="127.0.0.1:0", heartbeat_s=60.0)
    try:
        receiver.datagrams(0.1)  # the first heartbeat
        with connect(f"ws://127.0.0.1:{out.websocket_port}", proxy=None) as client:
            deadline = time.monotonic() + 3
            while out.status()[-1].clients < 1 and time.monotonic() < deadline:
                time.sleep(0.01)
            out.publish(tracks(1, stamp=100.0))
            (datagram,) = receiver.datagrams(0.3)
            assert client.recv(timeout=3) == datagram.decode()
    finally:
        out.close()


def test_a_destination_added_while_running_receives_from_then_on(receiver):
    out = outputs(heartbeat_s=60.0)
    try:
        out.publish(tracks(1))
        out.configure({"udp": receiver.address})
        out.publish(tracks(2))
        documents = receiver.documents(0.3)
    finally:
        out.close()
    frames = [d for d in documents if d["header"]["frame_id"] == "world"]
    assert [f["tracks"][0]["id"] for f in frames] == [2]
    assert frames[0]["header"]["seq"] == 2  # sequence numbers go on


def test_a_bad_destination_is_refused_and_the_running_ones_kept(receiver):
    out = outputs(udp=receiver.address, heartbeat_s=60.0)
    try:
        with pytest.raises(OutputError):
            out.configure({"udp": "127.0.0.1:99999"})
        with pytest.raises(OutputError):
            out.configure({"udp_mode": "multicast"})  # 127.0.0.1 is not a group
        assert out.params.udp == receiver.address
        assert out.params.udp_mode == "unicast"
        out.publish(tracks(1))
        assert any(json.loads(d)["header"]["frame_id"] == "world" for d in receiver.datagrams(0.3))
    finally:
        out.close()


def test_status_lists_every_destination(receiver, closed_port):
    out = outputs(
        udp=f"{receiver.address},127.0.0.1:{closed_port}",
        osc=f"127.0.0.1:{closed_port}",
        websocket="127.0.0.1:0",
        heartbeat_s=60.0,
    )
    try:
        for i in range(5):
            out.publish(tracks(i))
        status = {(d.kind, d.address): d for d in out.status()}
    finally:
        out.close()
    assert status[("udp", receiver.address)].sent == 6  # 5 frames and the first heartbeat
    assert status[("udp", f"127.0.0.1:{closed_port}")].errors >= 1
    assert ("osc", f"127.0.0.1:{closed_port}") in status
    assert any(kind == "websocket" for kind, _ in status)
