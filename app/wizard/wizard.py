"""The calibration wizard: OpenPTrack's launch files and rostopic commands as six pages.

The wizard is one more client of the site's bus. It drives the calibration
code through :class:`optrack.runtime.calibration_live.LiveCalibration` and
shows what it says: a QTimer polls ``state()`` (``calibration_wizard.poll_hz``)
and hands the snapshot to the page on screen; every other backend call runs
on the wizard's worker thread (:class:`~app.wizard.jobs.JobRunner`), so the
window never freezes. The wizard keeps no calibration of its own: what was
solved and refined is the backend's, as its latest state says.

Pages: network and checkerboard, intrinsics (optional), extrinsics ("move
the checkerboard"), ground ("lay the board on the floor", then solve),
refinement (optional, "one person walks"), review (save, export, send).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from PySide6.QtCore import QPoint, QTimer, Signal
from PySide6.QtGui import QImage, QPainter
from PySide6.QtWidgets import QWidget, QWizard

from app.view_params import VIEW_PARAMS
from app.wizard.capture_pages import ExtrinsicsPage, FloorPage
from app.wizard.jobs import JobRunner
from app.wizard.page import WizardPage
from app.wizard.result_pages import RefinementPage, ReviewPage
from app.wizard.setup_pages import IntrinsicsPage, NetworkPage
from optrack.calibration.board import Checkerboard
from optrack.calibration.live import LiveState, RefinementReport
from optrack.errors import UserError
from optrack.params import Param, Schema, register
from optrack.types import NetworkCalibration

__all__ = ["WIZARD_PARAMS", "CalibrationWizard"]

WIZARD_PARAMS = register(
    Schema(
        "calibration_wizard",
        [
            Param(
                "poll_hz",
                5.0,
                min=0.5,
                max=30.0,
                unit="Hz",
                help="How often the wizard asks the live calibration for its state.",
            ),
            Param(
                "board_cols",
                6,
                min=2,
                max=40,
                step=1,
                help="Inner corners across the checkerboard page 1 starts with.",
            ),
            Param(
                "board_rows",
                5,
                min=2,
                max=40,
                step=1,
                help="Inner corners down the checkerboard page 1 starts with.",
            ),
            Param(
                "board_square",
                0.15,
                min=0.005,
                max=0.5,
                unit="m",
                help="Square side of the checkerboard page 1 starts with.",
            ),
            Param(
                "views_fair",
                5,
                min=1,
                max=1000,
                step=1,
                help="A sensor's (or pair's) view count shows yellow from this many views, "
                "red below.",
            ),
            Param(
                "views_good",
                15,
                min=1,
                max=1000,
                step=1,
                help="A sensor's (or pair's) view count shows green from this many views.",
            ),
            Param(
                "intrinsics_views_good",
                25,
                min=1,
                max=1000,
                step=1,
                help="A sensor's intrinsics view count shows green from this many views "
                "(red below calibration_intrinsics.min_views, which calibrating needs).",
            ),
            Param(
                "walk_seconds",
                60.0,
                min=10.0,
                max=600.0,
                unit="s",
                help="How long the refinement page asks one person to walk.",
            ),
            Param(
                "close_timeout_s",
                10.0,
                min=0.5,
                max=120.0,
                unit="s",
                help="Closing the wizard waits this long for the work it started to end.",
            ),
        ],
        help="The operator application's calibration wizard (not sent to nodes).",
    )
)


class CalibrationWizard(QWizard):
    """Six pages against a running site's bus.

    ``bus``: an open :class:`optrack.net.bus.Bus` of the site (the main window's);
    ``sensors``: calibrate only these (default: every detector node of the site);
    ``world_view``: draw the cameras in 3D on the extrinsics page (needs OpenGL).
    """

    #: where to hold the board next, in the site's frame (BoardSuggestion), or None
    guidance_changed = Signal(object)

    def __init__(
        self,
        bus: Any,
        parent: QWidget | None = None,
        *,
        sensors: Sequence[str] | None = None,
        world_view: bool = True,
    ) -> None:
        super().__init__(parent)
        self.setWindowTitle("Calibrate the sensors")
        self.setWizardStyle(QWizard.WizardStyle.ClassicStyle)
        self.setOption(QWizard.WizardOption.NoBackButtonOnStartPage, True)
        self.setOption(QWizard.WizardOption.HaveHelpButton, False)
        self.resize(1180, 820)
        self.bus = bus
        self.params = WIZARD_PARAMS.create()
        self.view_params = VIEW_PARAMS.create()
        self.only_sensors = list(sensors) if sensors is not None else None
        self.live: Any = None  # optrack.runtime.calibration_live.LiveCalibration once connected
        self.board = default_board()
        self.sensors: list[str] = []
        self.simulated = False
        self.last_state: LiveState | None = None  # the backend's latest snapshot
        self.runner = JobRunner(self)
        self.network_page = NetworkPage()
        self.intrinsics_page = IntrinsicsPage()
        self.extrinsics_page = ExtrinsicsPage(world_view)
        self.floor_page = FloorPage()
        self.refinement_page = RefinementPage(walk_seconds())
        self.review_page = ReviewPage()
        for page in self.pages:
            self.addPage(page)
        self.network_page.set_board(self.board)
        self.timer = QTimer(self)
        self.timer.setInterval(round(1000 / float(self.params.poll_hz)))
        self.timer.timeout.connect(self.poll)
        self._closed = False
        self.connect_site()

    @property
    def pages(self) -> list[WizardPage]:
        return [
            self.network_page,
            self.intrinsics_page,
            self.extrinsics_page,
            self.floor_page,
            self.refinement_page,
            self.review_page,
        ]

    # ------------------------------------------------------------ the site
    def connect_site(self) -> None:
        """Find the site's sensors (a LiveCalibration with the board on page 1), off the GUI
        thread: discovering them waits for their nodes' statuses."""
        if self.bus is None:
            self.network_page.set_looking(
                False,
                "No site connected: start a site (or connect the window to one) and open the "
                "wizard again.",
            )
            return
        self.network_page.set_looking(True)
        self._replace_live(self.board, then=None)

    def _replace_live(self, board: Checkerboard, then: Any) -> None:
        from optrack.runtime.calibration_live import LiveCalibration

        old, bus = self.live, self.bus
        sensors = self.only_sensors if old is None else old.sensors
        self.live = None

        def connect(progress: Any) -> Any:
            if old is not None:
                old.close()
            return LiveCalibration(bus, board, sensors=sensors)

        def connected(live: Any) -> None:
            if self._closed:
                self.runner.submit("Closing the calibration", lambda progress: live.close())
                return
            self.live = live
            self.last_state = None
            self.board = board
            self.sensors = list(live.sensors)
            self.simulated = bool(live.simulated)
            self.network_page.set_looking(False)
            self.network_page.set_sensors(self.sensors, self.simulated)
            self.timer.start()
            if then is not None:
                then()

        def failed(sentence: str) -> None:
            self.network_page.set_looking(False, sentence)

        self.runner.submit("Connecting to the site's sensors", connect, connected, failed)

    def use_board(self, board: Checkerboard) -> bool:
        """Leave page 1 with ``board``: at once when the session uses it already, else after
        the session is made again with it (returns False meanwhile; Next follows)."""
        if self.live is not None and board == self.board:
            return True
        self.network_page.set_looking(True)
        self._replace_live(board, then=self.next)
        return False

    # ------------------------------------------------- the backend's results
    @property
    def solved(self) -> NetworkCalibration | None:
        """The backend's solved calibration (None before a solve)."""
        return self.last_state.solved if self.last_state is not None else None

    @property
    def refinement(self) -> RefinementReport | None:
        """The backend's refinement of the solved calibration (None when none ran)."""
        return self.last_state.refinement if self.last_state is not None else None

    @property
    def refined(self) -> bool:
        return self.refinement is not None

    @property
    def calibration(self) -> NetworkCalibration | None:
        """The calibration the review page saves: the refined one, else the solved one."""
        return self.last_state.calibration if self.last_state is not None else None

    def view_thresholds(self, phase: str) -> tuple[int, int]:
        """(fair, good) view counts for a phase's red / yellow / green (backend schema)."""
        return view_thresholds(phase)

    # ------------------------------------------------------------ feedback
    def poll(self) -> None:
        """Take the live calibration's snapshot now (the timer does, ~5 times a second)."""
        if self.live is None:
            return
        try:
            state = self.live.state()
        except UserError as error:
            page = self.currentPage()
            if isinstance(page, WizardPage):
                page.show_error(str(error))
            return
        self.take_state(state)

    def take_state(self, state: LiveState) -> None:
        """The backend's snapshot: the wizard's view of the calibration, and the page on
        screen draws it."""
        self.last_state = state
        page = self.currentPage()
        if isinstance(page, WizardPage):
            page.show_state(state)

    def screenshot(self) -> QImage:
        """The wizard as the operator sees it: ``grab()`` leaves out what pyqtgraph paints
        over a 3D view (camera names), so the view's own framebuffer is laid over it."""
        image = self.grab().toImage()
        world = self.extrinsics_page.world
        if world is not None and world.isVisible():
            painter = QPainter(image)
            frame = world.grabFramebuffer()
            frame.setDevicePixelRatio(image.devicePixelRatio())
            painter.drawImage(world.mapTo(self, QPoint(0, 0)), frame)
            painter.end()
        return image

    # ------------------------------------------------------------- closing
    def shut_down(self) -> None:
        """Stop the capture, release the session and wait (bounded) for the worker."""
        if self._closed:
            return
        self._closed = True
        self.timer.stop()
        live = self.live
        if live is not None:
            self.runner.submit("Closing the calibration", lambda progress: live.close())
        self.runner.wait(round(1000 * float(self.params.close_timeout_s)))

    def done(self, result: int) -> None:
        self.shut_down()
        super().done(result)

    def closeEvent(self, event) -> None:  # noqa: N802 - Qt
        self.shut_down()
        super().closeEvent(event)


def default_board() -> Checkerboard:
    """The board page 1 starts with (``calibration_wizard.board_*``)."""
    p = WIZARD_PARAMS.create()
    return Checkerboard(int(p.board_cols), int(p.board_rows), float(p.board_square))


def walk_seconds() -> float:
    return float(WIZARD_PARAMS.create().walk_seconds)


def view_thresholds(phase: str) -> tuple[int, int]:
    """(fair, good) view counts of a phase: red below fair, yellow below good, green from
    good. Intrinsics: fair is the number of views calibrating a lens needs."""
    p = WIZARD_PARAMS.create()
    if phase == "intrinsics":
        from optrack.calibration.intrinsics import INTRINSICS_PARAMS

        fair = int(INTRINSICS_PARAMS.create().min_views)
        return fair, max(fair, int(p.intrinsics_views_good))
    return int(p.views_fair), int(p.views_good)
