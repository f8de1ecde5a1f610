"""Who moves the board: the live calibration's view of the site's operator.

The live calibration (:class:`optrack.runtime.calibration_live.LiveCalibration`)
sees an operator only through :class:`BoardOperator`. A real site has none (None):
its people do what the wizard's pages say. A simulated site has one, the
simulated operator of its ``site`` node (:mod:`optrack.sim.operator`), reached
over the bus by :class:`SiteOperator`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Protocol

from optrack.calibration.board import Checkerboard
from optrack.calibration.live import LiveCalibrationError
from optrack.errors import UserError
from optrack.net.bus import Bus
from optrack.net.messages import StatusMessage
from optrack.runtime.node import send_command

__all__ = ["OPERATOR_ACTION", "BoardOperator", "SiteOperator"]

#: What the simulated operator does in each phase (optrack.sim.operator).
OPERATOR_ACTION = {
    "intrinsics": "show_board",
    "extrinsics": "move_board",
    "floor": "lay_board",
    "refinement": "walk",
}


class BoardOperator(Protocol):
    """Whoever does on site what a calibration phase needs (show the board to one sensor,
    move it between the sensors, lay it on the floor, walk through every view)."""

    def act(self, phase: str, board: Checkerboard, sensor: str | None, hold_s: float = 0.0) -> str:
        """Start doing what ``phase`` needs with ``board`` (``sensor``: the one the
        intrinsics are for; ``hold_s``: how long to hold the board still at each place,
        0 for the operator's own habit); returns a sentence saying so. A UserError
        sentence when it cannot."""
        ...

    def finished(self) -> bool:
        """Whether it has made every placement of what it was asked (it then stands with
        the board; asked again, it goes round again)."""
        ...

    def wait(self) -> None:
        """Return once the detector nodes see what :meth:`act` set up; a UserError
        sentence when they do not."""
        ...

    def doing(self) -> str:
        """What the operator does now ("" when it cannot tell)."""
        ...

    def release(self) -> None:
        """The calibration is over: the site goes back to what it did before."""
        ...


class SiteOperator:
    """The simulated operator of a site's ``site`` node, over the bus (``operator``
    command; the site status says what it does, ``values.operator``, and what went wrong
    preparing a scene, ``operator.error``; a detector node's status names the scene its
    sensor reads, ``sensor``).

    ``sensors``: the detector nodes it moves; ``status``: the newest status of a node
    (None before any); ``timeout_s``: how long a command may take; ``wait_s``: how long
    the nodes may take to come back on a scene.
    """

    def __init__(
        self,
        bus: Bus,
        sensors: list[str],
        status: Callable[[str], StatusMessage | None],
        timeout_s: float,
        wait_s: float,
    ) -> None:
        self.bus = bus
        self.sensors = list(sensors)
        self.status = status
        self.timeout_s = timeout_s
        self.wait_s = wait_s
        self.scene = ""
        self.acted = False

    @classmethod
    def find(
        cls,
        bus: Bus,
        sensors: list[str],
        status: Callable[[str], StatusMessage | None],
        timeout_s: float,
        wait_s: float,
    ) -> SiteOperator | None:
        """The site's simulated operator, or None when its ``site`` node has none."""
        try:
            send_command(bus, "site", "operator", {"action": "status"}, timeout_s)
        except UserError:
            return None
        return cls(bus, sensors, status, timeout_s, wait_s)

    def act(self, phase: str, board: Checkerboard, sensor: str | None, hold_s: float = 0.0) -> str:
        action = OPERATOR_ACTION[phase]
        reply = send_command(
            self.bus,
            "site",
            "operator",
            {
                "action": action,
                "cols": board.cols,
                "rows": board.rows,
                "square": board.square,
                "pairs": phase == "extrinsics",
                "sensor": sensor or "",
                "hold": float(hold_s),
            },
            self.timeout_s,
        )
        self.acted = True
        self.scene = str(reply.get("scene", ""))
        return f"The simulated operator gets ready ({action.replace('_', ' ')})."

    def wait(self) -> None:
        deadline = time.monotonic() + self.wait_s
        while True:
            ready = [
                sid
                for sid in self.sensors
                if (st := self.status(sid)) is not None
                and self.scene in st.sensor
                and st.state == "running"
            ]
            if len(ready) == len(self.sensors):
                return
            site = self.status("site")
            if site is not None and site.values.get("operator.scene") == self.scene:
                error = str(site.values.get("operator.error", ""))
                if error:
                    raise LiveCalibrationError(error)
            if time.monotonic() > deadline:
                missing = sorted(set(self.sensors) - set(ready))
                raise LiveCalibrationError(
                    f"the detector nodes {', '.join(missing)} did not come back on the simulated "
                    f"operator's scene within {self.wait_s:g} s; check the site's output "
                    "(optrack run)."
                )
            time.sleep(0.2)

    def finished(self) -> bool:
        site = self.status("site")
        if site is None or site.values.get("operator.scene") != self.scene:
            return False
        until = str(site.values.get("operator.until", ""))
        return bool(until) and time.time() > float(until)

    def doing(self) -> str:
        site = self.status("site")
        return str(site.values.get("operator", "")) if site is not None else ""

    def release(self) -> None:
        if self.acted and not self.bus.closed:
            send_command(self.bus, "site", "operator", {"action": "people"}, self.timeout_s)
