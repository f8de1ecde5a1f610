"""The calibration capture on a detector node, over loopback: board views published with
corners, the floor test and a preview; refused commands as one sentence; board-view
messages validated like every bus message."""

from __future__ import annotations

import copy
import threading
import time

import cv2
import msgspec
import numpy as np
import pytest

from optrack.net.clock import ClockSync
from optrack.net.messages import BoardViewMessage, encode
from optrack.runtime.board_capture import CalibrationCapture
from optrack.runtime.config import NODE_PARAMS
from optrack.runtime.node import CommandError, Node, send_command
from optrack.sim.world import Simulation

BOARD = {"cols": 6, "rows": 5, "square": 0.15}


@pytest.fixture(scope="module")
def scene():
    """The `calibration` scenario (3 sensors, no noise) and the operator's timeline."""
    sim = Simulation("calibration", seed=0, sensors=3)
    return sim


def _frame_when(sim: Simulation, sensor: int, want_floor: bool):
    """A rendered frame of ``sensor`` while the simulated operator holds the board still
    (in the air, or lying on the floor) where that sensor sees it."""
    operator = sim.operator
    t = sim.crowd.t
    while t < sim.seconds:
        t += 0.25
        state = sim.snapshot(t)
        step = operator.steps[min(operator.index, len(operator.steps) - 1)]
        holding = operator.phase == "hold" and state.board_on_floor == want_floor
        if holding and sensor in step.sensors:
            return sim.frame(sensor, int(t * 30), state, noise=False)
    raise AssertionError("the simulated operator never held the board there")


class _Views:
    def __init__(self) -> None:
        self.items: list[BoardViewMessage] = []
        self.event = threading.Event()

    def __call__(self, message: BoardViewMessage, key: str) -> None:
        self.items.append(message)
        self.event.set()

    def next(self, timeout: float = 20.0) -> BoardViewMessage:
        assert self.event.wait(timeout), "no board view arrived"
        self.event.clear()
        return self.items[-1]


def _capture(hub, name: str, info):
    node = Node(hub, name, NODE_PARAMS.create(), {})
    capture = CalibrationCapture(hub, info, ClockSync(hub))
    capture.register(node.add_command)
    return node, capture


def test_a_node_publishes_board_views_with_corners_floor_test_and_preview(hub, make_client, scene):
    info = scene.sensors[0].info
    node, capture = _capture(hub, info.id, info)
    client = make_client("wizard")
    views = _Views()
    client.subscribe(client.keys.board_views(), BoardViewMessage, views)
    try:
        reply = send_command(client, info.id, "calibration_start", {"phase": "floor", **BOARD})
        assert reply["image"] == "color" and reply["intrinsics"]["width"] == 512
        held = _frame_when(scene, 0, want_floor=False)
        assert capture.offer(held, 1000.0) is True  # the capture has the frame alone
        view = views.next()
        assert view.sensor == info.id and view.stamp == pytest.approx(1000.0)
        assert view.corners is not None and len(view.corners) == 30
        assert view.on_floor is False
        preview = cv2.imdecode(np.frombuffer(view.preview_jpeg, np.uint8), cv2.IMREAD_COLOR)
        assert preview.shape[1] == 320
        capture.wait_ready(threading.Event())
        lying = _frame_when(scene, 0, want_floor=True)
        capture.offer(lying, 1001.0)
        view = views.next()
        assert view.corners is not None and view.on_floor is True
        capture.wait_ready(threading.Event())
        away = copy.copy(lying)
        away.color = np.full_like(lying.color, 128)  # nothing to find
        capture.offer(away, 1002.0)
        assert views.next().corners is None
        stopped = send_command(client, info.id, "calibration_stop")
        assert stopped == {"sensor": info.id, "searched": 3, "found": 2}
        assert capture.offer(away, 1003.0) is False  # detection goes on
        assert capture.status_values()["capture"] == "off"
    finally:
        capture.close()
        node.close()


def test_a_refused_capture_command_comes_back_as_one_sentence(hub, make_client, scene):
    info = scene.sensors[1].info
    node, capture = _capture(hub, info.id, info)
    client = make_client("wizard")
    try:
        cases = [
            ({"phase": "extrinsics", "cols": 8, "rows": 6, "square": 0.1}, "8x6"),
            ({"phase": "sideways", **BOARD}, "calibration phase 'sideways' is unknown"),
            ({"phase": "extrinsics", "cols": 6}, "needs the board's rows"),
            ({"phase": "floor", **BOARD, "rate_hz": 500}, "rate_hz"),
        ]
        for args, words in cases:
            with pytest.raises(CommandError) as refused:
                send_command(client, info.id, "calibration_start", args)
            sentence = str(refused.value)
            assert words in sentence
            assert "\n" not in sentence and sentence.endswith(".")
        assert not capture.active
    finally:
        capture.close()
        node.close()


def test_board_view_messages_are_validated_like_every_bus_message(hub, make_client):
    listener = make_client("wizard")
    views = _Views()
    listener.subscribe(listener.keys.board_views(), BoardViewMessage, views)
    sender = make_client("cam0")
    key = sender.keys.board_views("cam0")
    good = BoardViewMessage(
        sensor="cam0",
        stamp=5.0,
        phase="extrinsics",
        seq=1,
        image="color",
        intrinsics=Simulation("calibration", sensors=1).sensors[0].info.intrinsics,
        corners=[(1.0, 2.0)],
    )
    data = msgspec.msgpack.decode(encode(good))
    sender.put_raw(key, msgspec.msgpack.encode({**data, "colour": "red"}))  # unknown field
    sender.put_raw(key, msgspec.msgpack.encode({**data, "v": 99}))  # another wire version
    sender.put_raw(key, msgspec.msgpack.encode({**data, "corners": [[1.0, float("nan")]]}))
    sender.publish(key, good)
    assert views.next().corners == [(1.0, 2.0)]
    deadline = time.monotonic() + 5
    while listener.stats.snapshot()["rejected"] < 3 and time.monotonic() < deadline:
        time.sleep(0.05)
    counts = listener.stats.snapshot()
    assert counts["rejected_invalid"] == 2 and counts["rejected_version"] == 1
    assert len(views.items) == 1
