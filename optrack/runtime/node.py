"""What every node of a site does: status, live parameters, a clean stop.

A node holds a :class:`~optrack.net.bus.Bus`, takes parameter updates on
``optrack/<site>/params/<node>`` (validated through the stage's schema and
applied all-or-nothing between two frames, :meth:`Node.apply_params`), and
publishes its :class:`~optrack.net.messages.StatusMessage` on
``optrack/<site>/status/<node>`` every ``node.status_period_s`` from a
background thread. A node started by ``optrack run`` also stops by itself
when the launcher disappears (``OPTRACK_PARENT_PID``).
"""

from __future__ import annotations

import collections
import logging
import os
import statistics
import threading
import time
from collections.abc import Callable, Mapping
from typing import Any, ClassVar

from optrack.errors import UserError
from optrack.net.bus import Bus
from optrack.net.messages import CommandReply, CommandRequest, ParamsMessage, StatusMessage
from optrack.params import ParamError, Params

__all__ = ["PARENT_ENV", "Node", "RateMeter"]

PARENT_ENV = "OPTRACK_PARENT_PID"

log = logging.getLogger("optrack.runtime")


class RateMeter:
    """Events per second and the median of a value over a sliding window; thread-safe."""

    def __init__(self, window_s: float = 2.0) -> None:
        self.window_s = window_s
        self._events: collections.deque[tuple[float, float]] = collections.deque()
        self._lock = threading.Lock()
        self.count = 0

    def add(self, value: float = 0.0, now: float | None = None) -> None:
        now = time.monotonic() if now is None else now
        with self._lock:
            self._events.append((now, value))
            self.count += 1
            self._trim(now)

    def _trim(self, now: float) -> None:
        while self._events and now - self._events[0][0] > self.window_s:
            self._events.popleft()

    def rate(self, now: float | None = None) -> float:
        now = time.monotonic() if now is None else now
        with self._lock:
            self._trim(now)
            return len(self._events) / self.window_s

    def median(self) -> float:
        with self._lock:
            values = [v for _, v in self._events]
        return statistics.median(values) if values else 0.0

    def percentile(self, q: float) -> float:
        """The q-th percentile (0-100, linear interpolation) of the values in the window."""
        with self._lock:
            values = sorted(v for _, v in self._events)
        if not values:
            return 0.0
        position = (len(values) - 1) * q / 100.0
        below = int(position)
        above = min(below + 1, len(values) - 1)
        return values[below] + (values[above] - values[below]) * (position - below)


def live_schemas(
    live: Mapping[str, Params] | None, node_params: Params, schemas: Mapping[str, Any]
) -> dict[str, Params]:
    """A node's live parameter sets: those given, each schema's defaults for the rest, and
    the node's own parameters under ``node``."""
    sets = dict(live or {})
    for name, schema in schemas.items():
        sets.setdefault(name, schema.create())
    sets["node"] = node_params
    return sets


class Node:
    """Base of the detector, tracker and outputs nodes.

    ``live`` maps the stages this node takes updates for to the very
    :class:`~optrack.params.Params` objects its stages read, so an update
    changes behaviour on the next frame.
    """

    role: ClassVar[str] = "node"

    def __init__(
        self,
        bus: Bus,
        name: str,
        node_params: Params,
        live: Mapping[str, Params],
        logger: logging.Logger = log,
    ) -> None:
        self.bus = bus
        self.name = name
        self.node_params = node_params
        self.live = dict(live)
        self.log = logger
        self.started = time.monotonic()
        self.state = "starting"
        self.last_error = ""
        self.request = ""
        self.params_applied = 0
        self.params_refused = 0
        self._inbox: collections.deque[ParamsMessage] = collections.deque()
        self._stop = threading.Event()
        self._status_thread: threading.Thread | None = None
        self._closed = False
        parent = os.environ.get(PARENT_ENV)
        self._parent = int(parent) if parent and parent.isdigit() else None
        self._commands: dict[str, Callable[[dict[str, Any]], dict[str, Any] | None]] = {}
        bus.subscribe(bus.keys.params(name), ParamsMessage, self._on_params)
        bus.serve(bus.keys.command(name), CommandRequest, self._on_command)

    # -------------------------------------------------------------- commands
    def add_command(
        self, action: str, handler: Callable[[dict[str, Any]], dict[str, Any] | None]
    ) -> None:
        """Answer ``action`` commands with ``handler(args) -> result``. It runs on the
        bus's thread: it must return quickly (set a flag, start a thread) and be
        thread-safe; a UserError it raises is the refusal sentence sent back."""
        self._commands[action] = handler

    def _on_command(self, request: CommandRequest) -> CommandReply:
        handler = self._commands.get(request.action)
        if handler is None:
            known = ", ".join(sorted(self._commands)) or "none"
            return CommandReply(
                node=self.name,
                action=request.action,
                ok=False,
                sentence=f"node '{self.name}' has no command '{request.action}' (it has: {known}).",
            )
        try:
            result = handler(dict(request.args)) or {}
        except UserError as error:
            self.report_error(f"command '{request.action}' refused: {error}")
            return CommandReply(
                node=self.name, action=request.action, ok=False, sentence=str(error)
            )
        return CommandReply(node=self.name, action=request.action, ok=True, result=result)

    # ------------------------------------------------------------ parameters
    def _on_params(self, message: ParamsMessage, key: str) -> None:
        self._inbox.append(message)

    def apply_params(self) -> dict[str, dict[str, Any]]:
        """Apply the updates received since the last call; returns what changed."""
        changed_all: dict[str, dict[str, Any]] = {}
        while self._inbox:
            message = self._inbox.popleft()
            try:
                changed_all.update(self._apply(message))
                self.params_applied += 1
            except UserError as error:
                self.params_refused += 1
                self.report_error(f"parameter update refused: {error}")
            self.request = message.request
        return changed_all

    def _apply(self, message: ParamsMessage) -> dict[str, dict[str, Any]]:
        checked: dict[str, dict[str, Any]] = {}
        for stage, values in message.updates.items():
            params = self.live.get(stage)
            if params is None:
                raise ParamError(
                    f"node '{self.name}' takes no '{stage}' parameters (it takes: "
                    f"{', '.join(self.live) or 'none'})."
                )
            checked[stage] = params.schema.validate(values)
        before = {stage: self.live[stage].as_dict() for stage in checked}
        changed_all: dict[str, dict[str, Any]] = {}
        try:
            for stage, values in checked.items():
                changed = self.live[stage].update(values)
                if changed:
                    self.on_params(stage, changed)
                    changed_all[stage] = changed
        except UserError:
            for stage, values in before.items():  # all or nothing
                self.live[stage].update(values)
            raise
        if changed_all:
            described = "; ".join(
                f"{stage}.{name} = {value!r}"
                for stage, values in changed_all.items()
                for name, value in values.items()
            )
            self.log.info("parameters changed: %s", described)
        return changed_all

    def on_params(self, stage: str, changed: dict[str, Any]) -> None:
        """React to changed values (raise a UserError to refuse them)."""

    def report_error(self, sentence: str) -> None:
        """Keep the sentence for the status; log it unless it repeats the last one (a
        flood of the same bad request is logged once)."""
        if sentence != self.last_error:
            self.log.warning("%s", sentence)
        self.last_error = sentence

    # ---------------------------------------------------------------- status
    def status_fields(self) -> dict[str, Any]:
        """Role-specific fields of the status message."""
        return {}

    def status(self) -> StatusMessage:
        fields: dict[str, Any] = {
            "node": self.name,
            "role": self.role,
            "state": self.state,
            "stamp": time.time(),
            "uptime_s": time.monotonic() - self.started,
            "last_error": self.last_error,
            "counters": {
                **self.bus.stats.snapshot(),
                "params_applied": self.params_applied,
                "params_refused": self.params_refused,
            },
            "params": {stage: params.as_dict() for stage, params in self.live.items()},
            "request": self.request,
        }
        fields.update(self.status_fields())
        if self.bus.insecure:  # joined without keys (--insecure): every status says so
            fields["values"] = {**fields.get("values", {}), "insecure": True}
        return StatusMessage(**fields)

    def publish_status(self) -> None:
        if not self.bus.closed:
            self.bus.publish(self.bus.keys.status(self.name), self.status())

    def start_status(self) -> None:
        if self._status_thread is None:
            self._status_thread = threading.Thread(
                target=self._status_loop, name="status", daemon=True
            )
            self._status_thread.start()

    def _status_loop(self) -> None:
        while not self._stop.wait(float(self.node_params.status_period_s)):
            if self._parent is not None and os.getppid() != self._parent:
                self.log.warning("the site launcher has gone; stopping.")
                self.stop()
                return
            try:
                self.publish_status()
            except Exception as error:  # the bus closing under us
                if not self._stop.is_set():
                    self.log.debug("status not published: %s", error)

    # ---------------------------------------------------------------- life
    @property
    def stopping(self) -> bool:
        return self._stop.is_set()

    def stop(self) -> None:
        """Ask the node to stop (thread- and signal-safe)."""
        self._stop.set()

    def close(self) -> None:
        """Stop and publish a last status; idempotent. The bus stays open: whoever
        opened it closes it (several nodes may share one)."""
        self._stop.set()
        if self._status_thread is not None:
            self._status_thread.join(timeout=2.0)
            self._status_thread = None
        if self._closed:
            return
        self._closed = True
        if self.state not in ("ended", "error"):
            self.state = "stopped"
        try:
            self.publish_status()
        except Exception as error:
            self.log.debug("last status not published: %s", error)


class CommandError(UserError):
    """A command no node answered, or one a node refused."""


def send_command(
    bus: Bus, node: str, action: str, args: Mapping[str, Any] | None = None, timeout: float = 2.0
) -> dict[str, Any]:
    """Ask ``node`` to do ``action``; its result, or a :class:`CommandError` with the
    node's sentence (or saying that no node answered)."""
    replies = bus.query(
        bus.keys.command(node),
        CommandRequest(action=action, args=dict(args or {})),
        CommandReply,
        timeout=timeout,
    )
    if not replies:
        raise CommandError(
            f"node '{node}' did not answer the '{action}' command within {timeout:g} s; "
            "check that it is running (Sensors dock, or `optrack run` output)."
        )
    reply = replies[0]
    if not reply.ok:
        raise CommandError(reply.sentence or f"node '{node}' refused '{action}'.")
    return dict(reply.result)
