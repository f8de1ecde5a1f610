"""The Python receiver in examples/ reads what the outputs send."""

from __future__ import annotations

import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

from optrack.outputs import OUTPUTS_PARAMS, Outputs
from optrack.types import Skeleton, SkeletonBatch, Track, TrackBatch

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def received(port: int, count: int, send: Callable[[Outputs], None]) -> list[str]:
    """The lines the Python receiver prints for ``count`` datagrams of what ``send`` sends
    (after the heartbeat sent as the outputs start)."""
    receiver = subprocess.Popen(
        [
            sys.executable,
            str(EXAMPLES / "python_udp_receiver.py"),
            "--host",
            "127.0.0.1",
            "--port",
            str(port),
            "--count",
            str(count),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert receiver.stdout.readline().startswith("listening on 127.0.0.1")
        outputs = Outputs(OUTPUTS_PARAMS.create({"udp": f"127.0.0.1:{port}", "heartbeat_s": 60.0}))
        try:
            time.sleep(0.1)
            send(outputs)
            out, _ = receiver.communicate(timeout=10)
        finally:
            outputs.close()
    finally:
        receiver.kill()
        receiver.wait()
    return out.strip().splitlines()


def test_python_udp_receiver_prints_tracks_and_heartbeats(closed_port):
    def send(outputs: Outputs) -> None:
        outputs.publish(TrackBatch(stamp=10.0, tracks=[Track(4, 1.5, -0.25, 1.8, age=2.0)]))
        outputs.publish(TrackBatch(stamp=10.1))

    lines = received(closed_port, 3, send)  # the port is free now: the receiver binds it
    assert "alive [] max 0" in lines[0]  # the heartbeat sent as the outputs start
    assert lines[1] == "10.000 frame 1: #4 (+1.50, -0.25) 1.80 m"
    assert lines[2] == "10.100 frame 2: nobody"


def test_python_udp_receiver_prints_skeletons(closed_port):
    def send(outputs: Outputs) -> None:
        head = {"head": (1.5, -0.25, 1.62, 0.9)}
        skeleton = Skeleton(id=4, height=1.8, state="tracking", joints=head)
        outputs.publish_skeletons(SkeletonBatch(stamp=10.0, skeletons=[skeleton]))

    lines = received(closed_port, 2, send)
    assert lines[1] == "10.000 skeletons 1: #4 tracking head (+1.50, -0.25, 1.62)"
