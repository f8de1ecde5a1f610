"""The Top view: the floor seen from above, with each camera's coverage and the tracks."""

from __future__ import annotations

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QPointF
from PySide6.QtGui import QBrush, QColor, QPen, QPolygonF
from PySide6.QtWidgets import QGraphicsPolygonItem, QWidget

from app.trails import TrailHistory, track_color
from app.widgets.overlay import Overlay
from optrack.calibration.overlap import BoardSuggestion
from optrack.geometry import floor_footprint
from optrack.types import NetworkCalibration, TrackBatch

SENSOR_COLOR = (40, 110, 200)
#: Where the calibration wizard suggests holding the board.
GUIDANCE_COLOR = (30, 170, 60)


class TopView(pg.PlotWidget):
    """World x (right) and y (up) in metres, equal scale; z = 0 is the floor. The view
    frames the cameras; each camera's floor footprint runs to its detection range."""

    def __init__(self, trail_seconds: float = 8.0, parent: QWidget | None = None) -> None:
        super().__init__(parent, background="w")
        self.setAspectLocked(True)
        self.showGrid(x=True, y=True, alpha=0.25)
        self.setLabel("bottom", "x", units="m")
        self.setLabel("left", "y", units="m")
        self.setRange(xRange=(-5, 5), yRange=(-5, 5), padding=0.05)
        self.trails = TrailHistory(trail_seconds)
        self.overlay = Overlay(self)
        self._coverage: dict[str, list] = {}
        self._tracks = pg.ScatterPlotItem(size=14, pxMode=True)
        self._tracks.setZValue(10)
        self.addItem(self._tracks)
        self._labels: dict[int, pg.TextItem] = {}
        self._trail_items: dict[int, pg.PlotDataItem] = {}
        self.footprints: dict[str, np.ndarray] = {}
        self.guidance_items: list = []  # where to hold the board next (calibration)

    # --------------------------------------------------------------- coverage
    def set_calibration(
        self, calibration: NetworkCalibration, max_depth: dict[str, float] | float
    ) -> None:
        """Draw each calibrated camera and the floor it sees up to ``max_depth`` metres
        (one figure, or one per sensor id)."""
        for items in self._coverage.values():
            for item in items:
                self.removeItem(item)
        self._coverage.clear()
        self.footprints.clear()
        points = []
        for sensor_id, sensor in sorted(calibration.sensors.items()):
            depth = max_depth.get(sensor_id) if isinstance(max_depth, dict) else max_depth
            items = []
            position = sensor.pose[:3, 3]
            if sensor.intrinsics is not None and sensor.intrinsics.width and depth:
                footprint = floor_footprint(sensor.intrinsics, sensor.pose, depth)
                if len(footprint):
                    self.footprints[sensor_id] = footprint[:, :2]
                    polygon = QGraphicsPolygonItem(
                        QPolygonF([QPointF(float(x), float(y)) for x, y in footprint[:, :2]])
                    )
                    polygon.setBrush(QBrush(QColor(*SENSOR_COLOR, 40)))
                    pen = QPen(QColor(*SENSOR_COLOR, 160))
                    pen.setCosmetic(True)
                    polygon.setPen(pen)
                    items.append(polygon)
            marker = pg.ScatterPlotItem(
                [position[0]], [position[1]], symbol="s", size=10, brush=pg.mkBrush(*SENSOR_COLOR)
            )
            label = pg.TextItem(sensor_id, color=SENSOR_COLOR, anchor=(0.5, 1.3))
            label.setPos(float(position[0]), float(position[1]))
            items += [marker, label]
            points.append(position[None, :2])
            for item in items:
                self.addItem(item)
            self._coverage[sensor_id] = items
        if points:
            # Frame the cameras (they stand around the venue), not their whole range.
            everything = np.vstack(points)
            low, high = everything.min(axis=0) - 1.0, everything.max(axis=0) + 1.0
            self.setRange(xRange=(low[0], high[0]), yRange=(low[1], high[1]), padding=0)

    # --------------------------------------------------------------- guidance
    def set_guidance(self, guidance: BoardSuggestion | None) -> None:
        """Where to hold the board next (the calibration wizard's advice): the floor
        region in green, the board seen from above and the camera it is for; None (or no
        place found) clears them."""
        for item in self.guidance_items:
            self.removeItem(item)
        self.guidance_items = []
        if guidance is None or not guidance.found:
            return
        region = pg.ScatterPlotItem(
            guidance.region[:, 0],
            guidance.region[:, 1],
            size=7,
            pen=None,
            brush=pg.mkBrush(*GUIDANCE_COLOR, 90),
        )
        outline = np.vstack([guidance.corners, guidance.corners[:1]])  # closed
        board = pg.PlotDataItem(
            outline[:, 0], outline[:, 1], pen=pg.mkPen(*GUIDANCE_COLOR, width=4)
        )
        label = pg.TextItem(
            f"board for {guidance.sensor}", color=GUIDANCE_COLOR, anchor=(0.5, -0.4)
        )
        label.setPos(float(guidance.center[0]), float(guidance.center[1]))
        self.guidance_items = [region, board, label]
        for item in self.guidance_items:
            item.setZValue(5)
            self.addItem(item)

    # ----------------------------------------------------------------- tracks
    def set_batch(self, batch: TrackBatch) -> None:
        self.trails.update(batch)
        self._tracks.setData(
            [t.x for t in batch.tracks],
            [t.y for t in batch.tracks],
            brush=[pg.mkBrush(*track_color(t.id)) for t in batch.tracks],
            pen=pg.mkPen("k", width=1),
            data=[t.id for t in batch.tracks],
        )
        current = {t.id: t for t in batch.tracks}
        for track_id in list(self._labels):
            if track_id not in current:
                self.removeItem(self._labels.pop(track_id))
        for track_id, track in current.items():
            label = self._labels.get(track_id)
            if label is None:
                label = pg.TextItem(str(track_id), color=(20, 20, 20), anchor=(-0.3, 1.1))
                label.setZValue(11)
                self.addItem(label)
                self._labels[track_id] = label
            label.setPos(track.x, track.y)
        trail_ids = set(self.trails.ids())
        for track_id in list(self._trail_items):
            if track_id not in trail_ids:
                self.removeItem(self._trail_items.pop(track_id))
        for track_id in trail_ids:
            item = self._trail_items.get(track_id)
            if item is None:
                item = pg.PlotDataItem(pen=pg.mkPen(*track_color(track_id), width=2))
                self.addItem(item)
                self._trail_items[track_id] = item
            trail = self.trails.trail(track_id)
            item.setData(trail[:, 0], trail[:, 1])

    def track_positions(self) -> dict[int, tuple[float, float]]:
        """What the view draws now: track id -> (x, y)."""
        x, y = self._tracks.getData()
        ids = self._tracks.data["data"]
        return {int(i): (float(a), float(b)) for i, a, b in zip(ids, x, y, strict=True)}

    def labels(self) -> dict[int, str]:
        return {track_id: item.textItem.toPlainText() for track_id, item in self._labels.items()}

    def set_trail_seconds(self, seconds: float) -> None:
        self.trails.seconds = seconds
