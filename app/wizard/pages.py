"""The calibration wizard's six pages.

Every page shows what ``LiveCalibration.state()`` says (the wizard polls it
and hands each snapshot to the page on screen: :meth:`WizardPage.show_state`)
and sends the operator's requests to the backend through the wizard's job
runner, off the GUI thread. What goes wrong is shown on the page as the
backend's sentence (:meth:`WizardPage.show_error`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from PySide6.QtCore import Qt, QTimer
from PySide6.QtWidgets import (
    QComboBox,
    QDoubleSpinBox,
    QFileDialog,
    QFormLayout,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QListWidget,
    QSpinBox,
    QSplitter,
    QVBoxLayout,
    QWidget,
    QWizardPage,
)

from app.wizard.jobs import ProgressPanel, action_button
from app.wizard.widgets import (
    CovisibilityGraph,
    ImageTile,
    SensorImages,
    SensorTable,
    TrajectoryPlot,
    count_level,
)
from optrack.calibration.board import Checkerboard
from optrack.errors import UserError
from optrack.types import NetworkCalibration, SensorCalibration

if TYPE_CHECKING:
    from app.wizard.wizard import CalibrationWizard
    from optrack.calibration.live import LiveState

ERROR_STYLE = "QLabel { color: #b00020; font-weight: bold; }"
MESSAGE_STYLE = "QLabel { color: #1b4f8a; }"
DONE_STYLE = "QLabel { color: #1e6b2a; }"
# The extrinsics page's 3D view looks at the cameras from this many times their spread
# (plus their height), and from no nearer than this.
FRAME_SPREADS = 3.0
FRAME_MIN_DISTANCE_M = 6.0
NO_SESSION = (
    "The wizard is not connected to a site's sensors; go back to the first page and look for "
    "them again."
)


def _rms(value: float | None) -> str:
    return "" if value is None else f"{value:.2f}"


def _matrix(pose: np.ndarray) -> tuple:
    return tuple(tuple(float(v) for v in row) for row in np.asarray(pose))


def calibrated_network(state: LiveState) -> NetworkCalibration:
    """The sensors of a live state that have a pose, as a calibration to draw."""
    return NetworkCalibration(
        sensors={
            sensor: SensorCalibration(
                world_T_camera=_matrix(live.world_T_camera), intrinsics=live.intrinsics
            )
            for sensor, live in state.sensors.items()
            if live.calibrated and live.world_T_camera is not None
        }
    )


class WizardPage(QWizardPage):
    """A page with an instruction, the backend's message, an error line and a progress bar.

    Subclasses put their widgets in :attr:`body` and override :meth:`show_state`.
    """

    def __init__(self, title: str, instruction: str) -> None:
        super().__init__()
        self.setTitle(title)
        layout = QVBoxLayout(self)
        self.instruction = QLabel(instruction)
        self.instruction.setWordWrap(True)
        layout.addWidget(self.instruction)
        self.body = QVBoxLayout()
        layout.addLayout(self.body, 1)
        self.message = QLabel("")
        self.message.setWordWrap(True)
        self.message.setStyleSheet(MESSAGE_STYLE)
        self.error = QLabel("")
        self.error.setWordWrap(True)
        self.error.setStyleSheet(ERROR_STYLE)
        self.error.setVisible(False)
        self.progress = ProgressPanel()
        layout.addWidget(self.message)
        layout.addWidget(self.error)
        layout.addWidget(self.progress)
        self.busy = False

    @property
    def calibration_wizard(self) -> CalibrationWizard:
        return self.wizard()  # type: ignore[return-value]

    # ------------------------------------------------------------ feedback
    def show_state(self, state: LiveState) -> None:
        """Draw a snapshot of the live calibration (called ~5 times a second)."""
        self.message.setText(state.message)

    def show_error(self, sentence: str) -> None:
        self.error.setText(sentence)
        self.error.setVisible(bool(sentence))

    capturing: Any = False

    def start_phase(self, phase: str, title: str) -> None:
        """Ask the site to capture for ``phase`` (on the worker); ``capturing`` says so."""
        live = self.calibration_wizard.live
        self.capturing = True
        self.run(
            title,
            lambda progress: live.start(phase),
            failed=lambda _: setattr(self, "capturing", False),
        )

    def stop_capture(self) -> None:
        if self.capturing:
            live = self.calibration_wizard.live
            self.capturing = False
            self.run("Stopping the capture", lambda progress: live.stop())

    def run(
        self,
        title: str,
        call: Callable[[Any], Any],
        done: Callable[[Any], None] | None = None,
        sentence: str = "",
        failed: Callable[[str], None] | None = None,
    ) -> None:
        """Run ``call(progress)`` on the wizard's worker; the progress bar shows ``sentence``
        until it ends; its error sentence is shown on the page."""
        if self.calibration_wizard.live is None:
            self.show_error(NO_SESSION)
            if failed is not None:
                failed(NO_SESSION)
            return
        self.show_error("")
        self.set_busy(True)
        if sentence:
            self.progress.begin(sentence)

        def finished(result: Any) -> None:
            self.progress.end()
            self.set_busy(False)
            if done is not None:
                done(result)

        def refused(text: str) -> None:
            self.progress.end()
            self.set_busy(False)
            self.show_error(text)
            if failed is not None:
                failed(text)

        self.calibration_wizard.runner.submit(
            title, call, finished, refused, self.progress.update_progress
        )

    def set_busy(self, busy: bool) -> None:
        self.busy = busy
        self.update_buttons()
        self.completeChanged.emit()

    def update_buttons(self) -> None:
        """Enable the page's buttons for what can be done now."""


# ---------------------------------------------------------------- 1. network


class NetworkPage(WizardPage):
    """The site's sensors and the checkerboard (inner corners, square size); print a board."""

    def __init__(self) -> None:
        super().__init__(
            "1. Network and checkerboard",
            "These are the sensors of the site. Give the checkerboard you will use: its inner "
            "corners (a 9x6 board has 10x7 squares; use one odd and one even count) and the side "
            "of one square. No board yet? Print one at 100 % and glue it flat.",
        )
        row = QHBoxLayout()
        sensors_box = QGroupBox("Sensors")
        sensors_layout = QVBoxLayout(sensors_box)
        self.sensor_list = QListWidget()
        self.sensor_list.setSelectionMode(QListWidget.SelectionMode.NoSelection)
        self.sensors_note = QLabel("Looking for the site's sensors…")
        self.sensors_note.setWordWrap(True)
        self.retry = action_button("Look again", "Ask the site again which sensors it has.")
        self.retry.clicked.connect(lambda: self.calibration_wizard.connect_site())
        sensors_layout.addWidget(self.sensor_list)
        sensors_layout.addWidget(self.sensors_note)
        sensors_layout.addWidget(self.retry)
        board_box = QGroupBox("Checkerboard")
        form = QFormLayout(board_box)
        self.cols = QSpinBox()
        self.cols.setRange(2, 40)
        self.cols.setToolTip("Inner corners along a row of the board.")
        self.rows = QSpinBox()
        self.rows.setRange(2, 40)
        self.rows.setToolTip("Inner corners along a column of the board.")
        self.square = QDoubleSpinBox()
        self.square.setRange(5.0, 500.0)
        self.square.setDecimals(1)
        self.square.setSuffix(" mm")
        self.square.setToolTip("Side of one square as printed; measure it on the board.")
        form.addRow("Inner corners across", self.cols)
        form.addRow("Inner corners down", self.rows)
        form.addRow("Square size", self.square)
        self.print_button = action_button(
            "Print a board…", "Write this board as a PDF (exact size) or PNG page to print."
        )
        self.print_button.clicked.connect(self._ask_print)
        form.addRow(self.print_button)
        self.printed = QLabel("")
        self.printed.setWordWrap(True)
        self.printed.setStyleSheet(DONE_STYLE)
        form.addRow(self.printed)
        self.pattern = ImageTile("")
        self.pattern.setMinimumSize(260, 200)
        form.addRow(self.pattern)
        for box in (self.cols, self.rows, self.square):
            box.valueChanged.connect(self._show_pattern)
        row.addWidget(sensors_box, 2)
        row.addWidget(board_box, 3)
        self.body.addLayout(row)
        self.sensors: list[str] = []

    def set_board(self, board: Checkerboard) -> None:
        self.cols.setValue(board.cols)
        self.rows.setValue(board.rows)
        self.square.setValue(board.square * 1000.0)
        self._show_pattern()

    def _show_pattern(self) -> None:
        """The board as it will be printed (the dark square before the first corner)."""
        from optrack.calibration.printable import board_image

        cols, rows = self.cols.value(), self.rows.value()
        board = Checkerboard(cols, rows, self.square.value() / 1000.0)
        usable = not board.symmetric
        self.pattern.set_view(
            board_image(board, px_per_square=24),
            usable,
            caption=f"{board.describe()}"
            + ("" if usable else ": looks the same after a half turn, not usable"),
        )

    def show_state(self, state: LiveState) -> None:
        """Nothing of the live state belongs on this page (no capture runs yet)."""

    def board(self) -> Checkerboard:
        """The board the fields describe (a BoardError sentence when it cannot be used)."""
        board = Checkerboard(self.cols.value(), self.rows.value(), self.square.value() / 1000.0)
        board.require_asymmetric()
        return board

    def set_sensors(self, sensors: list[str], simulated: bool) -> None:
        self.sensors = list(sensors)
        self.sensor_list.clear()
        self.sensor_list.addItems(self.sensors)
        where = " (a simulated site: its operator moves the board for you)" if simulated else ""
        self.sensors_note.setText(f"{len(self.sensors)} sensors found{where}.")
        self.completeChanged.emit()

    def set_looking(self, looking: bool, problem: str = "") -> None:
        if looking:
            self.sensors_note.setText("Looking for the site's sensors…")
        elif problem:
            self.sensors_note.setText("No sensors.")
        self.show_error(problem)
        self.retry.setEnabled(not looking)
        self.set_busy(looking)

    def print_board(self, path: str) -> bool:
        """Write the board to ``path`` (.pdf or .png); say where, or why not."""
        from optrack.calibration.printable import save_printable_board

        try:
            board = self.board()
            width, height = save_printable_board(path, board)
        except UserError as error:
            self.show_error(str(error))
            return False
        self.show_error("")
        self.printed.setText(
            f"Wrote {path} ({width:.0f} x {height:.0f} mm page): print it at 100 %, check the "
            "100 mm bar."
        )
        return True

    def _ask_print(self) -> None:
        path, _ = QFileDialog.getSaveFileName(
            self, "Save a printable board", "board.pdf", "PDF (*.pdf);;PNG image (*.png)"
        )
        if path:
            self.print_board(path)

    def isComplete(self) -> bool:  # noqa: N802 - Qt
        return bool(self.sensors) and not self.busy

    def validatePage(self) -> bool:  # noqa: N802 - Qt
        try:
            board = self.board()
        except UserError as error:
            self.show_error(str(error))
            return False
        self.show_error("")
        return self.calibration_wizard.use_board(board)


# ------------------------------------------------------------- 2. intrinsics


class IntrinsicsPage(WizardPage):
    """Optional: calibrate one sensor's lens from views of the board all over its image."""

    def __init__(self) -> None:
        super().__init__(
            "2. Intrinsics (optional)",
            "Only for a sensor whose own intrinsics are poor. Pick it, start the capture and "
            "show the board all over its image, near and far, tilted: the green cells fill where "
            "corners were seen. Then calibrate. Next without calibrating keeps the sensors' own "
            "intrinsics.",
        )
        row = QHBoxLayout()
        self.sensor = QComboBox()
        self.sensor.setMinimumContentsLength(12)
        self.start_button = action_button("Start capture", "Look for the board in this sensor.")
        self.stop_button = action_button("Stop")
        self.calibrate_button = action_button(
            "Calibrate intrinsics", "Solve this sensor's lens from the views captured."
        )
        row.addWidget(QLabel("Sensor"))
        row.addWidget(self.sensor)
        row.addWidget(self.start_button)
        row.addWidget(self.stop_button)
        row.addWidget(self.calibrate_button)
        row.addStretch(1)
        self.body.addLayout(row)
        split = QHBoxLayout()
        self.tile = ImageTile("")
        self.tile.setMinimumSize(360, 280)
        split.addWidget(self.tile, 3)
        right = QVBoxLayout()
        self.views = QLabel("")
        self.views.setWordWrap(True)
        self.table = SensorTable(
            [("sensor", "sensor"), ("views", "views"), ("intrinsics", "intrinsics")]
        )
        right.addWidget(self.views)
        right.addWidget(self.table, 1)
        split.addLayout(right, 2)
        self.body.addLayout(split, 1)
        self.start_button.clicked.connect(self.start_capture)
        self.stop_button.clicked.connect(self.stop_capture)
        self.calibrate_button.clicked.connect(self.calibrate)
        self.sensor.currentTextChanged.connect(lambda _: self.update_buttons())
        self.capturing: str | None = None
        self.results: dict[str, Any] = {}
        self.views_seen: dict[str, int] = {}

    def initializePage(self) -> None:  # noqa: N802 - Qt
        sensors = self.calibration_wizard.sensors
        if [self.sensor.itemText(i) for i in range(self.sensor.count())] != sensors:
            self.sensor.clear()
            self.sensor.addItems(sensors)
        self._rows()
        self.update_buttons()

    def cleanupPage(self) -> None:  # noqa: N802 - Qt
        self.stop_capture()

    def validatePage(self) -> bool:  # noqa: N802 - Qt
        self.stop_capture()
        return True

    def start_capture(self) -> None:
        sensor = self.sensor.currentText()
        if not sensor:
            return
        live = self.calibration_wizard.live
        self.capturing = sensor
        self.tile.sensor = sensor
        self.run(
            "Starting the intrinsics capture",
            lambda progress: live.start("intrinsics", sensor),
            failed=lambda _: self._stopped(),
        )

    def _stopped(self) -> None:
        self.capturing = None
        self.update_buttons()

    def stop_capture(self) -> None:
        if self.capturing is None:
            return
        live = self.calibration_wizard.live
        self.capturing = None
        self.run("Stopping the capture", lambda progress: live.stop())

    def calibrate(self) -> None:
        sensor = self.sensor.currentText()
        live = self.calibration_wizard.live
        self.stop_capture()
        self.run(
            f"Calibrating the intrinsics of {sensor}",
            lambda progress: live.calibrate_intrinsics(sensor, progress),
            lambda result: self._calibrated(sensor, result),
            sentence=f"Calibrating the intrinsics of {sensor}…",
        )

    def _calibrated(self, sensor: str, result: Any) -> None:
        self.results[sensor] = result
        k = result.intrinsics
        self.views.setText(
            f"{sensor}: fx {k.fx:.1f}, fy {k.fy:.1f}, cx {k.cx:.1f}, cy {k.cy:.1f} px; "
            f"RMS {result.rms:.2f} px over {len(result.used)} views "
            f"({len(result.rejected)} rejected)."
        )
        self._rows()

    def _rows(self) -> None:
        rows = {}
        for sensor in self.calibration_wizard.sensors:
            result = self.results.get(sensor)
            rows[sensor] = {
                "views": str(self.views_seen.get(sensor, "")),
                "intrinsics": "the sensor's own"
                if result is None
                else f"calibrated, RMS {result.rms:.2f} px",
            }
        fair, good = self.calibration_wizard.view_thresholds("intrinsics")
        levels = {s: count_level(self.views_seen.get(s, 0), fair, good) for s in rows}
        self.table.set_rows(rows, levels)

    def show_state(self, state: LiveState) -> None:
        super().show_state(state)
        sensor = self.capturing or self.sensor.currentText()
        live = state.sensors.get(sensor)
        if state.phase == "intrinsics" and live is not None:
            self.views_seen[sensor] = live.views
            self.tile.set_view(
                live.image,
                live.board_seen,
                live.coverage,
                caption=f"{sensor}: {live.views} views",
            )
            self._rows()

    def update_buttons(self) -> None:
        idle = not self.busy
        self.start_button.setEnabled(idle and self.capturing is None and self.sensor.count() > 0)
        self.stop_button.setEnabled(idle and self.capturing is not None)
        self.calibrate_button.setEnabled(idle and self.sensor.count() > 0)
        self.sensor.setEnabled(idle and self.capturing is None)

    def isComplete(self) -> bool:  # noqa: N802 - Qt
        return not self.busy


# ------------------------------------------------------------- 3. extrinsics


class ExtrinsicsPage(WizardPage):
    """Move the board through the room until every sensor is calibrated."""

    def __init__(self, world_view: bool) -> None:
        super().__init__(
            "3. Extrinsics: move the checkerboard",
            "Walk the board through the room. Hold it still wherever two sensors see it at "
            "once (both images show it with coloured corners). A sensor turns green in the "
            "graph when it is calibrated; keep going until every count is green.",
        )
        splitter = QSplitter(Qt.Orientation.Vertical)
        self.images = SensorImages(columns=3)
        splitter.addWidget(self.images)
        lower = QWidget()
        row = QHBoxLayout(lower)
        row.setContentsMargins(0, 0, 0, 0)
        self.table = SensorTable(
            [
                ("sensor", "sensor"),
                ("views", "views"),
                ("rms", "RMS (px)"),
                ("capture", "searches/s"),
                ("status", "status"),
            ]
        )
        self.table.setMinimumWidth(300)
        self.table.horizontalHeaderItem(3).setToolTip(
            "How often the sensor's node searches its image for the board (a few per second "
            "are needed; a slow node gives few views)."
        )
        self.graph = CovisibilityGraph()
        row.addWidget(self.table, 3)
        row.addWidget(self.graph, 2)
        self.world = None
        if world_view:
            from app.widgets.world_view import WorldView

            self.world = WorldView(floor_size_m=8.0)
            self.world.setMinimumSize(260, 200)
            row.addWidget(self.world, 3)
        splitter.addWidget(lower)
        splitter.setStretchFactor(0, 3)
        splitter.setStretchFactor(1, 2)
        splitter.setSizes([380, 280])
        self.body.addWidget(splitter, 1)
        self.rms = QLabel("")
        self.body.addWidget(self.rms)
        self.restart_button = action_button(
            "Start over", "Forget this phase's views and capture again."
        )
        self.restart_button.clicked.connect(self.start_capture)
        self.body.addWidget(self.restart_button, 0, Qt.AlignmentFlag.AlignLeft)
        self.all_calibrated = False
        self.capturing = False
        self._drawn: dict[str, tuple] = {}
        self.last_state: LiveState | None = None

    def initializePage(self) -> None:  # noqa: N802 - Qt
        self.images.set_sensors(self.calibration_wizard.sensors)
        self.all_calibrated = False
        self.start_capture()

    def start_capture(self) -> None:
        self.all_calibrated = False
        self.completeChanged.emit()
        self.start_phase("extrinsics", "Starting the board capture")

    def cleanupPage(self) -> None:  # noqa: N802 - Qt
        self.stop_capture()

    def validatePage(self) -> bool:  # noqa: N802 - Qt
        self.stop_capture()
        return True

    def show_state(self, state: LiveState) -> None:
        super().show_state(state)
        if state.phase != "extrinsics":
            return
        self.last_state = state
        wizard = self.calibration_wizard
        fair, good = wizard.view_thresholds("extrinsics")
        rows, levels = {}, {}
        for sensor in wizard.sensors:
            live = state.sensors.get(sensor)
            if live is None:
                rows[sensor] = {"status": "no views from its node"}
                levels[sensor] = "red"
                continue
            status = "calibrated" if live.calibrated else "not yet"
            if live.calibrated and live.parent:
                status += f" (via {live.parent})"
            rows[sensor] = {
                "views": str(live.views),
                "rms": _rms(live.rms_px),
                "capture": f"{live.capture_hz:.1f}",
                "status": status,
            }
            levels[sensor] = count_level(live.views, fair, good)
            self.images.set_view(
                sensor,
                live.image,
                live.board_seen,
                caption=f"{sensor}: {live.views} views" + (" ✓" if live.calibrated else ""),
            )
        self.table.set_rows(rows, levels)
        calibrated = {s for s, live in state.sensors.items() if live.calibrated}
        self.graph.set_graph(wizard.sensors, calibrated, state.covisibility, (fair, good))
        rms = [live.rms_px for live in state.sensors.values() if live.rms_px is not None]
        self.rms.setText(
            f"Reprojection RMS: {max(rms):.2f} px at worst, {np.mean(rms):.2f} px on average "
            f"({len(calibrated)} of {len(wizard.sensors)} sensors calibrated)."
            if rms
            else f"{len(calibrated)} of {len(wizard.sensors)} sensors calibrated."
        )
        if self.world is not None:
            drawn = {
                s: live.world_T_camera.round(3).tobytes()
                for s, live in state.sensors.items()
                if live.calibrated and live.world_T_camera is not None
            }
            if drawn != self._drawn:
                newcomers = set(drawn) != set(self._drawn)
                self._drawn = drawn
                network = calibrated_network(state)
                self.world.set_calibration(network, wizard.view_params.frustum_depth)
                if newcomers and network.sensors:
                    self._frame_cameras(network)  # a camera joined: keep them all in view
        everything = bool(wizard.sensors) and set(wizard.sensors) <= calibrated
        if everything != self.all_calibrated:
            self.all_calibrated = everything
            self.completeChanged.emit()

    def _frame_cameras(self, network: NetworkCalibration) -> None:
        """Look at the floor under the calibrated cameras, from far enough to see them all."""
        from PySide6.QtGui import QVector3D

        centres = np.array([sensor.pose[:3, 3] for sensor in network.sensors.values()])
        middle = centres.mean(axis=0)
        spread = float(np.linalg.norm(centres - middle, axis=1).max())
        self.world.setCameraPosition(
            pos=QVector3D(float(middle[0]), float(middle[1]), 0.0),
            distance=max(FRAME_MIN_DISTANCE_M, FRAME_SPREADS * spread + float(middle[2])),
        )

    def update_buttons(self) -> None:
        self.restart_button.setEnabled(not self.busy)

    def isComplete(self) -> bool:  # noqa: N802 - Qt
        return self.all_calibrated and not self.busy


# ------------------------------------------------------------------ 4. floor


class FloorPage(WizardPage):
    """Lay the board on the floor (one or several places), then solve everything."""

    def __init__(self) -> None:
        super().__init__(
            "4. Ground: lay the board on the floor",
            "Lay the board flat on the floor where the most sensors see it, printed face up, "
            "and press Capture; step out of the way. Several places (press Capture again for "
            "each) make the floor more exact. Then Solve: it adjusts every camera to all views.",
        )
        row = QHBoxLayout()
        self.capture_button = action_button(
            "Capture a floor place", "Capture the board lying at its current place on the floor."
        )
        self.stop_button = action_button("Stop")
        self.solve_button = action_button(
            "Solve", "Bundle adjustment over every view and floor board; the world on the floor."
        )
        for button in (self.capture_button, self.stop_button, self.solve_button):
            row.addWidget(button)
        row.addStretch(1)
        self.body.addLayout(row)
        self.images = SensorImages(columns=3)
        self.body.addWidget(self.images, 1)
        self.floor_views = QLabel("Floor views: 0")
        self.solved = QLabel("")
        self.solved.setWordWrap(True)
        self.solved.setStyleSheet(DONE_STYLE)
        self.body.addWidget(self.floor_views)
        self.body.addWidget(self.solved)
        self.capture_button.clicked.connect(self.capture_place)
        self.stop_button.clicked.connect(self.stop_capture)
        self.solve_button.clicked.connect(self.solve)
        self.capturing = False
        self.floor_count = 0

    def initializePage(self) -> None:  # noqa: N802 - Qt
        self.images.set_sensors(self.calibration_wizard.sensors)
        self.update_buttons()

    def cleanupPage(self) -> None:  # noqa: N802 - Qt
        self.stop_capture()

    def capture_place(self) -> None:
        self.start_phase("floor", "Starting the floor capture")

    def solve(self) -> None:
        live = self.calibration_wizard.live
        self.stop_capture()
        self.run(
            "Solving the network",
            lambda progress: live.solve(progress),
            self._solved,
            sentence="Adjusting every camera to all views…",
        )

    def _solved(self, calibration: NetworkCalibration) -> None:
        self.calibration_wizard.set_calibration(calibration, refined=False)
        rms = [s.reprojection_rms_px for s in calibration.sensors.values()]
        rms = [r for r in rms if r is not None]
        worst = f"; reprojection RMS {max(rms):.2f} px at worst" if rms else ""
        world = (
            "the world's origin is on the floor"
            if self.floor_count
            else "no board lay on the floor: the world is the first camera's frame"
        )
        self.solved.setText(f"Solved {len(calibration.sensors)} cameras{worst}; {world}.")
        self.completeChanged.emit()

    def show_state(self, state: LiveState) -> None:
        super().show_state(state)
        self.floor_count = state.floor_views
        operator = f" ({state.operator})" if state.operator else ""
        self.floor_views.setText(f"Floor views: {state.floor_views}{operator}")
        if state.phase != "floor":
            return
        for sensor in self.calibration_wizard.sensors:
            live = state.sensors.get(sensor)
            if live is not None:
                on_floor = ", on the floor" if live.on_floor else ""
                self.images.set_view(
                    sensor,
                    live.image,
                    live.board_seen,
                    caption=f"{sensor}{on_floor}",
                )

    def update_buttons(self) -> None:
        idle = not self.busy
        self.capture_button.setEnabled(idle)
        self.stop_button.setEnabled(idle and self.capturing)
        self.solve_button.setEnabled(idle)

    def isComplete(self) -> bool:  # noqa: N802 - Qt
        return not self.busy and self.calibration_wizard.solved is not None


# ------------------------------------------------------------- 5. refinement


class RefinementPage(WizardPage):
    """Optional: one person walks alone; each sensor's view of them aligns the cameras."""

    def __init__(self, duration_s: float) -> None:
        super().__init__(
            "5. Refinement (optional): one person walks",
            "Ask one person to walk alone through every sensor's view for the time below, "
            "everyone else out of the room. The sensors' trajectories of that person are then "
            "aligned. Next without walking keeps the checkerboard's calibration.",
        )
        row = QHBoxLayout()
        self.duration = QSpinBox()
        self.duration.setRange(10, 600)
        self.duration.setSuffix(" s")
        self.duration.setValue(round(duration_s))
        self.duration.setToolTip("How long the person walks.")
        self.walk_button = action_button("Start walking", "Collect the walker's detections.")
        self.refine_button = action_button(
            "Refine now", "Stop collecting and align the sensors' trajectories."
        )
        row.addWidget(QLabel("Walk for"))
        row.addWidget(self.duration)
        row.addWidget(self.walk_button)
        row.addWidget(self.refine_button)
        self.countdown = QLabel("")
        row.addWidget(self.countdown)
        row.addStretch(1)
        self.body.addLayout(row)
        plots = QHBoxLayout()
        self.before = TrajectoryPlot("Before")
        self.after = TrajectoryPlot("After")
        plots.addWidget(self.before)
        plots.addWidget(self.after)
        self.body.addLayout(plots, 1)
        self.samples = QLabel("")
        self.samples.setWordWrap(True)
        self.figure = QLabel("")
        self.figure.setWordWrap(True)
        self.figure.setStyleSheet(DONE_STYLE)
        self.body.addWidget(self.samples)
        self.body.addWidget(self.figure)
        self.walk_button.clicked.connect(self.start_walk)
        self.refine_button.clicked.connect(self.refine)
        self.timer = QTimer(self)
        self.timer.setInterval(250)
        self.timer.timeout.connect(self._tick)
        self.walking = False
        self.ends_at = 0.0
        self.report: Any = None

    def cleanupPage(self) -> None:  # noqa: N802 - Qt
        self._stop_walk()

    def validatePage(self) -> bool:  # noqa: N802 - Qt
        self._stop_walk()
        return True

    def start_walk(self) -> None:
        from time import monotonic

        live = self.calibration_wizard.live
        self.walking = True
        self.ends_at = monotonic() + self.duration.value()
        self.timer.start()
        self._tick()
        self.run(
            "Starting the walk",
            lambda progress: live.start("refinement"),
            failed=lambda _: self._stop_walk(send=False),
        )

    def _tick(self) -> None:
        from time import monotonic

        left = self.ends_at - monotonic()
        if left <= 0:
            self.timer.stop()
            self.countdown.setText("")
            if self.walking:
                self.refine()
            return
        self.countdown.setText(f"{math.ceil(left)} s left")

    def _stop_walk(self, send: bool = True) -> None:
        self.timer.stop()
        self.countdown.setText("")
        if self.walking:
            self.walking = False
            if send:
                live = self.calibration_wizard.live
                self.run("Stopping the walk", lambda progress: live.stop())
        self.update_buttons()

    def refine(self) -> None:
        live = self.calibration_wizard.live
        self._stop_walk()
        self.run(
            "Refining from the walk",
            lambda progress: live.refine(progress),
            self._refined,
            sentence="Aligning the sensors' trajectories…",
        )

    def _refined(self, report: Any) -> None:
        self.report = report
        self.before.set_trajectories(report.trajectories_before)
        self.after.set_trajectories(report.trajectories_after)
        refused, board = report.refused, report.board_rms_px
        self.figure.setText(
            f"The sensors disagree on where the person was by "
            f"{100 * report.error_before_m:.1f} cm on average before refinement and "
            f"{100 * report.error_after_m:.1f} cm after."
            + (
                f" Not refined (too few detections): {', '.join(report.skipped)}."
                if report.skipped
                else ""
            )
            + (
                " Kept the checkerboard's pose for "
                + ", ".join(
                    f"{s} (the walk's correction puts its board views {rms:.1f} px off, "
                    f"against {board.get(s, math.nan):.1f} px)"
                    for s, rms in sorted(refused.items())
                )
                + ": the board is the more exact there."
                if refused
                else ""
            )
        )
        self.calibration_wizard.set_calibration(report.calibration, refined=True)

    def show_state(self, state: LiveState) -> None:
        super().show_state(state)
        if state.refinement_samples:
            counts = ", ".join(f"{s} {n}" for s, n in sorted(state.refinement_samples.items()))
            self.samples.setText(f"Detections of the walker: {counts}.")

    def update_buttons(self) -> None:
        idle = not self.busy
        self.walk_button.setEnabled(idle and not self.walking)
        self.refine_button.setEnabled(idle)
        self.duration.setEnabled(not self.walking)

    def isComplete(self) -> bool:  # noqa: N802 - Qt
        return not self.busy


# ----------------------------------------------------------------- 6. review

EXPORTS = {
    "openptrack": ("OpenPTrack camera_poses.yaml", "camera_poses.yaml"),
    "ros": ("ROS static transforms", "static_transforms.yaml"),
}


class ReviewPage(WizardPage):
    """Per-sensor quality; save, export and send the calibration to the nodes."""

    def __init__(self) -> None:
        super().__init__(
            "6. Review, save and send",
            "Check each sensor's figures. Save the calibration (the previous file is kept as "
            ".bak), export it for other tools if you need to, and send it to the nodes: they "
            "use it from their next frame.",
        )
        self.table = SensorTable(
            [
                ("sensor", "sensor"),
                ("views", "views"),
                ("rms", "RMS (px)"),
                ("refinement", "refinement moved it"),
                ("height", "height (m)"),
            ]
        )
        self.body.addWidget(self.table, 1)
        self.summary = QLabel("")
        self.summary.setWordWrap(True)
        self.body.addWidget(self.summary)
        row = QHBoxLayout()
        self.save_button = action_button("Save…", "Write the calibration file.")
        self.export_choice = QComboBox()
        for key, (title, _) in EXPORTS.items():
            self.export_choice.addItem(title, key)
        self.export_button = action_button("Export…", "Write the calibration for another tool.")
        self.publish_button = action_button(
            "Send to the nodes", "Every node stores the calibration and uses it."
        )
        row.addWidget(self.save_button)
        row.addSpacing(16)
        row.addWidget(self.export_choice)
        row.addWidget(self.export_button)
        row.addSpacing(16)
        row.addWidget(self.publish_button)
        row.addStretch(1)
        self.body.addLayout(row)
        self.done = QLabel("")
        self.done.setWordWrap(True)
        self.done.setStyleSheet(DONE_STYLE)
        self.body.addWidget(self.done)
        self.save_button.clicked.connect(self._ask_save)
        self.export_button.clicked.connect(self._ask_export)
        self.publish_button.clicked.connect(self.publish)
        self.saved: Path | None = None
        self.published = False
        self.outcomes: list[str] = []
        self.file: Any = None  # the CalibrationFile shown

    def initializePage(self) -> None:  # noqa: N802 - Qt
        wizard = self.calibration_wizard
        self.outcomes = []
        self.done.setText("")
        self.file = None
        if wizard.calibration is None:
            self.summary.setText("Nothing solved yet: go back to the ground page and Solve.")
            self.update_buttons()
            return
        live = wizard.live
        self.run(
            "Reading the calibration",
            lambda progress: live.calibration_file(),
            self.show_file,
        )

    def show_file(self, calibration: Any) -> None:
        """Per-sensor quality of the calibration as it will be saved (a CalibrationFile)."""
        from optrack.geometry import rotation_angle_deg

        self.file = calibration
        fair, good = self.calibration_wizard.view_thresholds("extrinsics")
        rows, levels = {}, {}
        refused = str(calibration.quality.get("refinement_refused") or "").split(",")
        for sensor in sorted(calibration.sensors):
            entry = calibration.sensors[sensor]
            row = {
                "views": str(entry.views),
                "rms": _rms(entry.reprojection_rms_px),
                "height": f"{entry.pose[2, 3]:.2f}",
                "refinement": "kept the board's pose" if sensor in refused else "not refined",
            }
            if entry.refinement is not None:
                delta = np.asarray(entry.refinement, dtype=float)
                row["refinement"] = (
                    f"{100 * np.linalg.norm(delta[:3, 3]):.1f} cm, "
                    f"{rotation_angle_deg(delta, np.eye(4)):.2f}°"
                )
            rows[sensor] = row
            levels[sensor] = count_level(entry.views, fair, good)
        self.table.set_rows(rows, levels)
        quality = calibration.quality
        parts = [f"{len(calibration.sensors)} sensors calibrated"]
        if quality.get("reprojection_rms_px") is not None:
            parts.append(f"reprojection RMS {float(quality['reprojection_rms_px']):.2f} px")
        parts.append(
            f"{quality.get('floor_views', 0)} floor views: the world's origin is on the floor"
            if calibration.world == "floor"
            else f"no floor: the world is the frame of {calibration.world}"
        )
        if "refinement_error_after_m" in quality:
            parts.append(
                "refined from a walk: the sensors agree within "
                f"{100 * float(quality['refinement_error_after_m']):.1f} cm "
                f"({100 * float(quality['refinement_error_before_m']):.1f} cm before)"
            )
            if quality.get("refinement_refused"):
                parts.append(
                    f"{str(quality['refinement_refused']).replace(',', ', ')} kept the "
                    "checkerboard's pose (the walk's correction contradicted its board views)"
                )
        else:
            parts.append("not refined")
        self.summary.setText("; ".join(parts) + ".")
        self.update_buttons()

    def _say(self, sentence: str) -> None:
        self.outcomes.append(sentence)
        self.done.setText(" ".join(self.outcomes))

    def save_to(self, path: str) -> None:
        """Save the calibration to ``path`` (on the worker); say where, and the backup."""
        live = self.calibration_wizard.live

        def saved(written: Path) -> None:
            self.saved = Path(written)
            backup = self.saved.with_name(self.saved.name + ".bak")
            kept = f"; the previous file is kept as {backup.name}" if backup.exists() else ""
            self._say(f"Saved to {self.saved}{kept}.")
            self.update_buttons()

        self.run("Saving the calibration", lambda progress: live.save(path), saved)

    def export_to(self, kind: str, path: str) -> None:
        """Write the saved calibration for another tool (``kind`` in :data:`EXPORTS`)."""
        from optrack.calibration.files import (
            load_calibration,
            openptrack_camera_poses,
            ros_static_transforms,
        )
        from optrack.io.files import atomic_write_text

        source = self.saved

        def export(progress: Any) -> Path:
            calibration = load_calibration(source)
            text = (
                openptrack_camera_poses(calibration)
                if kind == "openptrack"
                else ros_static_transforms(calibration)
            )
            atomic_write_text(Path(path), text)
            return Path(path)

        self.run(
            "Exporting the calibration",
            export,
            lambda written: self._say(f"Exported {EXPORTS[kind][0]} to {written}."),
        )

    def publish(self) -> None:
        live = self.calibration_wizard.live

        def sent(_: Any) -> None:
            self.published = True
            self._say("Sent to the nodes.")

        self.run("Sending the calibration", lambda progress: live.publish(), sent)

    def _ask_save(self) -> None:
        path, _ = QFileDialog.getSaveFileName(
            self, "Save the calibration", "calibration.yaml", "Calibration (*.yaml *.yml)"
        )
        if path:
            self.save_to(path)

    def _ask_export(self) -> None:
        kind = self.export_choice.currentData()
        title, name = EXPORTS[kind]
        folder = self.saved.parent if self.saved is not None else Path.cwd()
        path, _ = QFileDialog.getSaveFileName(
            self, f"Export as {title}", str(folder / name), "YAML (*.yaml)"
        )
        if path:
            self.export_to(kind, path)

    def update_buttons(self) -> None:
        ready = not self.busy and self.calibration_wizard.calibration is not None
        self.save_button.setEnabled(ready)
        self.publish_button.setEnabled(ready)
        self.export_button.setEnabled(ready and self.saved is not None)
        self.export_button.setToolTip(
            "Write the calibration for another tool."
            if self.saved is not None
            else "Save the calibration first; the export is made from the saved file."
        )
