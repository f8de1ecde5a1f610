"""Skeletons out: OpenPTrack v2's pose message over UDP and WebSocket, OSC bundles, all
read by real receivers on loopback; a frame too large for one datagram is split into
complete documents."""

from __future__ import annotations

import json
import threading
import time

import pytest
from pythonosc.dispatcher import Dispatcher
from pythonosc.osc_bundle import OscBundle
from pythonosc.osc_server import ThreadingOSCUDPServer
from websockets.sync.client import connect

from optrack.outputs import OUTPUTS_PARAMS, Outputs, openptrack_json, osc
from optrack.skeleton.joints import JOINTS
from optrack.types import Skeleton, SkeletonBatch


def skeleton(track_id: int, x: float = 1.0) -> Skeleton:
    joints = {
        name: (x + 0.01 * k, -0.5, 0.1 * k, round(0.05 * k, 2)) for k, name in enumerate(JOINTS)
    }
    return Skeleton(id=track_id, height=1.72, state="tracking", rate_hz=15.0, joints=joints)


BATCH = SkeletonBatch(stamp=1700000000.25, seq=9, skeletons=[skeleton(3), skeleton(8, x=-2.0)])


def test_every_joint_of_ours_has_a_pose_message_name_and_v2s_names_are_kept():
    assert set(openptrack_json.POSE_JOINT_NAMES) == set(JOINTS)
    names = set(openptrack_json.POSE_JOINT_NAMES.values())
    v2 = {"HEAD", "NECK", "CHEST", "RIGHT_SHOULDER", "RIGHT_ELBOW", "RIGHT_WRIST"}
    v2 |= {"LEFT_SHOULDER", "LEFT_ELBOW", "LEFT_WRIST", "RIGHT_HIP", "RIGHT_KNEE"}
    v2 |= {"RIGHT_ANKLE", "LEFT_HIP", "LEFT_KNEE", "LEFT_ANKLE"}
    assert v2 <= names and len(names) == len(JOINTS)


def test_the_pose_document_is_openptrack_v2s():
    (datagram,) = openptrack_json.skeleton_datagrams(4, BATCH, 65000)
    document = json.loads(datagram)
    assert document["header"] == {
        "seq": 4,
        "stamp": {"sec": 1700000000, "nsec": 250000000},
        "frame_id": "world",
    }
    first = document["pose_tracks"][0]
    assert (first["id"], first["height"], first["state"]) == (3, 1.72, "tracking")
    head = JOINTS.index("head")
    assert first["joints"]["HEAD"] == {
        "x": pytest.approx(1.0 + 0.01 * head),
        "y": -0.5,
        "z": pytest.approx(0.1 * head),
        "confidence": pytest.approx(0.05 * head),
    }
    assert first["joints"]["CHEST"]["z"] == pytest.approx(0.1 * JOINTS.index("spine"))
    assert [t["id"] for t in document["pose_tracks"]] == [3, 8]


def test_a_frame_too_large_is_split_into_complete_documents_of_one_seq():
    batch = SkeletonBatch(stamp=5.0, skeletons=[skeleton(i) for i in range(6)])
    datagrams = openptrack_json.skeleton_datagrams(7, batch, 2500)
    assert len(datagrams) > 1 and all(len(d) <= 2500 for d in datagrams)
    documents = [json.loads(d) for d in datagrams]
    assert {d["header"]["seq"] for d in documents} == {7}
    assert [t["id"] for d in documents for t in d["pose_tracks"]] == list(range(6))
    bundles = osc.skeleton_bundles(7, batch, 2500)
    assert len(bundles) > 1 and all(len(b) <= 2500 for b in bundles)
    counts = [next(iter(OscBundle(b))).params[3] for b in bundles]
    assert sum(counts) == 6


def test_udp_osc_and_websocket_receivers_get_the_skeletons(receiver):
    received: list[tuple[str, tuple]] = []
    done = threading.Event()
    dispatcher = Dispatcher()

    def on_message(address, *args):
        if address == "/optrack/alive":  # the heartbeat sent as the outputs start
            return
        received.append((address, args))
        if len(received) == 1 + 2 * len(JOINTS):
            done.set()

    dispatcher.set_default_handler(on_message)
    server = ThreadingOSCUDPServer(("127.0.0.1", 0), dispatcher)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    out = Outputs(
        OUTPUTS_PARAMS.create(
            {
                "udp": receiver.address,
                "osc": f"127.0.0.1:{server.server_address[1]}",
                "websocket": "127.0.0.1:0",
                "heartbeat_s": 60.0,
            }
        )
    )
    try:
        with connect(f"ws://127.0.0.1:{out.websocket_port}", proxy=None) as client:
            deadline = time.monotonic() + 3
            while out.status()[-1].clients < 1 and time.monotonic() < deadline:
                time.sleep(0.01)
            out.publish_skeletons(BATCH)
            web = json.loads(client.recv(timeout=3))
            while "pose_tracks" not in web:  # the heartbeat sent as the outputs start
                web = json.loads(client.recv(timeout=3))
        assert done.wait(3.0)
        documents = [d for d in receiver.documents(0.5) if "pose_tracks" in d]
    finally:
        out.close()
        server.shutdown()
        server.server_close()
    assert len(documents) == 1 and documents[0] == web
    assert [t["id"] for t in web["pose_tracks"]] == [3, 8]
    assert received[0] == ("/optrack/skeletons", (1, 1700000000, 250000000, 2))
    joints = dict(received[1:])
    wrist = JOINTS.index("left_wrist")
    assert joints["/optrack/skeleton/8/left_wrist"] == pytest.approx(
        (-2.0 + 0.01 * wrist, -0.5, 0.1 * wrist), abs=1e-6
    )
    assert len(joints) == 2 * len(JOINTS)
