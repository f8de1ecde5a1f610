"""The detector node: one sensor in, its detections out, in tracker time.

``optrack node detect --sensor URI --site NAME [--config FILE]``. Each frame:

1. apply parameter updates received since the last frame (``params/<sensor>``)
   and a calibration received since then (stored first, atomically);
2. read the sensor's next frame (a live camera's newest; a recording plays as
   a live camera, :class:`~optrack.runtime.replay.LiveReplay`);
3. detect (any :class:`Detector`: ``process(RGBDFrame) -> DetectionBatch``),
   restamp the batch in tracker time (clock sync) and publish it on
   ``detections/<sensor>``;
4. now and then, publish a preview (``preview/<sensor>``).

Frames the node could not keep up with are skipped by the sensor and counted
as dropped (gaps in the frame numbers). The status reports the rate of
frames processed, the latency from capture to publication, the dropped
frames and the clock offset to the tracker with its uncertainty.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

import msgspec
import numpy as np

from optrack.errors import UserError
from optrack.net.bus import Bus
from optrack.net.clock import ClockSync
from optrack.net.messages import CalibrationMessage, DetectionsMessage, Message
from optrack.params import Params
from optrack.recording import SensorInfo
from optrack.runtime.board_capture import CalibrationCapture
from optrack.runtime.calibration_store import CalibrationStore
from optrack.runtime.node import Node, RateMeter
from optrack.runtime.node_recording import NodePlayback, NodeRecorder
from optrack.runtime.preview import make_preview
from optrack.runtime.replay import LiveReplay
from optrack.runtime.skeleton_node import SkeletonClouds
from optrack.sensors.base import Sensor
from optrack.types import DetectionBatch, NetworkCalibration, RGBDFrame

if TYPE_CHECKING:
    from optrack.sim.operator import SceneSwitch

__all__ = [
    "CalibrationRequest",
    "Detector",
    "DetectorFactory",
    "DetectorNode",
    "people_detector",
    "replay_streams",
]

log = logging.getLogger("optrack.runtime.detector")


class Detector(Protocol):
    """What a detector node runs on every frame."""

    def process(self, frame: RGBDFrame) -> DetectionBatch: ...


#: Builds a sensor's detector from its description, its ``world_T_camera``
#: (None when not calibrated) and the ``detection`` parameters it must read
#: live (the node updates that very object between frames).
DetectorFactory = Callable[[SensorInfo, np.ndarray | None, Params], Detector]


def people_detector(
    info: SensorInfo, world_T_camera: np.ndarray | None, params: Params
) -> Detector:
    """optrack's people detector (:class:`optrack.detection.pipeline.PeopleDetector`)."""
    from optrack.detection.pipeline import PeopleDetector

    return PeopleDetector(params, sensor_id=info.id, world_T_camera=world_T_camera)


class CalibrationRequest(Message, tag="calibration_request"):
    """Asks the tracker for the calibration it holds (nodes that start late)."""


def replay_streams(info: SensorInfo, hog_image: str) -> list[str]:
    """The streams a replayed sensor must decode for the detector (never one it ignores)."""
    recorded = set(info.streams)
    streams = ["depth"]
    use_color = "color" in recorded and hog_image != "infrared"
    if use_color:
        streams.append("color")
    if "infrared" in recorded and not use_color:
        streams.append("infrared")
    if "confidence" in recorded:
        streams.append("confidence")
    return streams


class DetectorNode(Node):
    """One sensor's detector on the bus (see the module docstring)."""

    role = "detector"

    def __init__(
        self,
        bus: Bus,
        sensor: Sensor,
        detection: Params,
        node_params: Params,
        sync: ClockSync,
        store: CalibrationStore,
        factory: DetectorFactory = people_detector,
        logger: logging.Logger = log,
        skeleton: dict[str, Params] | None = None,
    ) -> None:
        """``skeleton``: the stages ``skeleton_live`` and ``skeleton_fusion`` (the
        skeleton stage's switch and each person's crop; defaults: off)."""
        self.sensor = sensor
        self.info = sensor.info
        self.detection = detection
        self.sync = sync
        self.store = store
        self.factory = factory
        super().__init__(
            bus, self.info.id, node_params, {"detection": detection, "node": node_params}, logger
        )
        self.frames = 0
        self.dropped = 0
        self.failures = 0
        self.detections = 0
        self._last_seq: int | None = None
        self._meter = RateMeter()
        self._latency = RateMeter()
        self._processing = RateMeter()
        self._wait = RateMeter()  # capture to the start of detection (busy detector, decoding)
        self._next_preview = 0.0
        self._failure_kinds: set[str] = set()
        self._pending: NetworkCalibration | None = None
        self.calibration_id = ""
        self.world_T_camera = self._initial_pose()
        self.detector = factory(self.info, self.world_T_camera, detection)
        self._set_streams()
        bus.subscribe(bus.keys.calibration, CalibrationMessage, self._on_calibration)
        # The live calibration's board capture (commands calibration_start / _stop).
        self.capture = CalibrationCapture(bus, self.info, sync, on_streams=self._need_stream)
        self.capture.register(self.add_command)
        self.live["calibration_capture"] = self.capture.params
        # A simulated site's operator (calibration wizard) moves the node onto its scenes;
        # its switch is made (and the simulator loaded) when it first asks.
        self.scene: SceneSwitch | None = None
        self.add_command("sim_scene", self._sim_scene)
        # The skeleton stage: each person's points after each frame, while it is on.
        self.skeleton = SkeletonClouds(bus, self.info.id, self.live, skeleton)
        # Recording and playback commands (optrack.runtime.node_recording).
        self.recorder = NodeRecorder(self, self.info)
        self.playback = NodePlayback(self, sensor) if isinstance(sensor, LiveReplay) else None
        self._held: DetectionsMessage | None = None  # the last detections, sent while paused

    # ------------------------------------------------------------ calibration
    def _initial_pose(self) -> np.ndarray | None:
        stored = self.store.load()
        if stored is not None and self.info.id in stored.sensors:
            self.calibration_id = stored.notes or "stored"
            self.log.info("using the stored calibration %s", self.store.path)
            return stored.pose(self.info.id)
        if self.info.world_T_camera is not None:
            self.calibration_id = "sensor"
            return np.asarray(self.info.world_T_camera, dtype=np.float64)
        return None

    def ask_calibration(self, timeout: float = 0.5) -> None:
        """Ask the tracker for the site's current calibration (used from the next frame)."""
        replies = self.bus.query(
            self.bus.keys.calibration, CalibrationRequest(), CalibrationMessage, timeout
        )
        if replies:
            self._on_calibration(replies[0], self.bus.keys.calibration)

    def _on_calibration(self, message: CalibrationMessage, key: str) -> None:
        calibration = message.calibration
        if self.info.id not in calibration.sensors:
            known = ", ".join(sorted(calibration.sensors)) or "none"
            self.report_error(
                f"a calibration from '{message.sender}' has no sensor '{self.info.id}' (it has: "
                f"{known}); this node keeps its current pose, so calibrate this sensor too."
            )
            return
        path = self.store.save(calibration)  # atomically; the previous file kept as .bak
        self.log.info("stored the calibration from '%s' in %s", message.sender, path)
        self._pending = calibration

    def _take_calibration(self) -> None:
        calibration, self._pending = self._pending, None
        if calibration is None:
            return
        self.world_T_camera = calibration.pose(self.info.id)
        self.calibration_id = calibration.notes or calibration.created or "bus"
        self.detector = self.factory(self.info, self.world_T_camera, self.detection)
        self.log.info("using the new calibration from this frame on")

    # ---------------------------------------------------------- parameters
    def on_params(self, stage: str, changed: dict[str, Any]) -> None:
        if (stage == "detection" and "hog_image" in changed) or (
            stage == "node" and "replay_max_age_s" in changed
        ):
            self._set_streams()

    def _sim_scene(self, args: dict[str, Any]) -> dict[str, Any]:
        """``sim_scene {uri}``: read this sensor of a simulated operator's scene from the
        next frame (optrack.sim.operator.SceneSwitch)."""
        if self.scene is None:
            from optrack.sim.operator import SceneSwitch

            self.scene = SceneSwitch(self.sensor)
        return self.scene.command(args)

    def _take_scene(self) -> None:
        if self.scene is None:
            return
        sensor = self.scene.take(self.report_error)
        if sensor is None:
            return
        self.sensor, self.info = sensor, sensor.info
        self.capture.info = self.info
        self._last_seq = None
        self.detector = self.factory(self.info, self.world_T_camera, self.detection)

    def _need_stream(self, kind: str) -> None:
        streams = getattr(self.sensor, "streams", None)
        if isinstance(self.sensor, LiveReplay) and streams is not None and kind not in streams:
            self.sensor.streams = (*streams, kind)

    def _set_streams(self) -> None:
        if isinstance(self.sensor, LiveReplay):
            self.sensor.streams = tuple(replay_streams(self.info, str(self.detection.hog_image)))
            age = float(self.node_params.replay_max_age_s)
            self.sensor.max_age_s = age if age >= 0 else None

    # ---------------------------------------------------------------- frames
    def step(self) -> bool:
        """Process one frame; False when the sensor has ended."""
        self.apply_params()
        self._take_calibration()
        self._take_scene()
        if self.playback is not None and self.playback.hold():
            self._hold_scene()  # paused: no frame until a step or a resume
            return True
        frame = self.sensor.read()
        if frame is None:
            return False
        # A replay stamps the instant each frame became due on this node's clock; a
        # sensor stamping its captures on this computer's wall clock (Sensor.host_clock:
        # a simulated one, which renders for a while after the capture) is stamped at the
        # capture, the frame's age taken off the node's clock; any other sensor is
        # stamped when its frame arrives here.
        if isinstance(self.sensor, LiveReplay):
            captured = frame.timestamp
        elif getattr(self.sensor, "host_clock", False):
            captured = self.sync.clock() - max(0.0, time.time() - frame.timestamp)
        else:
            captured = self.sync.clock()
        frame.timestamp = captured
        if self._last_seq is not None and frame.seq > self._last_seq + 1:
            self.dropped += frame.seq - self._last_seq - 1
        self._last_seq = frame.seq
        self.recorder.offer(frame, self.sync.to_tracker(captured))
        if self.playback is not None:
            self.playback.last_frame = frame.seq
        if self.capture.offer(frame, captured):  # the board capture has this frame alone
            self.capture.wait_ready(self._stop)
            return True
        started = time.perf_counter()
        self._wait.add(self.sync.clock() - captured)
        try:
            batch = self.detector.process(frame)
        except UserError as error:
            self._failed(error)
            return True
        except Exception as error:  # a detector bug must not stop the sensor's stream
            self._failed(error)
            return True
        processing = time.perf_counter() - started
        estimate = self.sync.estimate
        batch.sensor_id = self.info.id
        batch.stamp = self.sync.to_tracker(captured)
        batch.seq = self.frames
        batch.processing_ms = processing * 1000.0
        self._held = DetectionsMessage(
            batch=batch,
            clock_offset_s=self.sync.offset_s,
            clock_uncertainty_s=estimate.uncertainty_s if estimate is not None else None,
        )
        self.bus.publish(self.bus.keys.detections(self.info.id), self._held)
        self.skeleton.offer(frame, batch, self.world_T_camera)
        self.frames += 1
        self.detections = len(batch.detections)
        self.state = "running"
        now = time.monotonic()
        self._meter.add(now=now)
        self._latency.add(self.sync.clock() - captured, now)
        self._processing.add(processing, now)
        rate = float(self.node_params.preview_hz)
        if rate > 0 and now >= self._next_preview:
            self._next_preview = now + 1.0 / rate
            self._publish_preview(frame, batch)
        return True

    def _hold_scene(self) -> None:
        """A paused replay's scene stays as it was: its last detections are sent again,
        stamped now (as a camera watching people standing still), so the tracker keeps
        everyone with their IDs until a step or a resume moves them."""
        if self._held is None:
            return
        batch = msgspec.structs.replace(
            self._held.batch, stamp=self.sync.to_tracker(self.sync.clock())
        )
        self._held = msgspec.structs.replace(self._held, batch=batch)
        self.bus.publish(self.bus.keys.detections(self.info.id), self._held)

    def _failed(self, error: BaseException) -> None:
        self.failures += 1
        kind = type(error).__name__
        sentence = f"detection failed on frame {self.frames} ({kind}: {error})"
        self.last_error = sentence
        if kind not in self._failure_kinds:
            self._failure_kinds.add(kind)
            self.log.error(
                "%s; further %s failures are only counted.", sentence, kind, exc_info=error
            )

    def _publish_preview(self, frame: RGBDFrame, batch: DetectionBatch) -> None:
        preview = make_preview(
            frame,
            batch,
            self.world_T_camera,
            int(self.node_params.preview_width),
            int(self.node_params.preview_points),
            batch.stamp,
        )
        self.bus.publish(self.bus.keys.preview(self.info.id), preview)

    def status_fields(self) -> dict[str, Any]:
        estimate = self.sync.estimate
        return {
            "sensor": self.info.uri or self.info.id,
            "fps": self._meter.rate(),
            "latency_ms": self._latency.median() * 1000.0,
            "dropped": self.dropped,
            "clock_offset_ms": estimate.offset_s * 1000.0 if estimate is not None else None,
            "clock_uncertainty_ms": (
                estimate.uncertainty_s * 1000.0 if estimate is not None else None
            ),
            "values": {
                "frames": self.frames,
                "detections": self.detections,
                "processing_ms": self._processing.median() * 1000.0,
                "wait_ms": self._wait.median() * 1000.0,
                "failures": self.failures,
                "calibrated": self.world_T_camera is not None,
                "calibration": self.calibration_id,
                "synchronised": estimate is not None,
                "model": self.info.model,
                **self.capture.status_values(),
                **self.recorder.status_values(),
                **(self.playback.status_values() if self.playback is not None else {}),
            },
        }

    def stop(self) -> None:
        super().stop()
        if self.playback is not None:
            self.playback.release()  # a paused replay must not hold the loop

    def close(self) -> None:
        self.sync.stop()
        self.capture.close()
        closing = self.recorder.stop()  # what is queued is written, then the take closed
        if closing is not None:
            closing.join(float(self.recorder.params.stop_wait_s) * 4)
        try:
            self.sensor.close()
        finally:
            super().close()

    def run(self) -> int:
        """Process frames until stopped or the sensor ends; returns an exit status."""
        self.start_status()
        self.publish_status()
        try:
            while not self.stopping:
                if not self.step():
                    self.state = "ended"
                    self.log.info("the sensor has no more frames after %d; stopping.", self.frames)
                    break
        except UserError as error:  # the sensor failed (unplugged...): say so, then exit
            self.state = "error"
            self.last_error = str(error)
            raise
        finally:
            self.close()
        return 0
