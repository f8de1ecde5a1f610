"""The bus: a Zenoh session of one site, carrying validated messages.

``Bus`` publishes :class:`~optrack.net.messages.Message` values on the key
expressions of :class:`~optrack.net.keys.SiteKeys`, and hands subscribers
only messages that decode and validate as the kind expected on that key.
Anything else (random bytes, another wire version, the wrong kind, a huge
payload, a NaN position) is counted in :class:`MessageStats`, logged once per
source key, and dropped: a bad message never stops a node. A subscriber
callback that raises is counted and logged the same way.
"""

from __future__ import annotations

import atexit
import logging
import threading
import time
import weakref
from collections import Counter
from collections.abc import Callable
from typing import Any, TypeVar

import zenoh

from optrack.errors import UserError
from optrack.net.config import (
    BUS_PARAMS,
    endpoints,
    local_endpoint,
    site_identity,
    zenoh_config,
)
from optrack.net.keys import SiteKeys, check_name
from optrack.net.messages import REJECT_REASONS, Message, MessageError, decode, encode

__all__ = ["Bus", "BusError", "MessageStats"]

log = logging.getLogger("optrack.net")

M = TypeVar("M", bound=Message)


_open_buses: weakref.WeakSet[Bus] = weakref.WeakSet()


def _close_open_buses() -> None:
    """Close the buses a program left open. Zenoh runs Python callbacks on non-daemon
    threads that end only when their subscription does, and the interpreter joins those
    threads before ``atexit`` handlers run; so this hooks where ``concurrent.futures``
    does, just before that join (and ``atexit`` where that hook does not exist)."""
    for bus in list(_open_buses):
        bus.close()


_register = getattr(threading, "_register_atexit", atexit.register)
_register(_close_open_buses)


class BusError(UserError):
    """The bus cannot be joined (nothing to connect to, a port in use)."""


class MessageStats:
    """Counts of received, accepted and rejected messages; thread-safe.

    The first rejection from each source key is logged (with its reason);
    later ones from the same source are only counted, so a flood of bad
    messages cannot flood the log.
    """

    def __init__(self, logger: logging.Logger = log) -> None:
        self._lock = threading.Lock()
        self._counts: Counter[str] = Counter()
        self._logged: set[str] = set()
        self._logger = logger

    def accept(self, key: str) -> None:
        with self._lock:
            self._counts["received"] += 1
            self._counts["accepted"] += 1

    def reject(self, key: str, error: MessageError) -> None:
        with self._lock:
            self._counts["received"] += 1
            self._counts["rejected"] += 1
            self._counts[f"rejected_{error.reason}"] += 1
            first = key not in self._logged
            self._logged.add(key)
        if first:
            self._logger.warning(
                "refused a message on %s: %s (further refusals from it are only counted)",
                key,
                error,
            )

    def handler_error(self, key: str, error: BaseException) -> None:
        with self._lock:
            self._counts["handler_errors"] += 1
            first = f"handler:{key}" not in self._logged
            self._logged.add(f"handler:{key}")
        if first:
            self._logger.error(
                "handling a message from %s failed: %s (further failures are only counted)",
                key,
                error,
                exc_info=error,
            )

    def snapshot(self) -> dict[str, int]:
        """``received``, ``accepted``, ``rejected``, ``rejected_<reason>``, ``handler_errors``."""
        with self._lock:
            counts = dict(self._counts)
        base = {"received": 0, "accepted": 0, "rejected": 0, "handler_errors": 0}
        base.update({f"rejected_{r}": 0 for r in REJECT_REASONS})
        base.update(counts)
        return base


def _open_session(config: zenoh.Config, params: Any, host: bool) -> zenoh.Session:
    deadline = time.monotonic() + float(params.connect_timeout_s)
    while True:
        try:
            return zenoh.open(config)
        except zenoh.ZError as error:
            if host or time.monotonic() >= deadline:
                raise BusError(_open_failure(params, host, error)) from None
            time.sleep(0.2)


def _open_failure(params: Any, host: bool, error: Exception) -> str:
    mode = str(params.mode)
    if mode == "local" and host:
        return (
            f"cannot host the local site on {local_endpoint(params)} ({error}); another site is "
            "probably running there: stop it or set bus.local_port to a free port."
        )
    if mode == "local":
        return (
            f"cannot reach the local site's hub at {local_endpoint(params)} within "
            f"{float(params.connect_timeout_s):g} s; start the tracker node first "
            "('optrack node track') or run the whole site with 'optrack run'."
        )
    where = ", ".join(endpoints(str(params.connect))) or "by scouting"
    return (
        f"cannot join the bus ({mode} mode, connecting {where}): {error}; check bus.connect, "
        "bus.listen and the network."
    )


class Bus:
    """One node's connection to a site's bus.

    ``node`` names this node (it stamps ``sender`` on what it publishes);
    ``host`` makes it host a local site's hub (the tracker node, or the
    ``optrack run`` launcher). Close it (or use ``with``): open Zenoh
    sessions keep the interpreter from exiting.
    """

    def __init__(
        self,
        site: str,
        node: str,
        params: Any | None = None,
        *,
        host: bool = False,
        logger: logging.Logger = log,
    ) -> None:
        self.keys = SiteKeys(site)
        self.node = check_name("node", node)
        self.params = params if params is not None else BUS_PARAMS.create()
        self.host = host
        self.stats = MessageStats(logger)
        self.max_bytes = int(self.params.max_message_bytes)
        self._logger = logger
        self._lock = threading.Lock()
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._declared: list[Any] = []
        #: joined without keys (``bus.insecure``): anyone on the network may speak
        self.insecure = not self.params.zenoh_config and site_identity(self.params, node) is None
        config = zenoh_config(self.params, host=host, node=self.node)
        self.session = _open_session(config, self.params, host)
        self._closed = False
        _open_buses.add(self)

    # ----------------------------------------------------------- publishing
    def publish(self, key: str, message: Message, *, realtime: bool = True) -> None:
        """Send a message. ``realtime``: low latency and dropped under congestion
        (detections, tracks, status, previews); otherwise reliable and blocking
        (calibration, parameters)."""
        if not message.sender:
            message.sender = self.node
        payload = encode(message)
        with self._lock:
            if self._closed:
                return
            publisher = self._publishers.get(key)
            if publisher is None:
                if realtime:
                    publisher = self.session.declare_publisher(
                        key,
                        congestion_control=zenoh.CongestionControl.DROP,
                        priority=zenoh.Priority.INTERACTIVE_HIGH,
                        express=True,
                    )
                else:
                    publisher = self.session.declare_publisher(
                        key,
                        congestion_control=zenoh.CongestionControl.BLOCK,
                        priority=zenoh.Priority.DATA,
                        reliability=zenoh.Reliability.RELIABLE,
                    )
                self._publishers[key] = publisher
        publisher.put(payload)

    def put_raw(self, key: str, payload: bytes) -> None:
        """Send bytes as they are, reliably (tests and tools that check what nodes refuse)."""
        self.session.put(key, payload, congestion_control=zenoh.CongestionControl.BLOCK)

    # ---------------------------------------------------------- subscribing
    def _decoded(self, cls: type[M], payload: zenoh.ZBytes | None, key: str) -> M | None:
        try:
            if payload is None:
                raise MessageError("malformed", f"an empty payload arrived on {key}.")
            size = len(payload)
            if size > self.max_bytes:
                raise MessageError(
                    "too_large",
                    f"a message of {size} bytes is larger than the {self.max_bytes}-byte "
                    "limit (bus.max_message_bytes).",
                )
            return decode(payload.to_bytes(), cls, self.max_bytes)
        except MessageError as error:
            self.stats.reject(key, error)
            return None

    def subscribe(
        self, key: str, cls: type[M], callback: Callable[[M, str], None]
    ) -> zenoh.Subscriber[None]:
        """Call ``callback(message, key)`` for every valid ``cls`` message on ``key``
        (which may hold wildcards). Runs on a Zenoh thread: keep it short."""

        def on_sample(sample: zenoh.Sample) -> None:
            key_here = str(sample.key_expr)
            try:
                if sample.kind != zenoh.SampleKind.PUT:
                    return
                message = self._decoded(cls, sample.payload, key_here)
                if message is None:
                    return
                self.stats.accept(key_here)
                callback(message, key_here)
            except Exception as error:  # a bad message or handler never kills the node
                self.stats.handler_error(key_here, error)

        subscriber = self.session.declare_subscriber(key, on_sample)
        self._declared.append(subscriber)
        return subscriber

    def serve(
        self, key: str, cls: type[M], answer: Callable[[M], Message | None]
    ) -> zenoh.Queryable[None]:
        """Answer queries on ``key`` whose payload is a valid ``cls`` message."""

        def on_query(query: zenoh.Query) -> None:
            key_here = str(query.key_expr)
            try:
                message = self._decoded(cls, query.payload, key_here)
                if message is None:
                    return
                self.stats.accept(key_here)
                reply = answer(message)
                if reply is not None:
                    if not reply.sender:
                        reply.sender = self.node
                    query.reply(key, encode(reply))
            except Exception as error:
                self.stats.handler_error(key_here, error)

        queryable = self.session.declare_queryable(key, on_query)
        self._declared.append(queryable)
        return queryable

    def query(self, key: str, request: Message, cls: type[M], timeout: float = 1.0) -> list[M]:
        """Valid ``cls`` replies to ``request`` from the queryables on ``key``."""
        if not request.sender:
            request.sender = self.node
        replies = self.session.get(
            key,
            payload=encode(request),
            timeout=timeout,
            priority=zenoh.Priority.REAL_TIME,
            express=True,
        )
        messages: list[M] = []
        for reply in replies:
            sample = reply.ok
            if sample is None:
                continue
            message = self._decoded(cls, sample.payload, str(sample.key_expr))
            if message is not None:
                self.stats.accept(str(sample.key_expr))
                messages.append(message)
        return messages

    # -------------------------------------------------------------- closing
    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        """Undeclare everything and close the session; idempotent."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            publishers = list(self._publishers.values())
            self._publishers.clear()
        for entity in [*self._declared, *publishers]:
            try:
                entity.undeclare()
            except zenoh.ZError:
                pass
        self._declared.clear()
        self.session.close()

    def __enter__(self) -> Bus:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
