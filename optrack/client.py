"""A site seen from outside: a plain-Python client of a site's bus.

The operator's window is one such client (``app/bus_source.py`` only wraps
this one in Qt signals); a headless tool can be another. A client joins the
site's bus as one more node (like rviz) and

* keeps what the site last said, for polling: each node's status (with the
  packet rate of every output destination), the latest tracks, the
  calibration, the stages the nodes run, the outputs as lists of
  destinations;
* calls the callbacks registered with :meth:`SiteClient.on` as messages
  arrive (events: :data:`EVENTS`);
* sends the operator's intent: parameter changes to the nodes that run the
  stage, outputs added, removed, turned off and on again, and recording and
  playback commands to every detector node.

Joining can take seconds (a local site's hub is still starting, a remote one
is far), so it happens on a thread that :meth:`SiteClient.start` starts; its
outcome is a ``connection`` or a ``log`` event. Callbacks run on that thread
or on the bus's threads: keep them short. A client that cannot keep up with
the site (a window's thread) calls :meth:`SiteClient.deliver_later`: the
events are then held, the newest of each kind (:data:`NEWEST`) replacing the
one not yet delivered, and handed to the callbacks when it calls
:meth:`SiteClient.deliver`, so a site sending faster than the client runs
can never pile up work for it.

Example (a headless tool)::

    config = load_node_config(None)  # optrack.runtime.config
    client = SiteClient(str(config["site"].name), config["bus"])
    client.on("tracks", lambda batch: print(batch.stamp, len(batch.tracks)))
    client.start()
    if client.wait_connected(10.0):
        client.add_output("udp", "192.168.1.20:21234")
"""

from __future__ import annotations

import itertools
import os
import threading
import time
from collections.abc import Callable
from typing import Any

import msgspec

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
from optrack.net.config import check_station
from optrack.net.messages import SkeletonsMessage
from optrack.outputs.streams import OUTPUT_PORTS
from optrack.outputs.udp import join_destinations, parse_address, split_destinations
from optrack.params import REGISTRY, Params, Schema
from optrack.runtime.config import register_node_stages
from optrack.runtime.detector_node import CalibrationRequest
from optrack.runtime.preview import decode_preview
from optrack.types import NetworkCalibration, SensorCalibration, TrackBatch

__all__ = ["EVENTS", "NEWEST", "SiteClient"]

#: What a site tells its client, and the arguments each event's callbacks get:
#: ``tracks(TrackBatch)``, ``detections(DetectionBatch)`` (one sensor's, world frame),
#: ``calibration(NetworkCalibration)``, ``status(node, values)`` (a node's status as a
#: dict; each output destination with ``packets_per_s`` once known and ``error``),
#: ``preview(sensor, RGBDFrame, DetectionBatch | None)``, ``cloud(sensor, Nx3 array)``
#: (world frame), ``schemas({stage: Schema}, {stage: values})`` (stages seen for the first
#: time), ``log(level, sentence)`` (``info``, ``warning``, ``error``),
#: ``connection(description)`` (joined) and ``command_reply(action, ok, sentence,
#: result)`` (the answer to a recording or playback command; ``result``: node -> answer)
#: and ``skeletons(SkeletonBatch)`` (while the site's skeleton stage runs).
EVENTS = (
    "tracks",
    "detections",
    "calibration",
    "status",
    "preview",
    "cloud",
    "schemas",
    "log",
    "connection",
    "command_reply",
    "skeletons",
)

#: The events of which only the newest matters, and what makes two of them the same
#: one (their arguments -> a key): a held event of these is replaced by a newer one. Every
#: other event is delivered, in order. A status carries its node's running counts, and the
#: outputs' rates are computed as each arrives, so keeping the newest loses no count.
NEWEST: dict[str, Callable[[tuple[Any, ...]], str]] = {
    "tracks": lambda args: "",
    "skeletons": lambda args: "",
    "calibration": lambda args: "",
    "status": lambda args: str(args[0]),  # per node
    "detections": lambda args: str(args[0].sensor_id),  # per sensor
    "preview": lambda args: str(args[0]),
    "cloud": lambda args: str(args[0]),
}

Callback = Callable[..., None]


class SiteClient:
    """One site's bus, from outside (see the module docstring).

    ``bus_params`` are the ``bus`` stage's values (mode, endpoints); ``node`` names this
    client on the bus; ``retry_while``: keep trying to join while it is set (a site still
    starting); ``label`` names the site in sentences (default: its name and where it is).
    """

    def __init__(
        self,
        site: str,
        bus_params: Params,
        *,
        node: str | None = None,
        retry_while: threading.Event | None = None,
        label: str = "",
    ) -> None:
        self.site = site
        self.bus_params = bus_params
        self.node = node or f"client-{os.getpid()}"
        self.retry_while = retry_while
        self.label = label
        self.bus: Bus | None = None
        self.latest_tracks: TrackBatch | None = None
        self.calibration: NetworkCalibration | None = None  # the site's, or the previews'
        self._callbacks: dict[str, list[Callback]] = {event: [] for event in EVENTS}
        self._lock = threading.Lock()
        self._closed = False
        self._thread: threading.Thread | None = None
        self._connected = threading.Event()
        self._statuses: dict[str, dict[str, Any]] = {}
        self._node_stages: dict[str, set[str]] = {}
        self._stages_shown: set[str] = set()
        self._unknown_stages: set[str] = set()
        self._sent: dict[tuple[str, str, str], tuple[float, int]] = {}
        self._outputs: dict[str, list[str]] = {}  # kind -> the destinations the site runs
        self._disabled: set[tuple[str, str]] = set()  # taken out, to come back when enabled
        self._site_calibration = False
        self._preview_calibration = NetworkCalibration()
        self._detectors: dict[str, str] = {}  # detector node -> its last state
        self._wake: Callable[[], None] | None = None  # set: events held for deliver()
        self._held: dict[tuple[str, Any], tuple[Any, ...]] = {}
        self._held_lock = threading.Lock()
        self._order = itertools.count()
        #: events not delivered because a newer one of the same kind replaced them
        self.replaced = 0
        register_node_stages()  # every stage a node may run has its schema known

    # ---------------------------------------------------------- callbacks
    def on(self, event: str, callback: Callback) -> None:
        """Call ``callback`` on every ``event`` (one of :data:`EVENTS`)."""
        if event not in self._callbacks:
            raise ValueError(f"unknown site event '{event}'; use one of {', '.join(EVENTS)}.")
        self._callbacks[event].append(callback)

    def _emit(self, event: str, *args: Any) -> None:
        wake = self._wake
        if wake is None:
            self._call(event, args)
            return
        newest = NEWEST.get(event)
        key = (event, newest(args) if newest is not None else next(self._order))
        with self._held_lock:
            first = not self._held
            self.replaced += key in self._held
            self._held[key] = args  # a newer one keeps the older one's place in line
        if first:
            wake()

    def _call(self, event: str, args: tuple[Any, ...]) -> None:
        for callback in self._callbacks[event]:
            callback(*args)

    def deliver_later(self, wake: Callable[[], None]) -> None:
        """Hold the events from now on; ``wake()`` (called on a bus thread) says that the
        first is held, so that the caller's own thread runs :meth:`deliver` soon. Until it
        does, a newer event of a kind in :data:`NEWEST` replaces the one held."""
        self._wake = wake

    def deliver(self) -> int:
        """Call back with every event held (on the calling thread); how many."""
        with self._held_lock:
            held, self._held = self._held, {}
        for (event, _), args in held.items():
            self._call(event, args)
        return len(held)

    # ------------------------------------------------------------ joining
    def start(self) -> None:
        """Join the site's bus on a thread of its own (once)."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._join, name="site-join", daemon=True)
            self._thread.start()

    def wait_connected(self, timeout: float | None = None) -> bool:
        """Whether the client joined the bus within ``timeout`` seconds."""
        return self._connected.wait(timeout) and self.connected

    def _open(self) -> Bus | None:
        while True:
            try:
                warning = check_station(self.bus_params, self.node)
                bus = Bus(self.site, self.node, self.bus_params)
                if warning:
                    self._emit("log", "warning", warning)
                return bus
            except BusError as error:
                retry = self.retry_while
                if retry is not None and retry.is_set() and not self._closed:
                    time.sleep(0.2)
                    continue  # the site is still starting (rendering its venue, say)
                if not self._closed:
                    self._emit("log", "error", str(error))
                return None
            except UserError as error:  # a configuration that cannot work
                self._emit("log", "error", str(error))
                return None

    def _join(self) -> None:
        bus = self._open()
        if bus is None:
            return
        with self._lock:
            if self._closed:
                bus.close()
                return
            self.bus = bus
        keys = bus.keys
        bus.subscribe(keys.tracks, TracksMessage, self._on_tracks)
        bus.subscribe(keys.detections(), DetectionsMessage, self._on_detections)
        bus.subscribe(keys.calibration, CalibrationMessage, self._on_calibration)
        bus.subscribe(keys.status(), StatusMessage, self._on_status)
        bus.subscribe(keys.preview(), PreviewMessage, self._on_preview)
        bus.subscribe(keys.skeletons, SkeletonsMessage, self._on_skeletons)
        self._connected.set()
        self._emit("connection", self.describe())
        self._emit("log", "info", f"Joined {self.describe()}; waiting for its nodes.")
        # The calibration is published when it changes; ask the tracker for the one it holds.
        for reply in bus.query(keys.calibration, CalibrationRequest(), CalibrationMessage):
            self._on_calibration(reply, keys.calibration)
            break

    @property
    def connected(self) -> bool:
        return self.bus is not None and not self.bus.closed

    @property
    def insecure(self) -> bool:
        """Whether the site runs without keys: this client joined it without (no TLS, no
        access control), or a node's status says so."""
        bus = self.bus
        if bus is not None and bus.insecure:
            return True
        with self._lock:
            statuses = list(self._statuses.values())
        return any((status.get("values") or {}).get("insecure") for status in statuses)

    def describe(self) -> str:
        """The site in a few words ("Site 'default' on this computer")."""
        if self.label:
            return self.label
        mode = str(self.bus_params.mode)
        where = "this computer" if mode == "local" else f"the network ({mode})"
        return f"Site '{self.site}' on {where}"

    # ---------------------------------------------------------- receiving
    def _on_tracks(self, message: TracksMessage, key: str) -> None:
        self.latest_tracks = message.batch
        self._emit("tracks", message.batch)

    def _on_skeletons(self, message: SkeletonsMessage, key: str) -> None:
        self._emit("skeletons", message.batch)

    def _on_detections(self, message: DetectionsMessage, key: str) -> None:
        self._emit("detections", message.batch)

    def _on_calibration(self, message: CalibrationMessage, key: str) -> None:
        with self._lock:
            self._site_calibration = True
            self.calibration = message.calibration
        self._emit("calibration", message.calibration)

    def _on_status(self, message: StatusMessage, key: str) -> None:
        if message.role == "detector":
            self._detectors[message.node] = message.state
        values = msgspec.to_builtins(message)
        self._add_rates(message.node, values.get("destinations", []))
        stages = set(message.params)
        self._node_stages[message.node] = stages
        unknown = stages - set(REGISTRY) - self._unknown_stages
        if unknown:
            self._unknown_stages |= unknown
            self._emit(
                "log",
                "warning",
                f"node {message.node} runs stages this window does not know "
                f"({', '.join(sorted(unknown))}); run the same optrack version everywhere.",
            )
        new = {s for s in stages - self._stages_shown if s in REGISTRY}
        if new:
            self._stages_shown |= new
            self._emit(
                "schemas",
                {stage: REGISTRY[stage] for stage in sorted(new)},
                {stage: dict(message.params[stage]) for stage in new},
            )
        if "outputs" in message.params:
            outputs = message.params["outputs"]
            with self._lock:
                self._outputs = {
                    kind: split_destinations(outputs.get(kind, "")) for kind in OUTPUT_PORTS
                }
                disabled = sorted(self._disabled)
            for kind, address in disabled:
                values["destinations"].append(
                    {"kind": kind, "address": address, "enabled": False, "sent": 0}
                )
        with self._lock:
            self._statuses[message.node] = values
        self._emit("status", message.node, values)

    def _add_rates(self, node: str, destinations: list[dict[str, Any]]) -> None:
        """Each destination's packets per second since the node's previous status."""
        now = time.monotonic()
        for destination in destinations:
            ident = (node, destination["kind"], destination["address"])
            before = self._sent.get(ident)
            if before is not None and now > before[0]:
                destination["packets_per_s"] = (destination["sent"] - before[1]) / (now - before[0])
            self._sent[ident] = (now, destination["sent"])
            destination["error"] = destination.get("last_error", "")

    def _on_preview(self, message: PreviewMessage, key: str) -> None:
        try:
            frame, cloud = decode_preview(message)
        except (UserError, ValueError) as error:
            self._emit("log", "warning", f"{error}.")
            return
        self._emit("preview", message.sensor, frame, message.detections)
        self._camera_from_preview(message)
        if message.cloud and message.cloud_frame == "world":
            self._emit("cloud", message.sensor, cloud)

    def _camera_from_preview(self, message: PreviewMessage) -> None:
        """Until the site sends a calibration, place the cameras where the detectors' previews
        say they are (the preview's intrinsics have the full field of view)."""
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
            self.calibration = calibration = self._preview_calibration
        self._emit("calibration", calibration)

    # ------------------------------------------------------------ polling
    def statuses(self) -> dict[str, dict[str, Any]]:
        """Each node's last status, as the ``status`` event gave it."""
        with self._lock:
            return dict(self._statuses)

    def schemas(self) -> dict[str, Schema]:
        """The schemas of the stages the site's nodes run."""
        return {stage: REGISTRY[stage] for stage in sorted(self._stages_shown)}

    def nodes_running(self, stage: str) -> list[str]:
        return sorted(node for node, stages in self._node_stages.items() if stage in stages)

    def detector_nodes(self) -> list[str]:
        """The detector nodes that are not stopped, ended or failed."""
        gone = ("stopped", "ended", "error")
        return sorted(node for node, state in self._detectors.items() if state not in gone)

    def outputs(self, kind: str) -> list[str]:
        """The ``kind`` destinations (udp, osc, websocket) the site runs, as it last said."""
        with self._lock:
            return list(self._outputs.get(kind, []))

    def destinations(self) -> list[dict[str, Any]]:
        """Every outputs node's destinations (kind, address, enabled, sent, packets_per_s,
        error), those turned off included."""
        statuses = self.statuses()
        return [
            destination
            for node in sorted(statuses)
            if statuses[node].get("role") == "outputs"
            for destination in statuses[node].get("destinations", [])
        ]

    # --------------------------------------------------- operator's intent
    def set_params(self, stage: str, values: dict[str, Any]) -> None:
        """Send validated parameter values to every node that runs ``stage``."""
        bus = self.bus
        nodes = self.nodes_running(stage)
        if bus is None or not nodes:
            names = ", ".join(f"{stage}.{name}" for name in values)
            self._emit(
                "log",
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

    def set_outputs(self, kind: str, destinations: list[str]) -> None:
        """Stream to exactly these ``kind`` destinations."""
        self.set_params("outputs", {kind: join_destinations(destinations)})

    def _same(self, kind: str, a: str, b: str) -> bool:
        port = OUTPUT_PORTS[kind]
        try:
            return parse_address(a, port, kind, True) == parse_address(b, port, kind, True)
        except UserError:
            return a == b

    def add_output(self, kind: str, address: str) -> None:
        """Start streaming tracks to ``address`` (a WebSocket output is one server)."""
        current = [] if kind == "websocket" else self.outputs(kind)
        self.set_outputs(kind, [*current, address])

    def _take_out(self, kind: str, address: str) -> None:
        kept = [d for d in self.outputs(kind) if not self._same(kind, d, address)]
        self.set_outputs(kind, kept)

    def remove_output(self, kind: str, address: str) -> None:
        with self._lock:
            disabled = (kind, address) in self._disabled
            self._disabled.discard((kind, address))
        if not disabled:  # a turned-off destination is not running: only forget it
            self._take_out(kind, address)

    def enable_output(self, kind: str, address: str, enabled: bool) -> None:
        """Turn a destination off (the site stops it; the client remembers it) or on again."""
        with self._lock:
            if enabled:
                self._disabled.discard((kind, address))
            else:
                self._disabled.add((kind, address))
        if enabled:
            self.add_output(kind, address)
        else:
            self._take_out(kind, address)

    # Recording and playback: commands to every detector node, on a worker thread (each
    # node may take up to recorder.command_timeout_s to answer); the answer is a
    # ``command_reply`` event, and a refusal also a sentence on ``log``.
    def _command(
        self, action: str, work: Callable[[Any, list[str]], Any]
    ) -> threading.Thread | None:
        from optrack.runtime.node_recording import SiteControl

        bus = self.bus
        if bus is None:
            self._refuse(action, f"Not connected to {self.describe()} yet; try again shortly.")
            return None

        def run() -> None:
            try:
                result = work(SiteControl(bus), self.detector_nodes())
            except UserError as error:
                self._emit("log", "error", str(error))
                self._emit("command_reply", action, False, str(error), {})
                return
            self._emit("command_reply", action, True, "", result)

        thread = threading.Thread(target=run, name=f"site-{action}", daemon=True)
        thread.start()
        return thread

    def _refuse(self, action: str, sentence: str) -> None:
        self._emit("log", "warning", sentence)
        self._emit("command_reply", action, False, sentence, {})

    def start_recording(self, folder: str) -> threading.Thread | None:
        """Every detector node records its sensor into ``folder`` (on its own computer).
        Returns the thread that waits for the answers (join it to wait), or None when
        refused at once (not connected)."""
        return self._command("record_start", lambda c, nodes: c.start_recording(nodes, folder))

    def stop_recording(self) -> threading.Thread | None:
        return self._command("record_stop", lambda c, nodes: c.stop_recording(nodes))

    def playback(self, action: str, **args: Any) -> threading.Thread | None:
        """``action`` (pause, resume, step, speed with ``value``) on every replayed sensor."""
        return self._command(action, lambda c, nodes: c.playback(nodes, action, **args))

    def close(self) -> None:
        """Leave the bus; idempotent."""
        with self._lock:
            self._closed = True
            bus, self.bus = self.bus, None
        if bus is not None:
            bus.close()
