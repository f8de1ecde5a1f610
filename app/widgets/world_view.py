"""The World 3D view: the venue's floor and the world frame, in OpenGL."""

from __future__ import annotations

import pyqtgraph.opengl as gl
from PySide6.QtWidgets import QSizePolicy


class WorldView(gl.GLViewWidget):
    """3D view of the world frame (origin on the floor, z up, metres)."""

    def __init__(self, floor_size_m: float = 10.0, parent=None) -> None:
        super().__init__(parent)
        # Without Expanding a GLViewWidget collapses to zero width in a box layout.
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
        self.setMinimumSize(320, 240)
        self.setBackgroundColor((25, 28, 34))
        self.setCameraPosition(distance=floor_size_m * 1.2, elevation=30, azimuth=-60)
        self.floor = gl.GLGridItem()
        self.floor.setSize(floor_size_m, floor_size_m)
        self.floor.setSpacing(1.0, 1.0)
        self.floor.setColor((150, 150, 160, 160))
        self.addItem(self.floor)
        self.axes = gl.GLAxisItem()
        self.axes.setSize(1.0, 1.0, 1.0)
        self.addItem(self.axes)
