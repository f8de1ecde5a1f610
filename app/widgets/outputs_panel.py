"""The Outputs dock: where the tracks are streamed (UDP JSON, OSC, WebSocket).

The table shows what the site reports (the ``outputs`` node's status); the
buttons only send the operator's request to the site.
"""

from __future__ import annotations

from typing import Any

from PySide6.QtCore import Qt, Signal
from PySide6.QtGui import QColor
from PySide6.QtWidgets import (
    QComboBox,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QLineEdit,
    QPushButton,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from app.source import NO_SITE
from optrack.errors import UserError
from optrack.outputs.streams import OUTPUT_KINDS, OUTPUT_PORTS
from optrack.outputs.udp import no_receiver_note, parse_address

KIND_TITLES = {"udp": "UDP JSON", "osc": "OSC", "websocket": "WebSocket"}
DEFAULT_ADDRESSES = {kind: f"127.0.0.1:{port}" for kind, port in OUTPUT_PORTS.items()}
COLUMNS = ("on", "kind", "address", "packets/s", "problem")
NO_RECEIVER_TIP = (
    "No program listens at this address yet. The site sends the tracks anyway; a program "
    "that starts listening there gets them at once."
)


def check_address(kind: str, address: str) -> str | None:
    """Why ``address`` cannot be a ``kind`` destination (optrack.outputs' own parser says),
    or None when it can."""
    try:
        parse_address(
            address, OUTPUT_PORTS[kind], f"{KIND_TITLES[kind]} address", kind == "websocket"
        )
    except UserError as error:
        return str(error)
    return None


class OutputsPanel(QWidget):
    """Destinations and their rates; add, remove, enable."""

    add_requested = Signal(str, str)  # kind, address
    remove_requested = Signal(str, str)
    enable_requested = Signal(str, str, bool)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.table = QTableWidget(0, len(COLUMNS))
        self.table.setHorizontalHeaderLabels(COLUMNS)
        self.table.verticalHeader().hide()
        self.table.setSelectionBehavior(QTableWidget.SelectionBehavior.SelectRows)
        self.table.setEditTriggers(QTableWidget.EditTrigger.NoEditTriggers)
        header = self.table.horizontalHeader()
        header.setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)
        header.setSectionResizeMode(len(COLUMNS) - 1, QHeaderView.ResizeMode.Stretch)
        self.kind = QComboBox()
        for kind in OUTPUT_KINDS:
            self.kind.addItem(KIND_TITLES[kind], kind)
        self.address = QLineEdit(DEFAULT_ADDRESSES[OUTPUT_KINDS[0]])
        self.address.setToolTip(
            "HOST:PORT. UDP JSON and OSC send to that address; a WebSocket output is a server "
            "listening on it."
        )
        self.add_button = QPushButton("Add")
        self.remove_button = QPushButton("Remove")
        self.message = QLabel(NO_SITE)
        self.message.setWordWrap(True)
        row = QHBoxLayout()
        row.addWidget(self.kind)
        row.addWidget(self.address, 1)
        row.addWidget(self.add_button)
        row.addWidget(self.remove_button)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.addWidget(self.table, 1)
        layout.addLayout(row)
        layout.addWidget(self.message)
        self.destinations: list[dict[str, Any]] = []
        self._by_node: dict[str, list[dict[str, Any]]] = {}
        self.kind.currentIndexChanged.connect(self._kind_changed)
        self.add_button.clicked.connect(self.request_add)
        self.address.returnPressed.connect(self.request_add)
        self.remove_button.clicked.connect(self.request_remove)
        self.table.itemChanged.connect(self._item_changed)
        self.set_connected(False)

    def set_connected(self, connected: bool, description: str = NO_SITE) -> None:
        for widget in (self.kind, self.address, self.add_button, self.remove_button):
            widget.setEnabled(connected)
        self.message.setText("" if connected else f"{description}: outputs run on a site.")

    def _kind_changed(self) -> None:
        kind = self.kind.currentData()
        if self.address.text() in DEFAULT_ADDRESSES.values():
            self.address.setText(DEFAULT_ADDRESSES[kind])

    def request_add(self) -> None:
        kind, address = self.kind.currentData(), self.address.text().strip()
        problem = check_address(kind, address)
        if problem is not None:
            self.message.setText(problem)
            return
        if any(d["kind"] == kind and d["address"] == address for d in self.destinations):
            self.message.setText(f"{KIND_TITLES[kind]} to {address} is already in the list.")
            return
        self.message.setText("")
        self.add_requested.emit(kind, address)

    def request_remove(self) -> None:
        rows = sorted({index.row() for index in self.table.selectedIndexes()})
        if not rows:
            self.message.setText("Select the output to remove in the table first.")
            return
        for row in rows:
            destination = self.destinations[row]
            self.remove_requested.emit(destination["kind"], destination["address"])

    def _item_changed(self, item: QTableWidgetItem) -> None:
        if item.column() != 0 or self._filling:
            return
        destination = self.destinations[item.row()]
        enabled = item.checkState() == Qt.CheckState.Checked
        if enabled != bool(destination.get("enabled", True)):
            self.enable_requested.emit(destination["kind"], destination["address"], enabled)

    _filling = False

    def set_destinations(self, destinations: list[dict[str, Any]]) -> None:
        """The site's outputs: dicts with kind, address, enabled, packets_per_s (and error)."""
        self._filling = True
        try:
            self.destinations = list(destinations)
            self.table.setRowCount(len(self.destinations))
            for row, destination in enumerate(self.destinations):
                on = QTableWidgetItem()
                on.setFlags(
                    Qt.ItemFlag.ItemIsUserCheckable
                    | Qt.ItemFlag.ItemIsEnabled
                    | Qt.ItemFlag.ItemIsSelectable
                )
                on.setCheckState(
                    Qt.CheckState.Checked
                    if destination.get("enabled", True)
                    else Qt.CheckState.Unchecked
                )
                rate = destination.get("packets_per_s")
                error = destination.get("error") or ""
                # Nothing listening yet is the default output's state, not a fault: grey.
                waiting = no_receiver_note(destination["address"], error)
                cells = [
                    on,
                    QTableWidgetItem(KIND_TITLES.get(destination["kind"], destination["kind"])),
                    QTableWidgetItem(destination["address"]),
                    QTableWidgetItem("" if rate is None else f"{rate:.1f}"),
                    QTableWidgetItem(waiting or error),
                ]
                if waiting:
                    for cell in cells:
                        cell.setToolTip(f"{NO_RECEIVER_TIP} ({error})")
                    cells[-1].setForeground(QColor(130, 130, 130))
                elif error:  # the sentence, whole, on every cell of the row
                    for cell in cells:
                        cell.setToolTip(error)
                    cells[-1].setForeground(QColor(190, 40, 40))
                for column, cell in enumerate(cells):
                    self.table.setItem(row, column, cell)
        finally:
            self._filling = False

    def set_status(self, node: str, values: dict) -> None:
        """Only an outputs node's status says what the outputs are: every status message
        carries a ``destinations`` list, empty for detectors and trackers, which must not
        wipe the table. Several outputs nodes (one per computer) are listed together."""
        if values.get("role") != "outputs":
            return
        self._by_node[node] = list(values.get("destinations", []))
        self.set_destinations([d for name in sorted(self._by_node) for d in self._by_node[name]])
