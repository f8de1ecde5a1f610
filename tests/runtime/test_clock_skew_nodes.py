"""`optrack node track` and two `optrack node detect` processes on loopback, one with its
clock 250 ms ahead: its offset is estimated within 2 ms and its detections land in the
right time order (stamped in tracker time, never in the future, none dropped as late)."""

from __future__ import annotations

import threading
import time

import pytest
import yaml

from optrack.net.bus import Bus
from optrack.net.config import BUS_PARAMS
from optrack.net.messages import DetectionsMessage, StatusMessage

from .conftest import free_port


def write_config(path, port: int, state, **stages) -> str:
    data = {
        "bus": {"local_port": port},
        "node": {"state_dir": str(state), "status_period_s": 0.5},
        "outputs": {"udp": ""},
        "clock": {"period_s": 0.5},
        **stages,
    }
    path.write_text(yaml.safe_dump(data))
    return str(path)


def test_a_node_250ms_ahead_is_synchronised_and_its_detections_keep_time_order(
    venue, processes, tmp_path
):
    port = free_port()
    state = tmp_path / "state"
    plain = write_config(tmp_path / "plain.yaml", port, state)
    skewed = write_config(tmp_path / "skewed.yaml", port, state, clock={"skew_s": 0.25})
    tracker = processes.start(
        ["optrack.cli", "node", "track", "--site", "skew", "--config", plain], "tracker"
    )
    observer = Bus(
        "skew", "observer", BUS_PARAMS.create({"local_port": port, "connect_timeout_s": 60.0})
    )
    lock = threading.Lock()
    arrivals: list[tuple[float, DetectionsMessage]] = []
    statuses: dict[str, StatusMessage] = {}

    def on_detections(message: DetectionsMessage, key: str) -> None:
        with lock:
            arrivals.append((time.time(), message))

    def on_status(message: StatusMessage, key: str) -> None:
        with lock:
            statuses[message.node] = message

    try:
        observer.subscribe(observer.keys.detections(), DetectionsMessage, on_detections)
        observer.subscribe(observer.keys.status(), StatusMessage, on_status)
        # The nodes measure their clock offset against the tracker as they start: start
        # them once it answers (a node started before it stamps in its own time until then).
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and "tracker" not in statuses:
            time.sleep(0.1)
        uri = f"file://{venue}?loop=true#"
        processes.start(
            [
                "optrack.cli",
                "node",
                "detect",
                "--sensor",
                uri + "kinect2_0",
                "--site",
                "skew",
                "--config",
                plain,
            ],
            "plain",
        )
        processes.start(
            [
                "optrack.cli",
                "node",
                "detect",
                "--sensor",
                uri + "kinect2_1",
                "--site",
                "skew",
                "--config",
                skewed,
            ],
            "skewed",
        )
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:
            with lock:
                counts = {
                    s: sum(m.batch.sensor_id == s for _, m in arrivals)
                    for s in ("kinect2_0", "kinect2_1")
                }
                skewed_status = statuses.get("kinect2_1")
            if (
                min(counts.values()) >= 30
                and skewed_status is not None
                and skewed_status.clock_offset_ms is not None
                and "tracker" in statuses
            ):
                break
            time.sleep(0.1)
        assert tracker.poll() is None, processes.output(tracker)
        assert min(counts.values()) >= 30, counts
        with lock:
            skewed_status = statuses["kinect2_1"]
            plain_status = statuses["kinect2_0"]
            seen = list(arrivals)
        assert skewed_status.clock_offset_ms == pytest.approx(-250.0, abs=2.0)
        assert skewed_status.clock_uncertainty_ms < 2.0
        assert plain_status.clock_offset_ms == pytest.approx(0.0, abs=2.0)
        for sensor in ("kinect2_0", "kinect2_1"):
            latencies = [t - m.batch.stamp for t, m in seen if m.batch.sensor_id == sensor]
            # Captured before it arrived: a stamp 250 ms in the future would be negative.
            assert min(latencies) > 0.0, (sensor, min(latencies))
        skewed_offsets = {m.clock_offset_s for _, m in seen if m.batch.sensor_id == "kinect2_1"}
        assert all(o == pytest.approx(-0.25, abs=0.002) for o in skewed_offsets)
        # The tracker took every batch in time order (none dropped as too late).
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline:
            with lock:
                tracker_status = statuses["tracker"]
            if tracker_status.values.get("batches", 0) > 0:
                break
            time.sleep(0.1)
        assert tracker_status.values["batches"] > 0
        assert tracker_status.values.get("dropped_batches", 0) == 0
    finally:
        observer.close()
