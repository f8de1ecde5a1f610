"""The wizard's live views, each fed with what ``LiveCalibration.state()`` says.

* :class:`SensorImages`: each sensor's latest image with the corners the
  backend drew on it, whether the board is seen, and (intrinsics) where
  corners have been seen so far;
* :class:`SensorTable`: per sensor views, reprojection RMS and state; the view
  count coloured red / yellow / green against the backend's thresholds;
* :class:`CovisibilityGraph`: sensors as nodes, shared views on the edges;
* :class:`TrajectoryPlot`: the walker's per-sensor trajectories from above.

Nothing here computes calibration: the widgets draw the numbers they get.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QPointF, QRectF, Qt
from PySide6.QtGui import QColor, QFont, QImage, QPainter, QPen
from PySide6.QtWidgets import (
    QGridLayout,
    QHeaderView,
    QSizePolicy,
    QTableWidget,
    QTableWidgetItem,
    QWidget,
)

from app.trails import track_color

__all__ = [
    "COUNT_COLORS",
    "CovisibilityGraph",
    "SensorImages",
    "SensorTable",
    "TrajectoryPlot",
    "count_level",
    "operator_text",
    "views_text",
]

# Red / yellow / green: too few views, enough to solve, plenty.
COUNT_COLORS = {
    "red": QColor(230, 120, 120),
    "yellow": QColor(240, 210, 90),
    "green": QColor(120, 200, 120),
}
CALIBRATED_COLOR = QColor(70, 160, 80)
UNCALIBRATED_COLOR = QColor(150, 150, 150)
BACKGROUND = QColor(25, 28, 34)
TEXT = QColor(230, 230, 230)


# What the simulated operator does, in words (the site status says its action's name).
OPERATOR_WORDS = {
    "move_board": "the simulated operator carries the board to each camera and pair",
    "show_board": "the simulated operator shows the board to one camera",
    "lay_board": "the simulated operator lays the board on the floor",
    "walk": "a simulated person walks through every view",
    "people": "the site's own people walk",
}


def operator_text(operator: str) -> str:
    """The simulated operator's action in words; any other sentence as it is."""
    return OPERATOR_WORDS.get(operator, operator)


def views_text(count: int) -> str:
    """``1 view``, ``2 views``."""
    return f"{count} view" if count == 1 else f"{count} views"


def count_level(count: int, fair: int, good: int) -> str:
    """``red`` below ``fair``, ``yellow`` below ``good``, else ``green``."""
    if count < fair:
        return "red"
    if count < good:
        return "yellow"
    return "green"


def to_qimage(image: np.ndarray) -> QImage:
    """A uint8 HxW (grey) or HxWx3 (RGB) image as a QImage (copied)."""
    image = np.ascontiguousarray(image, dtype=np.uint8)
    if image.ndim == 2:
        height, width = image.shape
        return QImage(image.data, width, height, width, QImage.Format.Format_Grayscale8).copy()
    height, width, _ = image.shape
    return QImage(image.data, width, height, 3 * width, QImage.Format.Format_RGB888).copy()


# ------------------------------------------------------------------- images


class ImageTile(QWidget):
    """One sensor's image scaled to fit, its name, board seen or not, and coverage cells."""

    def __init__(self, sensor: str, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.sensor = sensor
        self.setMinimumSize(180, 140)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
        self.image: QImage | None = None
        self.board_seen = False
        self.coverage: np.ndarray | None = None
        self.caption = sensor
        self.highlight = False

    def set_view(
        self,
        image: np.ndarray | None,
        board_seen: bool,
        coverage: np.ndarray | None = None,
        caption: str = "",
    ) -> None:
        self.image = None if image is None else to_qimage(image)
        self.board_seen = board_seen
        self.coverage = None if coverage is None else np.asarray(coverage, dtype=float)
        self.caption = caption or self.sensor
        self.update()

    def paintEvent(self, event) -> None:  # noqa: N802 - Qt
        painter = QPainter(self)
        painter.fillRect(self.rect(), BACKGROUND)
        font = QFont()
        font.setPointSize(9)
        painter.setFont(font)
        caption_height = painter.fontMetrics().height() + 6
        area = QRectF(self.rect()).adjusted(2, caption_height, -2, -2)
        if self.image is None:
            painter.setPen(TEXT)
            painter.drawText(
                area, Qt.AlignmentFlag.AlignCenter | Qt.TextFlag.TextWordWrap, "No image yet."
            )
        else:
            width, height = self.image.width(), self.image.height()
            scale = min(area.width() / width, area.height() / height)
            target = QRectF(
                area.left() + (area.width() - width * scale) / 2,
                area.top() + (area.height() - height * scale) / 2,
                width * scale,
                height * scale,
            )
            painter.drawImage(target, self.image)
            if self.coverage is not None and self.coverage.size:
                self._paint_coverage(painter, target)
        # Caption: the sensor, and a green / red mark for the board seen / not seen.
        mark = COUNT_COLORS["green"] if self.board_seen else COUNT_COLORS["red"]
        painter.setPen(Qt.PenStyle.NoPen)
        painter.setBrush(mark)
        painter.drawEllipse(QRectF(6, 5, caption_height - 10, caption_height - 10))
        painter.setPen(TEXT)
        painter.drawText(
            QRectF(caption_height, 0, self.width() - caption_height - 4, caption_height),
            Qt.AlignmentFlag.AlignVCenter | Qt.AlignmentFlag.AlignLeft,
            self.caption,
        )
        if self.highlight:
            pen = QPen(COUNT_COLORS["yellow"])
            pen.setWidth(2)
            painter.setPen(pen)
            painter.setBrush(Qt.BrushStyle.NoBrush)
            painter.drawRect(QRectF(self.rect()).adjusted(1, 1, -1, -1))

    def _paint_coverage(self, painter: QPainter, target: QRectF) -> None:
        """Cells where corners were seen, tinted green by how much (0..1)."""
        rows, cols = self.coverage.shape[:2]
        cell_w, cell_h = target.width() / cols, target.height() / rows
        painter.setPen(Qt.PenStyle.NoPen)
        for r in range(rows):
            for c in range(cols):
                value = float(np.clip(self.coverage[r, c], 0.0, 1.0))
                if value <= 0.0:
                    continue
                painter.setBrush(QColor(60, 220, 90, round(40 + 110 * value)))
                painter.drawRect(
                    QRectF(target.left() + c * cell_w, target.top() + r * cell_h, cell_w, cell_h)
                )
        pen = QPen(QColor(255, 255, 255, 70))
        painter.setPen(pen)
        painter.setBrush(Qt.BrushStyle.NoBrush)
        for c in range(1, cols):
            x = target.left() + c * cell_w
            painter.drawLine(QPointF(x, target.top()), QPointF(x, target.bottom()))
        for r in range(1, rows):
            y = target.top() + r * cell_h
            painter.drawLine(QPointF(target.left(), y), QPointF(target.right(), y))


class SensorImages(QWidget):
    """A grid of :class:`ImageTile`, one per sensor."""

    def __init__(self, columns: int = 3, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.columns = columns
        self.grid = QGridLayout(self)
        self.grid.setContentsMargins(0, 0, 0, 0)
        self.grid.setSpacing(4)
        self.tiles: dict[str, ImageTile] = {}

    def set_sensors(self, sensors: Sequence[str]) -> None:
        if list(self.tiles) == list(sensors):
            return
        for tile in self.tiles.values():
            self.grid.removeWidget(tile)
            tile.deleteLater()
        self.tiles = {}
        for i, sensor in enumerate(sensors):
            tile = ImageTile(sensor, self)
            self.grid.addWidget(tile, i // self.columns, i % self.columns)
            self.tiles[sensor] = tile

    def set_view(self, sensor: str, *args, **kwargs) -> None:
        tile = self.tiles.get(sensor)
        if tile is not None:
            tile.set_view(*args, **kwargs)


# -------------------------------------------------------------------- table


class SensorTable(QTableWidget):
    """One row per sensor; columns given as (key, title); the ``views`` cell coloured."""

    def __init__(self, columns: Sequence[tuple[str, str]], parent: QWidget | None = None) -> None:
        super().__init__(0, len(columns), parent)
        self.keys = [key for key, _ in columns]
        self.setHorizontalHeaderLabels([title for _, title in columns])
        self.verticalHeader().setVisible(False)
        self.setEditTriggers(QTableWidget.EditTrigger.NoEditTriggers)
        self.setSelectionMode(QTableWidget.SelectionMode.NoSelection)
        header = self.horizontalHeader()
        header.setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)
        header.setStretchLastSection(True)
        self.rows: dict[str, int] = {}
        self.levels: dict[str, str] = {}  # sensor -> red / yellow / green of its views

    def set_rows(self, rows: Mapping[str, Mapping[str, str]], levels: Mapping[str, str]) -> None:
        """``rows``: sensor -> {key: text}; ``levels``: sensor -> colour name of its views."""
        if list(self.rows) != list(rows):
            self.setRowCount(len(rows))
            self.rows = {sensor: i for i, sensor in enumerate(rows)}
        for sensor, values in rows.items():
            row = self.rows[sensor]
            for column, key in enumerate(self.keys):
                text = sensor if key == "sensor" else values.get(key, "")
                item = self.item(row, column)
                if item is None:
                    item = QTableWidgetItem()
                    self.setItem(row, column, item)
                if item.text() != text:
                    item.setText(text)
                if key == "views" and sensor in levels:
                    item.setBackground(COUNT_COLORS[levels[sensor]])
                    item.setForeground(QColor(0, 0, 0))
        self.levels = dict(levels)

    def text(self, sensor: str, key: str) -> str:
        item = self.item(self.rows[sensor], self.keys.index(key))
        return "" if item is None else item.text()


# -------------------------------------------------------------- covisibility


class CovisibilityGraph(QWidget):
    """Sensors on a circle; an edge where two sensors saw the board at once, labelled with
    the number of shared views. Calibrated sensors are green, the others grey."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setMinimumSize(220, 180)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
        self.sensors: list[str] = []
        self.calibrated: set[str] = set()
        self.edges: dict[tuple[str, str], int] = {}
        self.levels: dict[tuple[str, str], str] = {}
        self.thresholds = (1, 1)

    def set_graph(
        self,
        sensors: Sequence[str],
        calibrated: Iterable[str],
        edges: Iterable[tuple[str, str, int]],
        thresholds: tuple[int, int] = (1, 1),
    ) -> None:
        """``edges``: (sensor a, sensor b, shared views); edges with no views are not drawn;
        ``thresholds``: (fair, good) shared views for the edge's colour."""
        self.sensors = list(sensors)
        self.calibrated = set(calibrated)
        self.thresholds = thresholds
        self.edges = {}
        for a, b, count in edges:
            if count > 0 and a != b:
                self.edges[tuple(sorted((a, b)))] = int(count)  # type: ignore[index]
        self.levels = {pair: count_level(n, *thresholds) for pair, n in self.edges.items()}
        self.update()

    def positions(self) -> dict[str, QPointF]:
        """Where each sensor's node is drawn (widget pixels)."""
        n = len(self.sensors)
        centre = QPointF(self.width() / 2, self.height() / 2)
        radius = max(min(self.width(), self.height()) / 2 - 34, 10)
        return {
            sensor: centre
            + QPointF(
                radius * math.cos(-math.pi / 2 + 2 * math.pi * i / max(n, 1)),
                radius * math.sin(-math.pi / 2 + 2 * math.pi * i / max(n, 1)),
            )
            for i, sensor in enumerate(self.sensors)
        }

    def paintEvent(self, event) -> None:  # noqa: N802 - Qt
        painter = QPainter(self)
        painter.setRenderHint(QPainter.RenderHint.Antialiasing)
        painter.fillRect(self.rect(), QColor(250, 250, 250))
        font = QFont()
        font.setPointSize(9)
        painter.setFont(font)
        if not self.sensors:
            painter.setPen(QColor(60, 60, 60))
            painter.drawText(self.rect(), Qt.AlignmentFlag.AlignCenter, "No sensors.")
            return
        where = self.positions()
        metrics = painter.fontMetrics()
        for (a, b), count in self.edges.items():
            if a not in where or b not in where:
                continue
            color = COUNT_COLORS[self.levels[(a, b)]].darker(130)
            pen = QPen(color)
            pen.setWidthF(1.5 + min(count, 30) / 6)
            painter.setPen(pen)
            painter.drawLine(where[a], where[b])
            middle = (where[a] + where[b]) / 2
            label = str(count)
            box = QRectF(0, 0, metrics.horizontalAdvance(label) + 8, metrics.height() + 2)
            box.moveCenter(middle)
            painter.setPen(QPen(color))
            painter.setBrush(QColor(255, 255, 255))
            painter.drawRoundedRect(box, 4, 4)
            painter.setPen(QColor(0, 0, 0))
            painter.drawText(box, Qt.AlignmentFlag.AlignCenter, label)
        for sensor, point in where.items():
            fill = CALIBRATED_COLOR if sensor in self.calibrated else UNCALIBRATED_COLOR
            painter.setPen(QPen(fill.darker(140), 1.5))
            painter.setBrush(fill)
            painter.drawEllipse(point, 9, 9)
            painter.setPen(QColor(20, 20, 20))
            width = metrics.horizontalAdvance(sensor) + 4
            below = point.y() + 12 < self.height() - metrics.height()
            top = point.y() + 11 if below else point.y() - 11 - metrics.height()
            left = min(max(point.x() - width / 2, 2), self.width() - width - 2)
            painter.drawText(
                QRectF(left, top, width, metrics.height()), Qt.AlignmentFlag.AlignCenter, sensor
            )


# ------------------------------------------------------------- trajectories


class TrajectoryPlot(pg.PlotWidget):
    """Per-sensor trajectories of the walker seen from above (world x, y in metres)."""

    def __init__(self, title: str, parent: QWidget | None = None) -> None:
        super().__init__(parent, background="w")
        self.setTitle(title, color="k", size="10pt")
        self.setAspectLocked(True)
        self.showGrid(x=True, y=True, alpha=0.25)
        self.setLabel("bottom", "x", units="m")
        self.setLabel("left", "y", units="m")
        self.setMinimumSize(240, 220)
        self.legend = self.addLegend(offset=(-5, 5), labelTextColor="k")
        self.curves: dict[str, pg.PlotDataItem] = {}

    def set_trajectories(self, trajectories: Mapping[str, np.ndarray]) -> None:
        """``trajectories``: sensor -> Nx2 or Nx3 world points (x, y used)."""
        for curve in self.curves.values():
            self.removeItem(curve)
        self.legend.clear()
        self.curves = {}
        for i, (sensor, points) in enumerate(sorted(trajectories.items())):
            points = np.asarray(points, dtype=float).reshape(-1, np.shape(points)[-1])
            # Dots, not lines: a sensor loses the walker between views, and a line would
            # join the two ends of such a gap.
            color = track_color(i + 1)
            curve = pg.PlotDataItem(
                points[:, 0],
                points[:, 1],
                pen=None,
                symbol="o",
                symbolSize=4,
                symbolPen=None,
                symbolBrush=pg.mkBrush(*color),
                name=sensor,
            )
            self.addItem(curve)
            self.curves[sensor] = curve
        if self.curves:
            self.autoRange()
