"""The tracker node: every sensor's detections in, smoothed tracks out.

``optrack node track --site NAME [--config FILE]``. It answers clock-sync
requests (it is the site's time reference), keeps the site's calibration
(stores what is published, answers nodes that ask for it), and feeds each
:class:`~optrack.types.DetectionBatch` as it arrives to the tracker (only a
sensor of the current calibration's: others are counted in
``foreign_sensor_batches`` and reported once)
(anything with ``update(DetectionBatch, now) -> TrackBatch | None``; the
tracker itself handles batches that arrive out of order). The tracks go
through the output smoother (OpenPTrack's moving average; tracks unseen for
``smoothing.drop_after`` left out;
:class:`~optrack.tracking.smoothing.OutputSmoother`) and are sent
(``node.tracks_publish``):

- ``update`` (default): at once after every batch, stamped with the capture
  instant of the frame whose detections it carries, and, when no batch came
  for a period of ``smoothing.rate``, again with the same stamp (a repeat:
  the same data, tracks unseen for too long left out). Nothing waits, and the
  output never falls below ``smoothing.rate``.
- ``rate``: only at ``smoothing.rate``, the newest state each time, stamped
  with the capture instant of the newest frame in it.

A tracks frame goes first to the ``sinks`` (the outputs, called in this
loop: no bus hop before the datagram), then on the bus (``tracks``) for the
GUI and any other listener.
"""

from __future__ import annotations

import collections
import logging
import math
import threading
import time
from collections.abc import Callable, Iterable
from typing import Any, Protocol

from optrack.errors import UserError
from optrack.net.bus import Bus
from optrack.net.clock import ClockServer
from optrack.net.keys import SiteKeys
from optrack.net.messages import CalibrationMessage, DetectionsMessage, TracksMessage
from optrack.params import Params
from optrack.runtime.calibration_store import CalibrationStore
from optrack.runtime.detector_node import CalibrationRequest
from optrack.runtime.node import Node, RateMeter, live_schemas
from optrack.types import DetectionBatch, NetworkCalibration, TrackBatch

__all__ = ["TrackerLike", "TrackerNode"]

log = logging.getLogger("optrack.runtime.tracker")

#: Takes every tracks frame the node sends (the outputs).
Sink = Callable[[TrackBatch], None]


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
        sinks: Iterable[Sink] = (),
        clock: Callable[[], float] = time.time,
        logger: logging.Logger = log,
    ) -> None:
        from optrack.tracking import Tracker
        from optrack.tracking.params import APPEARANCE_PARAMS, SMOOTHING_PARAMS, TRACKING_PARAMS
        from optrack.tracking.smoothing import OutputSmoother

        live = live_schemas(
            live,
            node_params,
            {
                "tracking": TRACKING_PARAMS,
                "appearance": APPEARANCE_PARAMS,
                "smoothing": SMOOTHING_PARAMS,
            },
        )
        self.tracker = (
            tracker if tracker is not None else Tracker(live["tracking"], live["appearance"])
        )
        self.smoother = smoother if smoother is not None else OutputSmoother(live["smoothing"])
        self.smoothing = live["smoothing"]
        super().__init__(bus, "tracker", node_params, live, logger)
        self.store = store
        self.sinks = list(sinks)
        self.clock = clock  # the site's time reference
        self.calibration: NetworkCalibration | None = store.load()
        self.clock_server = ClockServer(bus, clock)
        self.batches = 0
        self.refused = 0
        self.future = 0  # refused: stamped ahead of this clock
        self.foreign = 0  # refused: from a sensor the current calibration does not have
        self.published = 0
        self.repeats = 0
        self.tracks = 0
        self.sink_errors = 0
        self._detections: collections.deque[DetectionsMessage] = collections.deque()
        self._arrived = threading.Event()
        self._meter = RateMeter()
        self._latency = RateMeter()
        self._sensors: dict[str, RateMeter] = {}
        self._refused_sensors: set[str] = set()
        self._sink_failures: set[str] = set()
        self._newest = -math.inf  # capture instant of the newest frame tracked
        self._sent_stamp: float | None = None  # stamp of the last frame sent
        self._next_tick = time.monotonic()
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
        calibration = self.calibration
        if calibration is not None and calibration.sensors and sensor not in calibration.sensors:
            self.foreign += 1
            known = ", ".join(sorted(calibration.sensors))
            self._refuse(
                sensor,
                f"detections of sensor '{sensor}' are not used: the current calibration has "
                f"no such sensor (it has: {known}); calibrate it to add it to the site.",
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

    @property
    def period(self) -> float:
        """Seconds between two fixed-rate frames (``smoothing.rate``)."""
        return 1.0 / float(self.smoothing.rate)

    @property
    def on_update(self) -> bool:
        return str(self.node_params.tracks_publish) == "update"

    def step(self, timeout: float = 0.1) -> int:
        """Track every batch that arrived, waiting for one up to ``timeout`` or the next
        fixed-rate frame; send what is due. Returns how many batches were used."""
        self.apply_params()
        if not self._detections:
            tick = self._next_tick if self._sent_stamp is not None else math.inf
            wait = min(timeout, tick - time.monotonic())
            if wait > 0:
                self._arrived.wait(wait)
        self._arrived.clear()
        used = 0
        while self._detections:
            batch = self._detections.popleft().batch
            if not self._track(batch):
                continue
            used += 1
            if self.on_update:
                self._send(batch.stamp)
        if time.monotonic() >= self._next_tick and self._sent_stamp is not None:
            # a fixed-rate frame: the newest state, or (update mode) a repeat of the last
            self._send(self._newest if not self.on_update else self._sent_stamp)
        elif used and not self.on_update and self._sent_stamp is None:
            self._send(self._newest)  # the first frame at once, then at the rate
        self.state = "running"
        return used

    def _track(self, batch: DetectionBatch) -> bool:
        """One batch through the tracker and into the smoother; False when refused or late."""
        now = self.clock()
        ahead = batch.stamp - now
        if ahead > float(self.node_params.max_future_s):
            self.future += 1
            self._refuse(
                batch.sensor_id,
                f"detections of sensor '{batch.sensor_id}' are stamped {ahead * 1000.0:.0f} ms "
                "ahead of the tracker's clock, so they are not used: that node's clock is not "
                "synchronised with the tracker yet (or jumped); if this goes on, run NTP "
                "(chrony) on its computer.",
            )
            return False
        try:
            tracks = self.tracker.update(batch, now=now)
        except UserError as error:  # e.g. detections not in the world frame
            self._refuse(batch.sensor_id, str(error))
            return False
        self.batches += 1
        meter = self._sensors.get(batch.sensor_id)
        if meter is None:
            meter = self._sensors[batch.sensor_id] = RateMeter()
        meter.add()
        if tracks is None:  # too late: the tracker counts it
            return False
        self.smoother.add(tracks)
        self._newest = max(self._newest, batch.stamp)
        return True

    def _send(self, stamp: float) -> None:
        """Send the smoothed tracks now (sinks first, then the bus), stamped ``stamp``."""
        out = self.smoother.publish(self.clock())  # tracks unseen for drop_after left out
        out.stamp = stamp
        fresh = stamp != self._sent_stamp
        for sink in self.sinks:
            try:
                sink(out)
            except Exception as error:  # an output's failure never stops the tracking
                self.sink_errors += 1
                kind = type(error).__name__
                if kind not in self._sink_failures:
                    self._sink_failures.add(kind)
                    self.log.error("sending tracks failed (%s: %s)", kind, error, exc_info=error)
        sent = self.clock()
        self.bus.publish(self.bus.keys.tracks, TracksMessage(batch=out))
        self._sent_stamp = stamp
        self.published += 1
        self.tracks = len(out.tracks)
        now = time.monotonic()
        if self.on_update:  # a repeat only after a period without an update
            self._next_tick = now + self.period
        else:  # the fixed rate; after a stall, on from now (no burst)
            self._next_tick += self.period
            if self._next_tick <= now:
                self._next_tick = now + self.period
        self._meter.add(now=now)
        if fresh:
            self._latency.add(sent - stamp, now)
        else:
            self.repeats += 1

    def status_fields(self) -> dict[str, Any]:
        values: dict[str, Any] = {
            "tracks": self.tracks,
            "batches": self.batches,
            "published": self.published,
            "repeats": self.repeats,
            "refused_batches": self.refused,
            "future_batches": self.future,
            "foreign_sensor_batches": self.foreign,
            "sink_errors": self.sink_errors,
            "latency_p95_ms": self._latency.percentile(95) * 1000.0,
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
            report = status(self.clock())
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
