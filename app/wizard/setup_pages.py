"""The calibration wizard's first pages: the site's sensors and the checkerboard (1), and
one sensor's intrinsics (2, optional)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

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
    QVBoxLayout,
)

from app.folders import calibrations_folder, start_in
from app.wizard.jobs import action_button
from app.wizard.page import DONE_STYLE, WizardPage
from app.wizard.widgets import ImageTile, SensorTable, count_level, views_text
from optrack.calibration.board import Checkerboard
from optrack.errors import UserError

if TYPE_CHECKING:
    from optrack.calibration.intrinsics import IntrinsicsResult
    from optrack.calibration.live import LiveState

__all__ = ["IntrinsicsPage", "NetworkPage"]


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
            self,
            "Save a printable board",
            start_in(calibrations_folder(), "board.pdf"),
            "PDF (*.pdf);;PNG image (*.png)",
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
            "corners were seen, and the line below says where the board is still missing until "
            "the lens is good. Then calibrate. Next without calibrating keeps the sensors' own "
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
        self.views_seen: dict[str, int] = {}
        # the lens from the views so far, per sensor (the backend's check while capturing)
        self.lens_seen: dict[str, IntrinsicsResult] = {}

    @property
    def results(self) -> dict[str, IntrinsicsResult]:
        """The intrinsics calibrated so far, per sensor (the backend's)."""
        state = self.calibration_wizard.last_state
        return state.intrinsics_results if state is not None else {}

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
        self.lens_seen.pop(sensor, None)  # the capture starts from no views
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

    def lens_good(self, sensor: str) -> bool:
        """Whether the views captured for ``sensor`` pin its lens down (the backend's check,
        calibration_intrinsics.good_std_px)."""
        lens = self.lens_seen.get(sensor)
        return lens is not None and lens.good

    def _calibrated(self, sensor: str, result: IntrinsicsResult) -> None:
        self.calibration_wizard.poll()  # the backend's state has the result now
        k = result.intrinsics
        self.views.setText(
            f"{sensor}: fx {k.fx:.1f}, fy {k.fy:.1f}, cx {k.cx:.1f}, cy {k.cy:.1f} px; "
            f"RMS {result.rms:.2f} px over {len(result.used)} views "
            f"({len(result.rejected)} rejected). "
            + (
                result.advice(sensor)
                if result.good
                else f"Not good yet: {result.advice(sensor)} Start capture again (it starts "
                "from no views) and follow the line below, or Next uses this lens anyway."
            )
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
                else f"calibrated, {'good' if result.good else 'not good yet'} "
                f"(±{result.uncertainty_px:.2f} px), RMS {result.rms:.2f} px",
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
            lens = ""
            if live.lens is not None:
                self.lens_seen[sensor] = live.lens
                known = live.lens.uncertainty_px
                lens = (
                    ", lens good"
                    if live.lens.good
                    else f", lens known to {known:.2f} px"
                    if math.isfinite(known)
                    else ", lens not known yet"
                )
            self.tile.set_view(
                live.image,
                live.board_seen,
                live.coverage,
                caption=f"{sensor}: {views_text(live.views)}{lens}",
            )
        # Every snapshot: a result the backend has is shown at once, even when this poll
        # comes before the calibrating job's own callback.
        self._rows()

    def update_buttons(self) -> None:
        idle = not self.busy
        self.start_button.setEnabled(idle and self.capturing is None and self.sensor.count() > 0)
        self.stop_button.setEnabled(idle and self.capturing is not None)
        self.calibrate_button.setEnabled(idle and self.sensor.count() > 0)
        self.sensor.setEnabled(idle and self.capturing is None)

    def isComplete(self) -> bool:  # noqa: N802 - Qt
        return not self.busy
