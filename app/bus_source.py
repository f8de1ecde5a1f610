"""The window's source for a site on the Zenoh bus: the GUI is one more node (like rviz).

It subscribes to the site's tracks, detections, calibration, statuses and
previews (``optrack.net``), re-emits them as :class:`~app.source.SiteSource`
signals, and publishes the operator's parameter changes to the nodes that
run the stage. Joining the bus can take seconds (a local site's hub is still
starting, a remote one is far), so it happens on a worker thread; the
window stays responsive and hears the outcome on ``connection`` and ``log``.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from typing import Any

import msgspec

from app.source import OUTPUT_PORTS, SiteSource, node_schemas
from optrack.errors import UserError
from optrack.net import (
    Bus,
    BusError,
    CalibrationMessage,
    DetectionsMessage,
    ParamsMessage,
    PreviewMessage,
    StatusMessage,
    TracksMessage,
)
from optrack.outputs.udp import parse_address
from optrack.params import REGISTRY, Params
from optrack.runtime.detector_node import CalibrationRequest
from optrack.runtime.preview import decode_preview
from optrack.types import NetworkCalibration, SensorCalibration

__all__ = ["BusSource"]

log = logging.getLogger("app.bus")


class BusSource(SiteSource):
    """A site on the bus. ``bus_params`` are the ``bus`` stage's values (mode, endpoints)."""

    def __init__(
        self,
        site: str,
        bus_params: Params,
        parent: Any = None,
        *,
        retry_while: threading.Event | None = None,
        label: str = "",
    ) -> None:
        """``retry_while``: keep trying to join while it is set (a site still starting);
        ``label`` names the site in the window (default: its name and where it is)."""
        super().__init__(parent)
        self.site = site
        self.retry_while = retry_while
        self.label = label
        self.bus_params = bus_params
        self.node = f"gui-{os.getpid()}"
        self.bus: Bus | None = None
        self._lock = threading.Lock()
        self._closed = False
        self._node_stages: dict[str, set[str]] = {}
        self._stages_shown: set[str] = set()
        self._sent: dict[tuple[str, str, str], tuple[float, int]] = {}
        self._unknown_stages: set[str] = set()
        self._outputs: dict[str, Any] = {}
        self._site_calibration = False
        self._preview_calibration = NetworkCalibration()
        self._disabled: set[tuple[str, str]] = set()
        self._detectors: dict[str, str] = {}  # detector node -> its last state
        node_schemas()  # the stages' schemas must be registered to build their controls
        self._thread = threading.Thread(target=self._join, name="gui-bus-join", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------ joining
    def _join(self) -> None:
        while True:
            try:
                bus = Bus(self.site, self.node, self.bus_params)
                break
            except BusError as error:
                retry = self.retry_while
                if retry is not None and retry.is_set() and not self._closed:
                    time.sleep(0.2)
                    continue  # the site is still starting (rendering its venue, say)
                if not self._closed:
                    self.log.emit("error", str(error))
                return
            except UserError as error:  # a configuration that cannot work
                self.log.emit("error", str(error))
                return
        with self._lock:
            if self._closed:
                bus.close()
                return
            self.bus = bus
        keys = bus.keys
        bus.subscribe(keys.tracks, TracksMessage, lambda m, _: self.tracks.emit(m.batch))
        bus.subscribe(
            keys.detections(), DetectionsMessage, lambda m, _: self.detections.emit(m.batch)
        )
        bus.subscribe(keys.calibration, CalibrationMessage, self._on_calibration)
        bus.subscribe(keys.status(), StatusMessage, self._on_status)
        bus.subscribe(keys.preview(), PreviewMessage, self._on_preview)
        self.connection.emit(self.describe())
        self.log.emit("info", f"Joined {self.describe()}; waiting for its nodes.")
        # The calibration is published when it changes; ask the tracker for the one it holds.
        for reply in bus.query(keys.calibration, CalibrationRequest(), CalibrationMessage):
            self._on_calibration(reply, keys.calibration)
            break

    def _on_calibration(self, message: CalibrationMessage, key: str) -> None:
        with self._lock:
            self._site_calibration = True
        self.calibration.emit(message.calibration)

    @property
    def connected(self) -> bool:
        return self.bus is not None and not self.bus.closed

    def describe(self) -> str:
        if self.label:
            return self.label
        mode = str(self.bus_params.mode)
        where = "this computer" if mode == "local" else f"the network ({mode})"
        return f"Site '{self.site}' on {where}"

    # ---------------------------------------------------------- receiving
    def _on_status(self, message: StatusMessage, key: str) -> None:
        if message.role == "detector":
            self._detectors[message.node] = message.state
        values = msgspec.to_builtins(message)
        now = time.monotonic()
        for destination in values.get("destinations", []):
            ident = (message.node, destination["kind"], destination["address"])
            before = self._sent.get(ident)
            if before is not None and now > before[0]:
                destination["packets_per_s"] = (destination["sent"] - before[1]) / (now - before[0])
            self._sent[ident] = (now, destination["sent"])
            destination["error"] = destination.get("last_error", "")
        stages = set(message.params)
        self._node_stages[message.node] = stages
        unknown = stages - set(REGISTRY) - self._unknown_stages
        if unknown:
            self._unknown_stages |= unknown
            self.log.emit(
                "warning",
                f"node {message.node} runs stages this window does not know "
                f"({', '.join(sorted(unknown))}); run the same optrack version everywhere.",
            )
        new = {s for s in stages - self._stages_shown if s in REGISTRY}
        if new:
            self._stages_shown |= new
            self.schemas.emit(
                {stage: REGISTRY[stage] for stage in sorted(new)},
                {stage: dict(message.params[stage]) for stage in new},
            )
        if "outputs" in message.params:
            self._outputs = dict(message.params["outputs"])
            for kind, address in sorted(self._disabled):
                values["destinations"].append(
                    {"kind": kind, "address": address, "enabled": False, "sent": 0}
                )
        self.status.emit(message.node, values)

    def _on_preview(self, message: PreviewMessage, key: str) -> None:
        try:
            frame, cloud = decode_preview(message)
        except (UserError, ValueError) as error:
            self.log.emit("warning", f"{error}.")
            return
        self.preview.emit(message.sensor, frame, message.detections)
        self._camera_from_preview(message)
        if message.cloud and message.cloud_frame == "world":
            self.cloud.emit(message.sensor, cloud)

    def _camera_from_preview(self, message: PreviewMessage) -> None:
        """Until the site sends a calibration, show the cameras the detectors place with
        the pose their previews carry (the preview's intrinsics have the full field of view)."""
        if message.world_T_camera is None:
            return
        with self._lock:
            if self._site_calibration:
                return
            known = self._preview_calibration.sensors.get(message.sensor)
            if known is not None and known.world_T_camera == message.world_T_camera:
                return
            sensors = dict(self._preview_calibration.sensors)
            sensors[message.sensor] = SensorCalibration(
                world_T_camera=message.world_T_camera, intrinsics=message.intrinsics
            )
            self._preview_calibration = NetworkCalibration(
                sensors=sensors, notes="poses of the detectors' previews"
            )
            calibration = self._preview_calibration
        self.calibration.emit(calibration)

    # ---------------------------------------------------- operator's intent
    def nodes_running(self, stage: str) -> list[str]:
        return sorted(node for node, stages in self._node_stages.items() if stage in stages)

    def set_params(self, stage: str, values: dict[str, Any]) -> None:
        bus = self.bus
        nodes = self.nodes_running(stage)
        if bus is None or not nodes:
            names = ", ".join(f"{stage}.{name}" for name in values)
            self.log.emit(
                "warning",
                f"No node of {self.describe()} runs the {stage} stage yet; {names} was not sent.",
            )
            return
        request = f"{self.node}-{time.monotonic_ns()}"
        for node in nodes:
            bus.publish(
                bus.keys.params(node),
                ParamsMessage(updates={stage: dict(values)}, request=request),
                realtime=False,
            )

    # Outputs are the ``outputs`` stage's comma-separated destination lists; a disabled
    # destination is taken out of its list and remembered here so it can come back.
    def _destinations(self, kind: str) -> list[str]:
        return [
            item.strip() for item in str(self._outputs.get(kind, "")).split(",") if item.strip()
        ]

    def _same(self, kind: str, a: str, b: str) -> bool:
        port = OUTPUT_PORTS[kind]
        try:
            return parse_address(a, port, kind, True) == parse_address(b, port, kind, True)
        except UserError:
            return a == b

    def _send_outputs(self, kind: str, destinations: list[str]) -> None:
        self.set_params("outputs", {kind: ",".join(destinations)})

    def add_output(self, kind: str, address: str) -> None:
        current = [] if kind == "websocket" else self._destinations(kind)  # one server
        self._send_outputs(kind, [*current, address])

    def _take_out(self, kind: str, address: str) -> None:
        kept = [d for d in self._destinations(kind) if not self._same(kind, d, address)]
        self._send_outputs(kind, kept)

    def remove_output(self, kind: str, address: str) -> None:
        if (kind, address) in self._disabled:
            self._disabled.discard((kind, address))  # not running: only forget it
        else:
            self._take_out(kind, address)

    def enable_output(self, kind: str, address: str, enabled: bool) -> None:
        if enabled:
            self._disabled.discard((kind, address))
            self.add_output(kind, address)
        else:
            self._take_out(kind, address)
            self._disabled.add((kind, address))

    # Recording and playback: commands to every detector node, on a worker thread (each
    # node may take up to recorder.command_timeout_s to answer); the answer comes back on
    # ``command_reply`` and refusals as sentences on ``log``.
    def detector_nodes(self) -> list[str]:
        gone = ("stopped", "ended", "error")
        return sorted(node for node, state in self._detectors.items() if state not in gone)

    def _command(self, action: str, work: Any) -> None:
        from optrack.runtime.node_recording import SiteControl

        bus = self.bus
        if bus is None:
            self._refuse(action, f"Not connected to {self.describe()} yet; try again shortly.")
            return

        def run() -> None:
            try:
                result = work(SiteControl(bus), self.detector_nodes())
            except UserError as error:
                self.log.emit("error", str(error))
                self.command_reply.emit(action, False, str(error), {})
                return
            self.command_reply.emit(action, True, "", result)

        threading.Thread(target=run, name=f"gui-{action}", daemon=True).start()

    def start_recording(self, folder: str) -> None:
        self._command("record_start", lambda c, nodes: c.start_recording(nodes, folder))

    def stop_recording(self) -> None:
        self._command("record_stop", lambda c, nodes: c.stop_recording(nodes))

    def playback(self, action: str, **args: Any) -> None:
        self._command(action, lambda c, nodes: c.playback(nodes, action, **args))

    def close(self) -> None:
        with self._lock:
            self._closed = True
            bus, self.bus = self.bus, None
        if bus is not None:
            bus.close()
