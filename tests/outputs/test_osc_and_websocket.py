"""OSC bundles read by python-osc's own server, and the WebSocket server read by a
websockets client: the same tracks, the same JSON."""

from __future__ import annotations

import json
import threading
import time

import pytest
from pythonosc.dispatcher import Dispatcher
from pythonosc.osc_bundle import OscBundle
from pythonosc.osc_server import ThreadingOSCUDPServer
from websockets.sync.client import connect

from optrack.outputs import osc
from optrack.outputs.udp import OutputError
from optrack.outputs.websocket import WebSocketServer
from optrack.types import Track, TrackBatch

BATCH = TrackBatch(
    stamp=1700000000.5,
    tracks=[Track(3, 1.25, -0.5, 1.72, age=4.0), Track(8, -2.0, 0.75, 1.6, age=1.0)],
)


def test_frame_bundle_holds_one_track_message_per_track():
    bundle = OscBundle(osc.frame_bundle(12, BATCH))
    messages = [(m.address, m.params) for m in bundle]
    assert messages[0] == ("/optrack/frame", [12, 1700000000, 500000000, 2])
    assert messages[1][0] == "/optrack/track"
    assert messages[1][1][0] == 3
    assert messages[1][1][1:] == pytest.approx([1.25, -0.5, 1.72], abs=1e-6)
    assert messages[2][1][0] == 8
    assert len(messages) == 3


def test_alive_bundle_lists_max_id_then_alive_ids():
    (message,) = list(OscBundle(osc.alive_bundle([3, 8], 9)))
    assert (message.address, message.params) == ("/optrack/alive", [9, 3, 8])


def test_python_osc_server_receives_the_tracks():
    received: list[tuple[str, tuple]] = []
    done = threading.Event()
    dispatcher = Dispatcher()

    def on_track(address, *args):
        received.append((address, args))
        if len(received) == 2:
            done.set()

    dispatcher.map("/optrack/track", on_track)
    server = ThreadingOSCUDPServer(("127.0.0.1", 0), dispatcher)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        from optrack.outputs.udp import Destination

        destination = Destination("osc", "127.0.0.1", server.server_address[1])
        destination.send(osc.frame_bundle(1, BATCH))
        assert done.wait(3.0)
        destination.close()
    finally:
        server.shutdown()
        server.server_close()
    assert [args[0] for _, args in received] == [3, 8]


def test_websocket_clients_receive_each_document():
    server = WebSocketServer("127.0.0.1", 0)
    try:
        with (
            connect(f"ws://127.0.0.1:{server.port}", proxy=None) as first,
            connect(f"ws://127.0.0.1:{server.port}", proxy=None) as second,
        ):
            deadline = time.monotonic() + 3
            while server.clients < 2 and time.monotonic() < deadline:
                time.sleep(0.01)
            document = json.dumps({"header": {"seq": 1}, "tracks": []})
            server.send(document)
            assert first.recv(timeout=3) == document
            assert second.recv(timeout=3) == document
            assert server.status().clients == 2
    finally:
        server.close()


def test_websocket_port_in_use_is_refused_with_one_sentence():
    server = WebSocketServer("127.0.0.1", 0)
    try:
        with pytest.raises(OutputError, match="choose a free port"):
            WebSocketServer("127.0.0.1", server.port)
    finally:
        server.close()


def test_a_client_that_leaves_does_not_disturb_the_server():
    server = WebSocketServer("127.0.0.1", 0)
    try:
        with connect(f"ws://127.0.0.1:{server.port}", proxy=None):
            pass
        server.send("{}")
        with connect(f"ws://127.0.0.1:{server.port}", proxy=None) as client:
            deadline = time.monotonic() + 3
            while server.clients < 1 and time.monotonic() < deadline:
                time.sleep(0.01)
            server.send('{"after":1}')
            assert client.recv(timeout=3) == '{"after":1}'
    finally:
        server.close()
