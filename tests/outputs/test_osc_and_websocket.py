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


@pytest.mark.parametrize(
    ("origin", "admitted"),
    [
        (None, True),  # not a browser page
        ("null", True),  # a file opened from disk
        ("http://localhost:8000", True),
        ("https://localhost", True),
        ("http://127.0.0.1:5173", True),
        ("http://[::1]:8080", True),
        ("https://evil.example", False),
        ("http://localhost.evil.example", False),
        ("http://192.168.1.7", False),
    ],
)
def test_only_pages_of_the_allowed_origins_may_connect(origin, admitted):
    """Issue 20: any web page the operator opened could read the tracks."""
    from websockets.exceptions import InvalidStatus

    server = WebSocketServer("127.0.0.1", 0)
    headers = {"Origin": origin} if origin else {}
    try:
        if admitted:
            with connect(f"ws://127.0.0.1:{server.port}", proxy=None, additional_headers=headers):
                pass
        else:
            with pytest.raises(InvalidStatus, match="403"):
                connect(f"ws://127.0.0.1:{server.port}", proxy=None, additional_headers=headers)
        status = server.status()
        assert (server.refused, status.errors) == ((0, 0) if admitted else (1, 1))
        assert (
            admitted
            or status.last_error == f"a page of {origin} (not in the allowed origins) was refused"
        )
    finally:
        server.close()


def test_a_token_is_required_when_set_and_an_allow_list_can_name_a_page():
    from websockets.exceptions import InvalidStatus

    server = WebSocketServer(
        "127.0.0.1", 0, origins=["https://tracks.example:8443"], token="s3cret"
    )
    url = f"ws://127.0.0.1:{server.port}"
    page = {"Origin": "https://tracks.example:8443"}
    try:
        with connect(f"{url}/?token=s3cret", proxy=None, additional_headers=page):
            pass
        for target, headers in (
            (f"{url}/?token=wrong", page),
            (url, page),
            (f"{url}/?token=s3cret", {"Origin": "null"}),
        ):
            with pytest.raises(InvalidStatus, match="403"):
                connect(target, proxy=None, additional_headers=headers)
        assert server.refused == 3
    finally:
        server.close()


def test_an_oversize_message_closes_its_client_and_is_counted_not_logged_as_a_traceback(caplog):
    from websockets.exceptions import ConnectionClosedError

    server = WebSocketServer("127.0.0.1", 0, max_size=1000)
    try:
        for _ in range(2):
            with connect(f"ws://127.0.0.1:{server.port}", proxy=None) as client:
                client.send("x" * 2000)
                with pytest.raises(ConnectionClosedError, match="1009"):
                    client.recv(timeout=3)
        deadline = time.monotonic() + 3
        while server.oversize < 2 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert server.oversize == 2 and server.status().errors == 2
        with connect(f"ws://127.0.0.1:{server.port}", proxy=None) as client:
            while server.clients < 1 and time.monotonic() < deadline + 3:
                time.sleep(0.01)
            server.send('{"still": "serving"}')
            assert client.recv(timeout=3) == '{"still": "serving"}'
    finally:
        server.close()
    assert not any(record.exc_info for record in caplog.records)
    warnings = [r.getMessage() for r in caplog.records if r.name == "optrack.outputs"]
    assert warnings == [
        "WebSocket output: a client's message over 1000 bytes closed it "
        "(further such clients are only counted)"
    ]
