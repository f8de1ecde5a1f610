"""The detector node in-process on a real bus, with the real detector on simulated Kinect v2
frames: live parameters, calibration from the bus, status, stamps in tracker time."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from optrack.calibration.files import load_network
from optrack.detection.params import detection_params
from optrack.net.clock import CLOCK_PARAMS, ClockServer, ClockSync
from optrack.net.messages import (
    CalibrationMessage,
    DetectionsMessage,
    ParamsMessage,
    StatusMessage,
)
from optrack.runtime.calibration_store import CalibrationStore
from optrack.runtime.config import NODE_PARAMS
from optrack.runtime.detector_node import DetectorNode, people_detector
from optrack.runtime.replay import LiveReplay
from optrack.types import NetworkCalibration, SensorCalibration


class Collector:
    def __init__(self) -> None:
        self.items: list = []
        self.lock = threading.Lock()

    def __call__(self, message, key) -> None:
        with self.lock:
            self.items.append(message)

    def wait_for(self, predicate, timeout: float = 5.0):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self.lock:
                found = [m for m in self.items if predicate(m)]
            if found:
                return found
            time.sleep(0.01)
        raise AssertionError("nothing arrived in time")


@pytest.fixture
def node_setup(venue, hub, make_client, tmp_path):
    """A detector node for sensor kinect2_0 of the venue (not running: the test steps it)."""
    ClockServer(hub)
    bus = make_client("kinect2_0")
    sensor = LiveReplay(venue, "kinect2_0", loop=True)
    sync = ClockSync(bus, CLOCK_PARAMS.create())
    made = []

    def make(factory=people_detector, **node_values) -> DetectorNode:
        time.sleep(0.1)
        sync.measure()
        node = DetectorNode(
            bus,
            sensor,
            detection_params("kinect2"),
            NODE_PARAMS.create({"preview_hz": 0.0, **node_values}),
            sync,
            CalibrationStore(tmp_path / "state" / "kinect2_0"),
            factory=factory,
        )
        made.append(node)
        time.sleep(0.3)  # let the node's subscriptions reach the hub
        return node

    yield make
    for node in made:
        node.close()


def wait_inbox(node: DetectorNode, timeout: float = 3.0) -> None:
    deadline = time.monotonic() + timeout
    while not node._inbox and time.monotonic() < deadline:
        time.sleep(0.01)
    assert node._inbox, "the update did not reach the node"


def step_until_detections(node: DetectorNode, batches: Collector, frames: int = 30):
    """Step until a frame with people (the venue always has some in view within a second)."""
    for _ in range(frames):
        node.step()
        latest = batches.wait_for(lambda m: m.batch.seq == node.frames - 1)[-1]
        if latest.batch.detections:
            return latest
    raise AssertionError("no one detected")


def test_a_parameter_update_changes_the_next_frame(node_setup, hub):
    node = node_setup()
    batches = Collector()
    hub.subscribe(hub.keys.detections(), DetectionsMessage, batches)
    time.sleep(0.2)
    step_until_detections(node, batches)
    hub.publish(
        hub.keys.params("kinect2_0"),
        ParamsMessage(updates={"detection": {"max_distance": 0.5}}, request="r1"),
        realtime=False,
    )
    wait_inbox(node)
    node.step()
    after = batches.wait_for(lambda m: m.batch.seq == node.frames - 1)[-1]
    assert node.detection.max_distance == 0.5
    assert after.batch.detections == []  # nobody within 0.5 m of the camera
    assert node.request == "r1"


def test_a_bad_parameter_update_is_refused_whole_and_reported(node_setup, hub):
    node = node_setup()
    before = node.detection.as_dict()
    hub.publish(
        hub.keys.params("kinect2_0"),
        ParamsMessage(updates={"detection": {"voxel_size": 0.08, "max_distance": -3.0}}),
        realtime=False,
    )
    wait_inbox(node)
    node.apply_params()
    assert node.detection.as_dict() == before  # all or nothing
    assert "detection.max_distance must be between" in node.last_error
    assert node.params_refused == 1
    hub.publish(
        hub.keys.params("kinect2_0"),
        ParamsMessage(updates={"tracking": {"gate_probability": 0.9}}),
        realtime=False,
    )
    wait_inbox(node)
    node.apply_params()
    assert "takes no 'tracking' parameters" in node.last_error


def shifted(venue_pose: np.ndarray, dx: float) -> tuple:
    pose = venue_pose.copy()
    pose[0, 3] += dx
    return tuple(tuple(float(v) for v in row) for row in pose)


def test_a_published_calibration_is_stored_and_used_from_the_next_frame(node_setup, hub):
    node = node_setup()
    truth = np.asarray(node.info.world_T_camera)
    batches = Collector()
    hub.subscribe(hub.keys.detections(), DetectionsMessage, batches)
    time.sleep(0.2)
    for dx, notes in ((1.0, "first"), (3.0, "second")):
        hub.publish(
            hub.keys.calibration,
            CalibrationMessage(
                calibration=NetworkCalibration(
                    sensors={"kinect2_0": SensorCalibration(world_T_camera=shifted(truth, dx))},
                    notes=notes,
                )
            ),
            realtime=False,
        )
        deadline = time.monotonic() + 3
        while (
            node._pending is None or node._pending.notes != notes
        ) and time.monotonic() < deadline:
            time.sleep(0.01)
    store = node.store
    assert load_network(store.path).notes == "second"
    assert load_network(store.previous_path).notes == "first"  # the previous file is kept
    latest = step_until_detections(node, batches)
    assert node.calibration_id == "second"
    for d in latest.batch.detections:
        expected = truth @ np.append(d.camera_xyz, 1.0)
        assert d.x == pytest.approx(expected[0] + 3.0, abs=1e-6)
        assert d.y == pytest.approx(expected[1], abs=1e-6)


def test_a_calibration_without_this_sensor_is_refused_and_the_pose_kept(node_setup, hub):
    node = node_setup()
    pose = node.world_T_camera.copy()
    hub.publish(
        hub.keys.calibration,
        CalibrationMessage(
            calibration=NetworkCalibration(
                sensors={"other": SensorCalibration(world_T_camera=shifted(np.eye(4), 1.0))}
            )
        ),
        realtime=False,
    )
    deadline = time.monotonic() + 3
    while "has no sensor 'kinect2_0'" not in node.last_error and time.monotonic() < deadline:
        time.sleep(0.01)
    node.step()
    assert "has no sensor 'kinect2_0'" in node.last_error
    assert np.array_equal(node.world_T_camera, pose)
    assert not node.store.path.exists()


def test_detections_are_stamped_in_tracker_time_and_status_reports_the_rates(node_setup, hub):
    node = node_setup()
    batches = Collector()
    statuses = Collector()
    hub.subscribe(hub.keys.detections(), DetectionsMessage, batches)
    hub.subscribe(hub.keys.status(), StatusMessage, statuses)
    time.sleep(0.2)
    arrivals = []
    for _ in range(10):
        node.step()
        arrivals.append(time.time())
    found = batches.wait_for(lambda m: m.batch.seq == 9)
    last = found[-1]
    # Captured (due) before it was published, and not long before.
    assert 0.0 < arrivals[-1] - last.batch.stamp < 1.0
    assert last.clock_uncertainty_s is not None and last.clock_uncertainty_s < 0.005
    node.publish_status()
    status = statuses.wait_for(lambda m: m.node == "kinect2_0")[-1]
    assert status.role == "detector"
    assert status.fps > 0 and status.latency_ms > 0
    assert status.clock_offset_ms == pytest.approx(0.0, abs=2.0)
    assert status.values["frames"] == 10
    assert status.values["calibrated"] is True
    assert status.params["detection"]["max_distance"] == node.detection.max_distance


class FailsOnce:
    def __init__(self, inner) -> None:
        self.inner = inner
        self.calls = 0

    def process(self, frame):
        self.calls += 1
        if self.calls == 2:
            raise RuntimeError("a detector bug")
        return self.inner.process(frame)


def test_a_detector_failure_is_reported_and_the_next_frame_goes_on(node_setup):
    node = node_setup(
        factory=lambda info, pose, params: FailsOnce(people_detector(info, pose, params))
    )
    for _ in range(3):
        assert node.step()
    assert node.failures == 1
    assert node.frames == 2
    assert "a detector bug" in node.last_error


def test_preview_is_small_and_decodes_to_a_frame(node_setup, hub):
    from optrack.net.messages import PreviewMessage
    from optrack.runtime.preview import decode_preview

    node = node_setup(preview_hz=30.0, preview_width=128, preview_points=500)
    previews = Collector()
    hub.subscribe(hub.keys.preview(), PreviewMessage, previews)
    time.sleep(0.2)
    node.step()
    message = previews.wait_for(lambda m: m.sensor == "kinect2_0")[0]
    frame, cloud = decode_preview(message)
    assert frame.depth.shape[1] == 128
    assert frame.color is not None and frame.color.shape[:2] == frame.depth.shape
    assert cloud.shape == (500, 3)
    assert message.cloud_frame == "world"
    assert len(message.depth_png) + len(message.color_jpeg) + len(message.cloud) < 100_000


class Delivered:
    """A camera whose frames arrive ``delay_s`` after their capture, stamped then on this
    computer's clock when ``host_clock`` (a simulated sensor renders after the capture)."""

    def __init__(self, inner, delay_s: float, host_clock: bool) -> None:
        self.inner, self.delay_s, self.host_clock = inner, delay_s, host_clock
        self.captured = self.delivered = 0.0

    @property
    def info(self):
        return self.inner.info

    def read(self):
        frame = self.inner.read()
        frame.timestamp = self.captured = time.time()
        time.sleep(self.delay_s)
        self.delivered = time.time()
        return frame

    def close(self) -> None:
        self.inner.close()


@pytest.mark.parametrize("host_clock", [True, False])
def test_a_sensor_stamping_its_captures_on_this_clock_is_stamped_at_the_capture(
    venue, hub, make_client, tmp_path, host_clock
):
    ClockServer(hub)
    bus = make_client("kinect2_0")
    sync = ClockSync(bus, CLOCK_PARAMS.create())
    time.sleep(0.1)
    sync.measure()
    sensor = Delivered(LiveReplay(venue, "kinect2_0", loop=True), 0.3, host_clock)
    node = DetectorNode(
        bus,
        sensor,
        detection_params("kinect2"),
        NODE_PARAMS.create({"preview_hz": 0.0}),
        sync,
        CalibrationStore(tmp_path / "state" / "kinect2_0"),
    )
    batches = Collector()
    hub.subscribe(hub.keys.detections(), DetectionsMessage, batches)
    time.sleep(0.3)
    try:
        node.step()
        stamp = batches.wait_for(lambda m: m.batch.seq == 0)[-1].batch.stamp
    finally:
        node.close()
    # Tracker time is this computer's clock here (one process; offset within milliseconds).
    if host_clock:  # the capture, 0.3 s before the frame arrived
        assert stamp == pytest.approx(sensor.captured, abs=0.05)
    else:  # the arrival
        assert stamp == pytest.approx(sensor.delivered, abs=0.05)
