"""The window's source for a site on the Zenoh bus: the GUI is one more node (like rviz).

All the talking to the site is :class:`optrack.client.SiteClient`'s (it
subscribes to the site's tracks, detections, calibration, statuses and
previews, computes the outputs' packet rates, keeps the outputs as lists of
destinations and sends the operator's parameter changes and commands); this
class only re-emits its events as :class:`~app.source.SiteSource` signals,
emitted on the window's thread. Joining the bus can take seconds, so it
happens on the client's thread; the window stays responsive and hears the
outcome on ``connection`` and ``log``.

A site can send faster than a loaded window draws (tracks at hundreds a
second, a busy computer): the client holds what arrives
(:meth:`~optrack.client.SiteClient.deliver_later`), the newest tracks,
skeletons and calibration and each node's newest status and sensor's newest
preview replacing older ones not yet shown, and wakes the window's thread
once; that thread emits all of it in one pass of its event loop. So at most
one delivery waits in the event loop at any time, and however fast the site
sends, the window's thread never falls behind by more than one pass.
"""

from __future__ import annotations

import os
import threading
from typing import Any

from PySide6.QtCore import Qt, Signal

from app.source import SiteSource
from optrack.client import EVENTS, SiteClient
from optrack.net import Bus
from optrack.params import Params

__all__ = ["BusSource"]


class BusSource(SiteSource):
    """A site on the bus. ``bus_params`` are the ``bus`` stage's values (mode, endpoints)."""

    _wake = Signal()  # something arrived: deliver it on this object's (the window's) thread

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
        self.client = SiteClient(
            site, bus_params, node=f"gui-{os.getpid()}", retry_while=retry_while, label=label
        )
        for event in EVENTS:  # each event of the client is the signal of the same name
            self.client.on(event, getattr(self, event).emit)
        self._wake.connect(self._deliver, Qt.ConnectionType.QueuedConnection)
        self.client.deliver_later(self._wake.emit)
        self.client.start()

    @property
    def node(self) -> str:
        return self.client.node

    @property
    def bus(self) -> Bus | None:
        return self.client.bus

    @property
    def connected(self) -> bool:
        return self.client.connected

    def _deliver(self) -> None:
        self.client.deliver()

    @property
    def insecure(self) -> bool:
        """The site runs without keys (no TLS, no access control)."""
        return self.client.insecure

    def describe(self) -> str:
        return self.client.describe()

    def nodes_running(self, stage: str) -> list[str]:
        return self.client.nodes_running(stage)

    def detector_nodes(self) -> list[str]:
        return self.client.detector_nodes()

    # ---------------------------------------------------- operator's intent
    def set_params(self, stage: str, values: dict[str, Any]) -> None:
        self.client.set_params(stage, values)

    def add_output(self, kind: str, address: str) -> None:
        self.client.add_output(kind, address)

    def remove_output(self, kind: str, address: str) -> None:
        self.client.remove_output(kind, address)

    def enable_output(self, kind: str, address: str, enabled: bool) -> None:
        self.client.enable_output(kind, address, enabled)

    def start_recording(self, folder: str) -> None:
        self.client.start_recording(folder)

    def stop_recording(self) -> None:
        self.client.stop_recording()

    def playback(self, action: str, **args: Any) -> None:
        self.client.playback(action, **args)

    def close(self) -> None:
        self.client.close()
