"""The tracker node: every sensor's detections in, tracks out.

``optrack node track --site NAME [--config FILE]``. It answers clock-sync
requests (it is the site's time reference), keeps the site's calibration
(stores what is published, answers nodes that ask for it), and feeds each
:class:`~optrack.types.DetectionBatch` as it arrives to the tracker
(anything with ``update(DetectionBatch, now) -> TrackBatch | None``; the
tracker itself handles batches that arrive out of order). Each update's
tracks go through the output smoother (moving average, tracks unseen for a
while left out; :class:`~optrack.tracking.smoothing.OutputSmoother`) and are
published at once on ``tracks``, stamped with the newest detection's time:
no fixed-rate resampling, so nothing waits.
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from typing import Any, Protocol

from optrack.errors import UserError
from optrack.net.bus import Bus
from optrack.net.clock import ClockServer
from optrack.net.keys import SiteKeys
from optrack.net.messages import CalibrationMessage, DetectionsMessage, TracksMessage
from optrack.params import Params
from optrack.runtime.calibration_store import CalibrationStore
from optrack.runtime.detector_node import CalibrationRequest
from optrack.runtime.node import Node, RateMeter
from optrack.types import DetectionBatch, NetworkCalibration, TrackBatch

__all__ = ["TrackerLike", "TrackerNode"]

log = logging.getLogger("optrack.runtime.tracker")


class TrackerLike(Protocol):
    """What the tracker node runs on every detection batch."""

    def update(self, batch: DetectionBatch, now: float | None = None) -> TrackBatch | None: ...


class TrackerNode(Node):
    """The site's central tracker (see the module docstring)."""

    role = "tracker"

    def __init__(
        self,
        bus: Bus,
        node_params: Params,
        store: CalibrationStore,
        tracker: TrackerLike | None = None,
        live: dict[str, Params] | None = None,
        smoother: Any | None = None,
        logger: logging.Logger = log,
    ) -> None:
        from optrack.tracking import Tracker
        from optrack.tracking.params import APPEARANCE_PARAMS, SMOOTHING_PARAMS, TRACKING_PARAMS
        from optrack.tracking.smoothing import OutputSmoother

        live = dict(live or {})
        live.setdefault("tracking", TRACKING_PARAMS.create())
        live.setdefault("appearance", APPEARANCE_PARAMS.create())
        live.setdefault("smoothing", SMOOTHING_PARAMS.create())
        live["node"] = node_params
        self.tracker = (
            tracker if tracker is not None else Tracker(live["tracking"], live["appearance"])
        )
        self.smoother = smoother if smoother is not None else OutputSmoother(live["smoothing"])
        super().__init__(bus, "tracker", node_params, live, logger)
        self.store = store
        self.calibration: NetworkCalibration | None = store.load()
        self.clock_server = ClockServer(bus)
        self.batches = 0
        self.refused = 0
        self.published = 0
        self.tracks = 0
        self._detections: collections.deque[DetectionsMessage] = collections.deque()
        self._arrived = threading.Event()
        self._meter = RateMeter()
        self._latency = RateMeter()
        self._sensors: dict[str, RateMeter] = {}
        self._refused_sensors: set[str] = set()
        bus.subscribe(bus.keys.detections(), DetectionsMessage, self._on_detections)
        bus.subscribe(bus.keys.calibration, CalibrationMessage, self._on_calibration)
        bus.serve(bus.keys.calibration, CalibrationRequest, self._answer_calibration)

    # ------------------------------------------------------------ calibration
    def _on_calibration(self, message: CalibrationMessage, key: str) -> None:
        self.store.save(message.calibration)
        self.calibration = message.calibration
        self.log.info(
            "stored the calibration from '%s' (%d sensors) in %s",
            message.sender,
            len(message.calibration.sensors),
            self.store.path,
        )

    def _answer_calibration(self, request: CalibrationRequest) -> CalibrationMessage | None:
        calibration = self.calibration
        return CalibrationMessage(calibration=calibration) if calibration is not None else None

    # ------------------------------------------------------------ detections
    def _on_detections(self, message: DetectionsMessage, key: str) -> None:
        sensor = SiteKeys.last_chunk(key)
        if message.batch.sensor_id != sensor:
            self._refuse(
                sensor,
                f"detections published on {key} say they are from sensor "
                f"'{message.batch.sensor_id}'; each sensor publishes on its own key.",
            )
            return
        self._detections.append(message)
        self._arrived.set()

    def _refuse(self, sensor: str, sentence: str) -> None:
        self.refused += 1
        self.last_error = sentence
        if sensor not in self._refused_sensors:
            self._refused_sensors.add(sensor)
            self.log.warning("%s (further refusals from it are only counted)", sentence)

    def step(self, timeout: float = 0.1) -> int:
        """Track every batch that arrived (waiting up to ``timeout`` for one); returns
        how many were used."""
        self.apply_params()
        if not self._detections and not self._arrived.wait(timeout):
            return 0
        self._arrived.clear()
        used = 0
        while self._detections:
            message = self._detections.popleft()
            batch = message.batch
            try:
                tracks = self.tracker.update(batch, now=time.time())
            except UserError as error:  # e.g. detections not in the world frame
                self._refuse(batch.sensor_id, str(error))
                continue
            self.batches += 1
            meter = self._sensors.get(batch.sensor_id)
            if meter is None:
                meter = self._sensors[batch.sensor_id] = RateMeter()
            meter.add()
            if tracks is None:  # too late: the tracker counts it
                continue
            self.smoother.add(tracks)
            out = self.smoother.publish(tracks.stamp)
            self.bus.publish(self.bus.keys.tracks, TracksMessage(batch=out))
            self.published += 1
            self.tracks = len(out.tracks)
            now = time.monotonic()
            self._meter.add(now=now)
            self._latency.add(time.time() - batch.stamp, now)
            used += 1
        self.state = "running"
        return used

    def status_fields(self) -> dict[str, Any]:
        values: dict[str, Any] = {
            "tracks": self.tracks,
            "batches": self.batches,
            "published": self.published,
            "refused_batches": self.refused,
            "clock_requests": self.clock_server.requests,
            "calibration": (
                (self.calibration.notes or self.calibration.created or "yes")
                if self.calibration is not None
                else ""
            ),
        }
        for sensor, meter in sorted(self._sensors.items()):
            values[f"hz.{sensor}"] = meter.rate()
        status = getattr(self.tracker, "status", None)
        if callable(status):
            report = status(time.time())
            values["dropped_batches"] = report.dropped_batches
            values["silent_sensors"] = ",".join(report.silent_sensors)
            if report.warnings:
                self.last_error = report.warnings[-1]
        return {
            "fps": self._meter.rate(),
            "latency_ms": self._latency.median() * 1000.0,
            "dropped": int(values.get("dropped_batches", 0)),
            "clock_offset_ms": 0.0,
            "clock_uncertainty_ms": 0.0,
            "values": values,
        }

    def run(self) -> int:
        self.start_status()
        self.publish_status()
        self.state = "running"
        try:
            while not self.stopping:
                self.step()
        finally:
            self.close()
        return 0
