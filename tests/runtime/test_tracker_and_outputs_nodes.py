"""The tracker and outputs nodes in-process on a real bus: detections in, OpenPTrack JSON
out over UDP; refused batches; the calibration kept for late nodes; live outputs."""

from __future__ import annotations

import json
import socket
import threading
import time
from collections.abc import Iterator

import numpy as np
import pytest

from optrack.net.messages import (
    CalibrationMessage,
    DetectionsMessage,
    ParamsMessage,
    StatusMessage,
)
from optrack.outputs import OUTPUTS_PARAMS
from optrack.runtime.calibration_store import CalibrationStore
from optrack.runtime.config import NODE_PARAMS
from optrack.runtime.detector_node import CalibrationRequest
from optrack.runtime.outputs_node import OutputsNode
from optrack.runtime.tracker_node import TrackerNode
from optrack.types import Detection, DetectionBatch, NetworkCalibration, SensorCalibration


@pytest.fixture
def receiver() -> Iterator[socket.socket]:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    yield sock
    sock.close()


def documents(sock: socket.socket, seconds: float) -> list[dict]:
    found = []
    deadline = time.monotonic() + seconds
    while (left := deadline - time.monotonic()) > 0:
        sock.settimeout(left)
        try:
            found.append(json.loads(sock.recv(65536)))
        except TimeoutError:
            break
    return found


@pytest.fixture
def site(hub, tmp_path, receiver):
    """A running tracker node and outputs node sharing the hub's bus (as 'optrack node track')."""
    address = f"127.0.0.1:{receiver.getsockname()[1]}"
    tracker = TrackerNode(
        hub, NODE_PARAMS.create({"status_period_s": 0.2}), CalibrationStore(tmp_path / "tracker")
    )
    outputs = OutputsNode(hub, NODE_PARAMS.create(), OUTPUTS_PARAMS.create({"udp": address}))
    thread = threading.Thread(target=tracker.run, daemon=True)
    thread.start()
    yield tracker, outputs
    tracker.stop()
    thread.join(5)
    outputs.close()


def person(x: float, y: float, sensor: str, t: float) -> DetectionsMessage:
    return DetectionsMessage(
        batch=DetectionBatch(sensor, t, detections=[Detection(x, y, 0.9, 1.75, 2.0)])
    )


def walk(node_bus, sensors: list[str], seconds: float, rate: float = 30.0) -> None:
    """One person walking along x, seen by every sensor, in real time."""
    start = time.time()
    k = 0
    while (t := time.time()) - start < seconds:
        sensor = sensors[k % len(sensors)]
        node_bus.publish(
            node_bus.keys.detections(sensor), person(1.0 * (t - start), 0.5, sensor, t)
        )
        k += 1
        time.sleep(1.0 / rate)


def test_detections_in_openptrack_json_out(site, make_client, receiver):
    camera = make_client("cams")
    time.sleep(0.2)
    walk(camera, ["cam0", "cam1"], 1.5)
    found = documents(receiver, 0.5)
    frames = [d for d in found if d["header"]["frame_id"] == "world" and d["tracks"]]
    beats = [d for d in found if d["header"]["frame_id"] == "heartbeat"]
    assert frames, "no tracks came out"
    track = frames[-1]["tracks"][0]
    assert set(track) == {"id", "x", "y", "height", "age", "confidence"}
    assert track["y"] == pytest.approx(0.5, abs=0.1)
    assert track["height"] == pytest.approx(1.75, abs=0.05)
    assert beats and beats[-1]["alive_IDs"] == [track["id"]]
    stamp = frames[-1]["header"]["stamp"]
    assert time.time() - (stamp["sec"] + stamp["nsec"] * 1e-9) < 1.0


def test_a_batch_on_another_sensors_key_is_refused(site, make_client):
    tracker, _ = site
    camera = make_client("cams")
    time.sleep(0.2)
    camera.publish(camera.keys.detections("cam0"), person(0, 0, "cam1", time.time()))
    deadline = time.monotonic() + 3
    while tracker.refused == 0 and time.monotonic() < deadline:
        time.sleep(0.01)
    assert tracker.refused == 1
    assert "each sensor publishes on its own key" in tracker.last_error


def test_uncalibrated_detections_are_refused_with_the_trackers_sentence(site, make_client):
    tracker, _ = site
    camera = make_client("cams")
    time.sleep(0.2)
    message = person(0, 0, "cam0", time.time())
    message.batch.frame_id = "ground"
    camera.publish(camera.keys.detections("cam0"), message)
    deadline = time.monotonic() + 3
    while tracker.refused == 0 and time.monotonic() < deadline:
        time.sleep(0.01)
    assert "give the detector the calibration" in tracker.last_error


def test_detections_stamped_ahead_of_the_tracker_clock_are_refused_and_counted(site, make_client):
    """A node not synchronised yet (its clock 0.5 s ahead) must not move the tracker's
    time forward; once its stamps are in tracker time its detections are used."""
    tracker, _ = site
    camera = make_client("cams")
    time.sleep(0.2)
    camera.publish(camera.keys.detections("cam0"), person(0, 0, "cam0", time.time() + 0.5))
    deadline = time.monotonic() + 3
    while tracker.future == 0 and time.monotonic() < deadline:
        time.sleep(0.01)
    assert (tracker.future, tracker.refused, tracker.batches) == (1, 1, 0)
    assert "sensor 'cam0' are stamped" in tracker.last_error
    assert "ahead of the tracker's clock" in tracker.last_error
    assert tracker.status_fields()["values"]["future_batches"] == 1
    camera.publish(camera.keys.detections("cam0"), person(0, 0, "cam0", time.time()))
    deadline = time.monotonic() + 3
    while tracker.batches == 0 and time.monotonic() < deadline:
        time.sleep(0.01)
    assert (tracker.batches, tracker.future) == (1, 1)


def test_the_tracker_keeps_the_calibration_for_nodes_that_start_later(site, make_client):
    tracker, _ = site
    gui = make_client("gui")
    time.sleep(0.2)
    pose = tuple(tuple(float(v) for v in row) for row in np.eye(4))
    gui.publish(
        gui.keys.calibration,
        CalibrationMessage(
            calibration=NetworkCalibration(
                sensors={"cam0": SensorCalibration(world_T_camera=pose)}, notes="cal-1"
            )
        ),
        realtime=False,
    )
    deadline = time.monotonic() + 3
    while tracker.calibration is None and time.monotonic() < deadline:
        time.sleep(0.01)
    late = make_client("cam0")
    time.sleep(0.2)
    (reply,) = late.query(late.keys.calibration, CalibrationRequest(), CalibrationMessage, 2.0)
    assert reply.calibration.notes == "cal-1"
    assert tracker.store.path.exists()


def test_outputs_change_destination_while_running(site, make_client, receiver):
    _, outputs = site
    other = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    other.bind(("127.0.0.1", 0))
    try:
        gui = make_client("gui")
        statuses = []
        gui.subscribe(gui.keys.status("outputs"), StatusMessage, lambda m, k: statuses.append(m))
        time.sleep(0.2)
        gui.publish(
            gui.keys.params("outputs"),
            ParamsMessage(updates={"outputs": {"udp": f"127.0.0.1:{other.getsockname()[1]}"}}),
            realtime=False,
        )
        assert documents(other, 1.0), "the new destination received nothing"
        gui.publish(
            gui.keys.params("outputs"),
            ParamsMessage(updates={"outputs": {"udp_mode": "multicast"}}),
            realtime=False,
        )
        deadline = time.monotonic() + 3
        while "not a multicast group" not in outputs.last_error and time.monotonic() < deadline:
            time.sleep(0.01)
        assert "not a multicast group" in outputs.last_error
        assert outputs.live["outputs"].udp_mode == "unicast"
        outputs.publish_status()
        deadline = time.monotonic() + 3
        while not statuses and time.monotonic() < deadline:
            time.sleep(0.01)
        assert [d.kind for d in statuses[-1].destinations] == ["udp"]
    finally:
        other.close()


@pytest.fixture
def direct(hub, tmp_path, receiver, request):
    """The tracker node handing its frames straight to the outputs (as `optrack node track`
    and `optrack run` do), with a quick fixed rate and drop delay."""
    from optrack.tracking.params import SMOOTHING_PARAMS

    mode = getattr(request, "param", "update")
    address = f"127.0.0.1:{receiver.getsockname()[1]}"
    node_params = NODE_PARAMS.create({"status_period_s": 0.2, "tracks_publish": mode})
    outputs = OutputsNode(
        hub, NODE_PARAMS.create(), OUTPUTS_PARAMS.create({"udp": address}), subscribe=False
    )
    tracker = TrackerNode(
        hub,
        node_params,
        CalibrationStore(tmp_path / "tracker"),
        live={"smoothing": SMOOTHING_PARAMS.create({"rate": 20.0, "drop_after": 0.3})},
        sinks=[outputs.send],
    )
    thread = threading.Thread(target=tracker.run, daemon=True)
    thread.start()
    yield tracker
    tracker.stop()
    thread.join(5)
    outputs.close()


def stamp_of(document: dict) -> float:
    return document["header"]["stamp"]["sec"] + document["header"]["stamp"]["nsec"] * 1e-9


def test_every_batch_goes_out_at_once_stamped_with_its_capture_instant(
    direct, make_client, receiver
):
    camera = make_client("cams")
    time.sleep(0.2)
    stamps = []
    for k in range(12):
        t = time.time()
        sensor = f"cam{k % 2}"
        camera.publish(camera.keys.detections(sensor), person(0.1 * k, 0.5, sensor, t))
        stamps.append(t)
        time.sleep(0.02)  # faster than the fixed rate: no repeat in between
    frames = [d for d in documents(receiver, 0.2) if d["header"]["frame_id"] == "world"]
    sent = [stamp_of(d) for d in frames]
    for t in stamps:  # one datagram per batch, carrying that frame's capture instant
        assert any(abs(s - t) < 1e-6 for s in sent), f"no datagram for the frame of {t}"
    assert direct.batches == 12
    assert direct.published >= 12
    assert [d["tracks"] for d in frames if abs(stamp_of(d) - stamps[-1]) < 1e-6][0]


def test_between_batches_tracks_repeat_at_the_fixed_rate_then_unseen_ones_drop(
    direct, make_client, receiver
):
    camera = make_client("cams")
    time.sleep(0.2)
    walk(camera, ["cam0"], 0.5, rate=30.0)
    last = time.time()
    found = documents(receiver, 1.2)
    frames = [d for d in found if d["header"]["frame_id"] == "world"]
    after = [d for d in frames if stamp_of(d) >= last - 0.05]
    repeats = [d for d in frames if abs(stamp_of(d) - stamp_of(after[0])) < 1e-6]
    # 20 Hz for about 1.2 s after the last batch: the same stamp, sent again and again
    assert len(repeats) >= 12, [stamp_of(d) for d in frames]
    assert repeats[0]["tracks"], "the person is in the first repeats"
    assert not repeats[-1]["tracks"], "a track unseen for drop_after is left out"
    beats = [d for d in found if d["header"]["frame_id"] == "heartbeat"]
    assert beats and beats[-1]["alive_IDs"] == [] and beats[-1]["max_ID"] >= 1
    assert direct.repeats >= 12


@pytest.mark.parametrize("direct", ["rate"], indirect=True)
def test_at_a_fixed_rate_only_the_newest_state_goes_out(direct, make_client, receiver):
    camera = make_client("cams")
    time.sleep(0.2)
    walk(camera, ["cam0", "cam1"], 1.0, rate=60.0)
    frames = [d for d in documents(receiver, 0.1) if d["header"]["frame_id"] == "world"]
    # about 20 frames for about 60 batches; each stamp the newest capture instant so far
    assert direct.batches >= 30
    assert 10 <= len(frames) <= 30, len(frames)
    stamps = [stamp_of(d) for d in frames]
    assert stamps == sorted(stamps)
