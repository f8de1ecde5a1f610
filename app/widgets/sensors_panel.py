"""The Sensors dock: each sensor's health, and a live preview of one of them."""

from __future__ import annotations

import time
from typing import Any

from PySide6.QtCore import Qt, QTimer
from PySide6.QtGui import QColor
from PySide6.QtWidgets import (
    QComboBox,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QSplitter,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from app.source import NO_SITE, SENSOR_STATUS_KEYS
from app.widgets.preview import STREAMS, PreviewView
from optrack.types import DetectionBatch, RGBDFrame

DROPPED_TIP = (
    "Frames the sensor captured while its node was still busy with an earlier one. The "
    "node skips them and always takes the newest frame, so the tracks stay current: a "
    "climbing count only says the computer is slower than the camera (simulated sensors "
    "on a busy computer drop most of their frames). It matters when fps gets low."
)
COLUMN_TIPS = {
    "fps": "Frames per second the sensor's node processes.",
    "latency_ms": "Time from capture to detections on the bus, milliseconds.",
    "clock_offset_ms": "The sensor computer's clock minus the site's clock, milliseconds.",
    "dropped": DROPPED_TIP,
    "last_error": "The last problem the node reported.",
}
STREAM_TITLES = {"depth": "Depth", "color": "Colour", "infrared": "Infrared"}
ERROR_COLOR = QColor(200, 40, 40)
STALE_COLOR = QColor(150, 150, 150)


def _format(value: Any, fmt: str) -> str:
    if value is None or value == "":
        return ""
    try:
        text = fmt.format(value)
    except (ValueError, TypeError):
        return str(value)
    if isinstance(value, float) and not text.strip("+-0."):
        text = fmt.format(0.0)  # a tiny negative number shows as 0, not "-0.0"
    return text


class SensorsPanel(QWidget):
    """A row per sensor (from its node's status) above the preview of the chosen sensor.

    A sensor whose status stops coming for ``stale_after`` seconds is greyed out
    and says so, so a dead node cannot look healthy.
    """

    def __init__(self, stale_after: float = 3.0, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.stale_after = stale_after
        self.table = QTableWidget(0, 1 + len(SENSOR_STATUS_KEYS))
        self.table.setHorizontalHeaderLabels(["sensor"] + [t for _, t, _ in SENSOR_STATUS_KEYS])
        self.table.verticalHeader().hide()
        for column, (key, _, _) in enumerate(SENSOR_STATUS_KEYS, start=1):
            self.table.horizontalHeaderItem(column).setToolTip(COLUMN_TIPS[key])
        self._text_color = self.table.palette().text().color()
        self.table.setEditTriggers(QTableWidget.EditTrigger.NoEditTriggers)
        self.table.setSelectionBehavior(QTableWidget.SelectionBehavior.SelectRows)
        header = self.table.horizontalHeader()
        header.setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)
        header.setSectionResizeMode(len(SENSOR_STATUS_KEYS), QHeaderView.ResizeMode.Stretch)
        self.table.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAsNeeded)
        self.table.setWordWrap(False)
        self.empty = QLabel(NO_SITE)
        self.sensor_choice = QComboBox()
        self.sensor_choice.setPlaceholderText("no sensor")
        self.stream_choice = QComboBox()
        for stream in STREAMS:
            self.stream_choice.addItem(STREAM_TITLES[stream], stream)
        self.preview = PreviewView()
        controls = QHBoxLayout()
        controls.addWidget(QLabel("Preview of"))
        controls.addWidget(self.sensor_choice, 1)
        controls.addWidget(self.stream_choice)
        top = QWidget()
        top_layout = QVBoxLayout(top)
        top_layout.setContentsMargins(0, 0, 0, 0)
        top_layout.addWidget(self.empty)
        top_layout.addWidget(self.table)
        bottom = QWidget()
        bottom_layout = QVBoxLayout(bottom)
        bottom_layout.setContentsMargins(0, 0, 0, 0)
        bottom_layout.addLayout(controls)
        bottom_layout.addWidget(self.preview, 1)
        splitter = QSplitter(Qt.Orientation.Vertical)
        splitter.addWidget(top)
        splitter.addWidget(bottom)
        splitter.setStretchFactor(1, 1)
        splitter.setSizes([130, 500])
        layout = QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.addWidget(splitter)
        self._rows: dict[str, int] = {}
        self._last_status: dict[str, float] = {}
        self._frames: dict[str, tuple[RGBDFrame, DetectionBatch | None]] = {}
        self.sensor_choice.currentTextChanged.connect(self._redraw)
        self.stream_choice.currentIndexChanged.connect(self._choose_stream)
        self._stale_timer = QTimer(self)
        self._stale_timer.setInterval(1000)
        self._stale_timer.timeout.connect(self.mark_stale)
        self._stale_timer.start()

    # ----------------------------------------------------------------- status
    def _row(self, sensor_id: str) -> int:
        if sensor_id not in self._rows:
            row = self.table.rowCount()
            self.table.insertRow(row)
            self.table.setItem(row, 0, QTableWidgetItem(sensor_id))
            for column in range(1, self.table.columnCount()):
                self.table.setItem(row, column, QTableWidgetItem(""))
            self._rows[sensor_id] = row
            self.sensor_choice.addItem(sensor_id)
            if self.sensor_choice.currentIndex() < 0:
                self.sensor_choice.setCurrentIndex(0)
            self.empty.hide()
        return self._rows[sensor_id]

    def add_sensor(self, sensor_id: str) -> None:
        """List a sensor known from elsewhere (the calibration) before its status comes."""
        self._row(sensor_id)

    def set_status(self, node: str, values: dict) -> None:
        """A node's status; a detector's (named after its sensor) or one naming a ``sensor``."""
        sensor_id = node if values.get("role") == "detector" else values.get("sensor")
        if not sensor_id:
            return
        row = self._row(str(sensor_id))
        self._last_status[str(sensor_id)] = time.monotonic()
        tooltip = f"node {node}\n" + "\n".join(f"{k}: {v}" for k, v in sorted(values.items()))
        shown = dict(values)
        state = values.get("state")
        # A node that is not running yet (starting, stopped) says so in grey: not an error.
        waiting = bool(state and state != "running" and not values.get("last_error"))
        if waiting:
            shown["last_error"] = str(state)
        for column, (key, _, fmt) in enumerate(SENSOR_STATUS_KEYS, start=1):
            item = self.table.item(row, column)
            item.setText(_format(shown.get(key), fmt))
            item.setToolTip(tooltip)
            error_color = STALE_COLOR if waiting else ERROR_COLOR
            item.setForeground(error_color if key == "last_error" else self._text_color)
        if waiting:
            self._item(row, "last_error").setToolTip(
                f"The node of sensor '{sensor_id}' is {state}; no problem so far.\n{tooltip}"
            )
        dropped = values.get("dropped")
        if isinstance(dropped, int) and dropped > 0:
            self._item(row, "dropped").setToolTip(
                f"{dropped} frames skipped so far. {DROPPED_TIP}\n{tooltip}"
            )
        self.table.item(row, 0).setToolTip(tooltip)
        self.table.item(row, 0).setForeground(self._text_color)

    def _item(self, row: int, key: str) -> QTableWidgetItem:
        keys = [k for k, _, _ in SENSOR_STATUS_KEYS]
        return self.table.item(row, 1 + keys.index(key))

    def mark_stale(self) -> None:
        now = time.monotonic()
        for sensor_id, seen in self._last_status.items():
            if now - seen > self.stale_after:
                row = self._rows[sensor_id]
                for column in range(self.table.columnCount()):
                    self.table.item(row, column).setForeground(STALE_COLOR)
                self.table.item(row, 0).setToolTip(
                    f"No status from sensor '{sensor_id}' for {now - seen:.0f} s; "
                    "its node may have stopped."
                )

    def status_text(self, sensor_id: str) -> dict[str, str]:
        """What the table shows for a sensor: column title -> text."""
        row = self._rows[sensor_id]
        return {
            self.table.horizontalHeaderItem(c).text(): self.table.item(row, c).text()
            for c in range(self.table.columnCount())
        }

    # ---------------------------------------------------------------- preview
    def set_preview(self, sensor_id: str, frame: RGBDFrame, batch: DetectionBatch | None) -> None:
        self._row(sensor_id)
        self._frames[sensor_id] = (frame, batch)
        if self.sensor_choice.currentText() == sensor_id:
            self._redraw()

    def _choose_stream(self) -> None:
        self.preview.stream = self.stream_choice.currentData()
        self._redraw()

    def _redraw(self) -> None:
        frame, batch = self._frames.get(self.sensor_choice.currentText(), (None, None))
        self.preview.show_frame(frame, batch)
