"""The Tracks table: one row per tracked person, as the tracker reports it."""

from __future__ import annotations

import time
from typing import Any

from PySide6.QtCore import QAbstractTableModel, QModelIndex, Qt
from PySide6.QtGui import QColor
from PySide6.QtWidgets import QHeaderView, QLabel, QTableView, QVBoxLayout, QWidget

from app.source import NO_SITE
from app.trails import track_color
from optrack.types import Track, TrackBatch, TrackStatus

COLUMNS = ("ID", "x (m)", "y (m)", "height (m)", "age (s)", "confidence", "status")


def _cell(track: Track, column: int) -> str:
    return (
        str(track.id),
        f"{track.x:.2f}",
        f"{track.y:.2f}",
        f"{track.height:.2f}",
        f"{track.age:.1f}",
        f"{track.confidence:.2f}",
        str(track.status),
    )[column]


def describe_stamp(stamp: float) -> str:
    """A stamp as the operator reads it: clock time for wall-clock stamps, else seconds."""
    if stamp > 1e9:  # seconds since 1970: a live site
        return time.strftime("%H:%M:%S", time.localtime(stamp)) + f".{int(stamp % 1 * 10)}"
    return f"t = {stamp:.2f} s"


class TracksModel(QAbstractTableModel):
    """The tracks of the latest :class:`TrackBatch`, sorted by id."""

    def __init__(self, parent: Any = None) -> None:
        super().__init__(parent)
        self.tracks: list[Track] = []

    def set_batch(self, batch: TrackBatch) -> None:
        tracks = sorted(batch.tracks, key=lambda t: t.id)
        if [t.id for t in tracks] == [t.id for t in self.tracks] and tracks:
            # The same people: new values in place, so the operator's selection stays.
            self.tracks = tracks
            last = self.index(len(tracks) - 1, len(COLUMNS) - 1)
            self.dataChanged.emit(self.index(0, 0), last)
            return
        self.beginResetModel()
        self.tracks = tracks
        self.endResetModel()

    def rowCount(self, parent: QModelIndex = QModelIndex()) -> int:  # noqa: N802, B008 - Qt
        return 0 if parent.isValid() else len(self.tracks)

    def columnCount(self, parent: QModelIndex = QModelIndex()) -> int:  # noqa: N802, B008 - Qt
        return 0 if parent.isValid() else len(COLUMNS)

    def headerData(self, section: int, orientation: Qt.Orientation, role: int = 0) -> Any:  # noqa: N802
        if role == Qt.ItemDataRole.DisplayRole and orientation == Qt.Orientation.Horizontal:
            return COLUMNS[section]
        return None

    def data(self, index: QModelIndex, role: int = 0) -> Any:
        if not index.isValid():
            return None
        track = self.tracks[index.row()]
        column = index.column()
        if role == Qt.ItemDataRole.DisplayRole:
            return _cell(track, column)
        if role == Qt.ItemDataRole.TextAlignmentRole and column < len(COLUMNS) - 1:
            return int(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
        if role == Qt.ItemDataRole.DecorationRole and column == 0:
            return QColor(*track_color(track.id))
        if role == Qt.ItemDataRole.ForegroundRole and track.status == TrackStatus.MISSING:
            return QColor(128, 128, 128)
        if role == Qt.ItemDataRole.ToolTipRole and track.sensors:
            return "Seen by " + ", ".join(track.sensors)
        return None


class TracksTable(QWidget):
    """A caption (how many tracks, at what time) above the table."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.caption = QLabel(NO_SITE)
        self.model = TracksModel(self)
        self.view = QTableView()
        self.view.setModel(self.model)
        self.view.verticalHeader().hide()
        self.view.setSelectionBehavior(QTableView.SelectionBehavior.SelectRows)
        self.view.setAlternatingRowColors(True)
        header = self.view.horizontalHeader()
        header.setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)
        header.setStretchLastSection(True)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.addWidget(self.caption)
        layout.addWidget(self.view)

    def set_batch(self, batch: TrackBatch) -> None:
        self.model.set_batch(batch)
        count = len(batch.tracks)
        people = "1 person" if count == 1 else f"{count} people"
        self.caption.setText(
            f"{people} tracked at {describe_stamp(batch.stamp)} (frame {batch.seq})"
        )

    def set_site(self, description: str) -> None:
        """Shown until the first tracks arrive."""
        if not self.model.tracks:
            self.caption.setText(description)
