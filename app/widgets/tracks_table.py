"""The Tracks table: one row per tracked person, as the tracker reports it, with the state
and rate of the person's skeleton while the skeleton stage runs."""

from __future__ import annotations

import time
from typing import Any

from PySide6.QtCore import QAbstractTableModel, QModelIndex, Qt
from PySide6.QtGui import QColor
from PySide6.QtWidgets import QHeaderView, QLabel, QTableView, QVBoxLayout, QWidget

from app.source import NO_SITE
from app.trails import track_color
from optrack.types import Skeleton, SkeletonBatch, Track, TrackBatch, TrackStatus

COLUMNS = ("ID", "x (m)", "y (m)", "height (m)", "age (s)", "confidence", "status", "skeleton")
STATUS_COLUMN = COLUMNS.index("status")
SKELETON_COLUMN = COLUMNS.index("skeleton")
CONFIDENCE_TIP = (
    "How person-like the detector found this person in its last detection (the HOG "
    "classifier's margin; larger is surer). Below zero is normal for someone far away, "
    "partly out of view or behind something: the tracker keeps a person it has confirmed "
    "over several frames."
)
# Skeletons not sent again for this long are no longer shown, nor their column (the
# skeleton stage was turned off); the column is there only while skeletons come.
SKELETON_STALE_S = 2.0


def describe_skeleton(skeleton: Skeleton | None) -> str:
    """A skeleton's state and update rate ("tracking 14 Hz"); empty without one."""
    if skeleton is None:
        return ""
    return f"{skeleton.state} {skeleton.rate_hz:.0f} Hz"


def _cell(track: Track, column: int, skeleton: Skeleton | None = None) -> str:
    if column == SKELETON_COLUMN:
        return describe_skeleton(skeleton)
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
        self.skeletons: dict[int, Skeleton] = {}
        self._skeletons_at = 0.0  # monotonic time of the last skeleton batch

    @property
    def skeleton_column(self) -> bool:
        """Whether the ``skeleton`` column is shown (skeletons arrive)."""
        return self._skeletons_at > 0.0

    def set_skeletons(self, batch: SkeletonBatch, now: float | None = None) -> None:
        """The newest skeletons (shown in the ``skeleton`` column until stale)."""
        if not self.skeleton_column:
            self.beginInsertColumns(QModelIndex(), SKELETON_COLUMN, SKELETON_COLUMN)
            self._skeletons_at = 1.0
            self.endInsertColumns()
        self.skeletons = {s.id: s for s in batch.skeletons}
        self._skeletons_at = max(time.monotonic() if now is None else now, 1.0)
        if self.tracks:
            last = self.index(len(self.tracks) - 1, SKELETON_COLUMN)
            self.dataChanged.emit(self.index(0, SKELETON_COLUMN), last)

    def set_batch(self, batch: TrackBatch, now: float | None = None) -> None:
        now = time.monotonic() if now is None else now
        if self.skeleton_column and now - self._skeletons_at > SKELETON_STALE_S:
            self.beginRemoveColumns(QModelIndex(), SKELETON_COLUMN, SKELETON_COLUMN)
            self.skeletons, self._skeletons_at = {}, 0.0
            self.endRemoveColumns()
        tracks = sorted(batch.tracks, key=lambda t: t.id)
        if [t.id for t in tracks] == [t.id for t in self.tracks] and tracks:
            # The same people: new values in place, so the operator's selection stays.
            self.tracks = tracks
            last = self.index(len(tracks) - 1, self.columnCount() - 1)
            self.dataChanged.emit(self.index(0, 0), last)
            return
        self.beginResetModel()
        self.tracks = tracks
        self.endResetModel()

    def rowCount(self, parent: QModelIndex = QModelIndex()) -> int:  # noqa: N802, B008 - Qt
        return 0 if parent.isValid() else len(self.tracks)

    def columnCount(self, parent: QModelIndex = QModelIndex()) -> int:  # noqa: N802, B008 - Qt
        shown = len(COLUMNS) if self.skeleton_column else SKELETON_COLUMN
        return 0 if parent.isValid() else shown

    def headerData(self, section: int, orientation: Qt.Orientation, role: int = 0) -> Any:  # noqa: N802
        if role == Qt.ItemDataRole.DisplayRole and orientation == Qt.Orientation.Horizontal:
            return COLUMNS[section]
        if role == Qt.ItemDataRole.ToolTipRole and section == COLUMNS.index("confidence"):
            return CONFIDENCE_TIP
        return None

    def data(self, index: QModelIndex, role: int = 0) -> Any:
        if not index.isValid():
            return None
        track = self.tracks[index.row()]
        column = index.column()
        if role == Qt.ItemDataRole.DisplayRole:
            return _cell(track, column, self.skeletons.get(track.id))
        if role == Qt.ItemDataRole.TextAlignmentRole and column < STATUS_COLUMN:
            return int(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
        if role == Qt.ItemDataRole.DecorationRole and column == 0:
            return QColor(*track_color(track.id))
        if role == Qt.ItemDataRole.ForegroundRole and track.status == TrackStatus.MISSING:
            return QColor(128, 128, 128)
        if role == Qt.ItemDataRole.ToolTipRole and column == COLUMNS.index("confidence"):
            return CONFIDENCE_TIP
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

    def set_skeletons(self, batch: SkeletonBatch) -> None:
        self.model.set_skeletons(batch)

    def set_site(self, description: str) -> None:
        """Shown until the first tracks arrive."""
        if not self.model.tracks:
            self.caption.setText(description)
