"""All outputs of a site: tracks in, UDP JSON / OSC / WebSocket out, plus the heartbeat.

:class:`Outputs` takes each :class:`~optrack.types.TrackBatch` (and, while the
skeleton stage runs, each :class:`~optrack.types.SkeletonBatch`) and sends it
to every destination of the ``outputs`` parameters; a thread sends the
heartbeat every ``heartbeat_s`` whether or not tracks arrive. ``alive_IDs``
are the ids of the latest batch (none once no batch came for ``stale_s``),
``max_ID`` the largest id ever sent. Parameters can change while running
(:meth:`Outputs.configure`): the destinations are rebuilt, sequence numbers
go on.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Mapping
from typing import Any

from optrack.net.messages import DestinationStatus
from optrack.outputs import openptrack_json, osc
from optrack.outputs.udp import MODES, Destination, UdpSender, parse_address, parse_destinations
from optrack.outputs.websocket import DEFAULT_ORIGINS, WebSocketServer
from optrack.params import Param, Params, Schema, register
from optrack.types import SkeletonBatch, TrackBatch

__all__ = ["DEFAULT_UDP_PORT", "OUTPUTS_PARAMS", "OUTPUT_KINDS", "OUTPUT_PORTS", "Outputs"]

log = logging.getLogger("optrack.outputs")

DEFAULT_UDP_PORT = 21234  # OpenPTrack's
DEFAULT_OSC_PORT = 21235
DEFAULT_WEBSOCKET_PORT = 21236
#: The kinds of destination of the ``outputs`` stage, each with the port of an address
#: that leaves its port out.
OUTPUT_PORTS = {
    "udp": DEFAULT_UDP_PORT,
    "osc": DEFAULT_OSC_PORT,
    "websocket": DEFAULT_WEBSOCKET_PORT,
}
OUTPUT_KINDS = tuple(OUTPUT_PORTS)

OUTPUTS_PARAMS = register(
    Schema(
        "outputs",
        [
            Param(
                "udp",
                f"127.0.0.1:{DEFAULT_UDP_PORT}",
                help="OpenPTrack JSON over UDP: comma-separated HOST:PORT destinations "
                f"(port {DEFAULT_UDP_PORT} when left out); empty: off.",
            ),
            Param(
                "udp_mode",
                "unicast",
                choices=MODES,
                help="unicast to each host, broadcast (e.g. 192.168.1.255) or multicast "
                "(a group such as 239.255.0.1).",
            ),
            Param(
                "multicast_ttl",
                1,
                min=0,
                max=255,
                step=1,
                help="Router hops a multicast datagram may cross (1: this network only).",
            ),
            Param(
                "multicast_interface",
                "",
                help="IPv4 address of the interface multicast leaves by; empty: the system's.",
            ),
            Param(
                "heartbeat_s",
                0.25,
                min=0.01,
                max=60.0,
                step=0.01,
                unit="s",
                help="Period of the heartbeat (alive_IDs, max_ID).",
            ),
            Param(
                "stale_s",
                1.0,
                min=0.05,
                max=60.0,
                step=0.05,
                unit="s",
                help="With no tracks for this long the heartbeat reports nobody alive.",
            ),
            Param(
                "max_datagram_bytes",
                65000,
                min=512,
                max=65507,
                step=1,
                unit="bytes",
                help="A frame's JSON larger than this is split into several documents.",
            ),
            Param(
                "osc",
                "",
                help="OSC over UDP: comma-separated HOST:PORT destinations "
                f"(port {DEFAULT_OSC_PORT} when left out); empty: off.",
            ),
            Param(
                "websocket",
                "",
                help="WebSocket server address HOST:PORT for browsers "
                f"(port {DEFAULT_WEBSOCKET_PORT} when left out; 0: any free port); empty: off.",
            ),
            Param(
                "websocket_origins",
                ",".join(DEFAULT_ORIGINS),
                help="Comma-separated origins of the web pages that may connect to the "
                "WebSocket output (scheme://host[:port]; without a port: any port of that host; "
                "'null': pages opened from a file; '*': any page).",
            ),
            Param(
                "websocket_token",
                "",
                help="When set, a WebSocket client must give it in its URL (?token=...).",
            ),
        ],
        help="Where tracks go: OpenPTrack JSON over UDP, OSC and WebSocket.",
    )
)


class Outputs:
    """The site's outputs; thread-safe. Close it to stop the heartbeat and the server."""

    def __init__(
        self, params: Params | None = None, clock: Callable[[], float] = time.time
    ) -> None:
        self.params = params if params is not None else OUTPUTS_PARAMS.create()
        self.clock = clock
        self._lock = threading.RLock()
        self.track_seq = 0
        self.heartbeat_seq = 0
        self.skeleton_seq = 0
        self.alive_ids: list[int] = []
        self.max_id = 0
        self.last_batch_at: float | None = None
        self.frames = 0
        self._udp: UdpSender | None = None
        self._osc: UdpSender | None = None
        self._websocket: WebSocketServer | None = None
        self._built: dict[str, Any] = {}
        self._stop = threading.Event()
        self.configure(self.params.as_dict())
        self._thread = threading.Thread(target=self._beat, name="heartbeat", daemon=True)
        self._thread.start()

    # -------------------------------------------------------- configuration
    def configure(self, values: Mapping[str, Any]) -> None:
        """Apply parameter values. Everything is validated and built before anything
        is swapped, so a bad destination leaves the running outputs as they were
        (except a WebSocket address change, which must free the old port first)."""
        with self._lock:
            updated = Params(self.params.schema, {**self.params.as_dict(), **values})
            built = {
                "udp": (
                    updated.udp,
                    updated.udp_mode,
                    updated.multicast_ttl,
                    updated.multicast_interface,
                ),
                "osc": updated.osc,
                "websocket": (
                    updated.websocket,
                    updated.websocket_origins,
                    updated.websocket_token,
                ),
            }
            udp, osc_sender, websocket = self._udp, self._osc, self._websocket
            created: list[UdpSender] = []
            try:
                if self._built.get("udp") != built["udp"]:
                    udp = UdpSender(
                        [
                            Destination(
                                "udp",
                                host,
                                port,
                                str(updated.udp_mode),
                                int(updated.multicast_ttl),
                                str(updated.multicast_interface),
                            )
                            for host, port in parse_destinations(
                                str(updated.udp), DEFAULT_UDP_PORT, "outputs.udp destination"
                            )
                        ]
                    )
                    created.append(udp)
                if self._built.get("osc") != built["osc"]:
                    osc_sender = UdpSender(
                        [
                            Destination("osc", host, port)
                            for host, port in parse_destinations(
                                str(updated.osc), DEFAULT_OSC_PORT, "outputs.osc destination"
                            )
                        ]
                    )
                    created.append(osc_sender)
                if self._built.get("websocket") != built["websocket"]:
                    websocket = None
                    text = str(updated.websocket).strip()
                    if text:
                        host, port = parse_address(
                            text, DEFAULT_WEBSOCKET_PORT, "outputs.websocket address", any_port=True
                        )
                        if self._websocket is not None:
                            self._websocket.close()  # free the port before binding it again
                            self._websocket = None
                        origins = [
                            o.strip()
                            for o in str(updated.websocket_origins).split(",")
                            if o.strip()
                        ]
                        websocket = WebSocketServer(
                            host, port, origins=origins, token=str(updated.websocket_token)
                        )
            except BaseException:
                for sender in created:
                    sender.close()
                raise
            for old, new in ((self._udp, udp), (self._osc, osc_sender)):
                if old is not None and old is not new:
                    old.close()
            if self._websocket is not None and self._websocket is not websocket:
                self._websocket.close()
            self._udp, self._osc, self._websocket = udp, osc_sender, websocket
            self._built = built
            self.params.update(updated.as_dict())

    @property
    def websocket_port(self) -> int | None:
        return self._websocket.port if self._websocket is not None else None

    # ------------------------------------------------------------- sending
    def publish(self, batch: TrackBatch) -> None:
        """Send one frame of tracks to every destination."""
        with self._lock:
            self.track_seq += 1
            self.frames += 1
            self.alive_ids = [int(t.id) for t in batch.tracks]
            if self.alive_ids:
                self.max_id = max(self.max_id, *self.alive_ids)
            self.last_batch_at = self.clock()
            datagrams = openptrack_json.track_datagrams(
                self.track_seq, batch, int(self.params.max_datagram_bytes)
            )
            self._send_json(datagrams)
            if self._osc is not None and self._osc.destinations:
                self._osc.send(osc.frame_bundle(self.track_seq, batch))

    def _send_json(self, datagrams: list[bytes]) -> None:
        """JSON documents to every UDP destination and WebSocket client."""
        if self._udp is not None:
            for datagram in datagrams:
                self._udp.send(datagram)
        if self._websocket is not None:
            for datagram in datagrams:
                self._websocket.send(datagram.decode("utf-8"))

    def publish_skeletons(self, batch: SkeletonBatch) -> None:
        """Send one frame of skeletons to every destination (OpenPTrack v2's pose
        message over UDP and WebSocket, OSC bundles)."""
        with self._lock:
            self.skeleton_seq += 1
            max_bytes = int(self.params.max_datagram_bytes)
            datagrams = openptrack_json.skeleton_datagrams(self.skeleton_seq, batch, max_bytes)
            self._send_json(datagrams)
            if self._osc is not None and self._osc.destinations:
                for bundle in osc.skeleton_bundles(self.skeleton_seq, batch, max_bytes):
                    self._osc.send(bundle)

    def heartbeat(self) -> None:
        """Send the heartbeat now."""
        with self._lock:
            now = self.clock()
            if self.last_batch_at is None or now - self.last_batch_at > float(self.params.stale_s):
                self.alive_ids = []
            self.heartbeat_seq += 1
            datagram = openptrack_json.encode(
                openptrack_json.heartbeat_document(
                    self.heartbeat_seq, now, self.alive_ids, self.max_id
                )
            )
            self._send_json([datagram])
            if self._osc is not None and self._osc.destinations:
                self._osc.send(osc.alive_bundle(self.alive_ids, self.max_id))

    def _beat(self) -> None:
        next_beat = time.monotonic()
        while not self._stop.is_set():
            try:
                self.heartbeat()
            except Exception as error:  # never let the heartbeat thread die
                log.error("heartbeat failed: %s", error, exc_info=error)
            next_beat += float(self.params.heartbeat_s)
            delay = next_beat - time.monotonic()
            if delay < 0:  # fell behind (suspended, overloaded): do not burst
                next_beat, delay = time.monotonic(), 0.0
            self._stop.wait(delay)

    # -------------------------------------------------------------- status
    def status(self) -> list[DestinationStatus]:
        with self._lock:
            found: list[DestinationStatus] = []
            for sender in (self._udp, self._osc):
                if sender is not None:
                    found.extend(sender.status())
            if self._websocket is not None:
                found.append(self._websocket.status())
            return found

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        with self._lock:
            for sender in (self._udp, self._osc):
                if sender is not None:
                    sender.close()
            if self._websocket is not None:
                self._websocket.close()
            self._udp = self._osc = None
            self._websocket = None

    def __enter__(self) -> Outputs:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
