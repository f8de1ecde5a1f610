"""The operator's main window."""

from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QLabel, QMainWindow, QVBoxLayout, QWidget

from app.widgets.world_view import WorldView
from optrack import __version__


class MainWindow(QMainWindow):
    """One window for the whole site: the world in 3D, and (as they land) the
    sensors, tracks, outputs, log and the calibration wizard."""

    def __init__(self) -> None:
        super().__init__()
        self.setWindowTitle(f"optrack {__version__}")
        self.resize(1280, 800)
        central = QWidget(self)
        layout = QVBoxLayout(central)
        layout.setContentsMargins(0, 0, 0, 0)
        self.world = WorldView(parent=central)
        layout.addWidget(self.world)
        self.setCentralWidget(central)
        self.site_label = QLabel("No site connected")
        self.site_label.setAlignment(Qt.AlignmentFlag.AlignLeft)
        self.statusBar().addWidget(self.site_label)
