"""The window's Help menu (the guides, keyboard shortcuts, the version and the folders
where files go) and View → Reset layout."""

from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import QUrl
from PySide6.QtGui import QAction, QDesktopServices, QKeySequence
from PySide6.QtWidgets import QMainWindow, QMenu, QMessageBox

from app.folders import calibrations_folder, node_state_folder, recordings_folder
from optrack import __version__

__all__ = ["GUIDES", "about_text", "add_help_menu", "guides_folder", "shortcuts_text"]

#: The guides in docs/, in the order an operator needs them: (file, title).
GUIDES = (
    ("gui.md", "The operator window and the calibration wizard"),
    ("runtime.md", "Running a site"),
    ("cameras.md", "Cameras"),
    ("calibration.md", "Calibration"),
    ("detection.md", "Detection"),
    ("tracking.md", "Tracking"),
    ("skeleton.md", "Skeletons"),
    ("deploy.md", "Installing on several computers"),
)


def guides_folder() -> Path:
    """docs/ beside the application (a source checkout or an install that ships it)."""
    return Path(__file__).resolve().parents[1] / "docs"


def shortcuts_text(window: QMainWindow) -> str:
    """Every menu action of ``window`` that has a keyboard shortcut, one a line."""
    lines = []
    for menu in window.menuBar().findChildren(QMenu):
        for action in menu.actions():
            keys = action.shortcut().toString(QKeySequence.SequenceFormat.NativeText)
            if keys:
                lines.append(f"{keys}\t{menu.title().replace('&', '')} → {action.text()}")
    return "\n".join(dict.fromkeys(lines)).replace("&", "")


def about_text() -> str:
    """The version and where calibrations, recordings and the nodes' state go."""
    return (
        f"optrack {__version__}: people tracking in RGB-D camera networks.\n\n"
        f"Calibrations are saved in {calibrations_folder()}.\n"
        f"Recordings are saved in {recordings_folder()}.\n"
        f"Each node keeps the calibration it received in {node_state_folder()}.\n"
        f"The guides are in {guides_folder()}."
    )


def _open_guide(path: Path) -> None:
    QDesktopServices.openUrl(QUrl.fromLocalFile(str(path)))


def add_help_menu(window: QMainWindow, view_menu: QMenu, reset_layout) -> QMenu:
    """View → Reset layout (``reset_layout``) and the Help menu of ``window``."""
    view_menu.addSeparator()
    reset = QAction("&Reset layout", window)
    reset.setToolTip("Every dock back where it was when the window opened, and shown.")
    reset.triggered.connect(reset_layout)
    view_menu.addAction(reset)
    help_menu = window.menuBar().addMenu("&Help")
    guides = help_menu.addMenu("&Guides")
    for number, (name, title) in enumerate(GUIDES):
        path = guides_folder() / name
        action = QAction(title, window)
        action.setData(str(path))
        action.setEnabled(path.is_file())
        if number == 0:
            action.setShortcut(QKeySequence.StandardKey.HelpContents)
        action.triggered.connect(lambda _checked=False, path=path: _open_guide(path))
        guides.addAction(action)
    shortcuts = QAction("&Keyboard shortcuts", window)
    shortcuts.triggered.connect(
        lambda: QMessageBox.information(window, "Keyboard shortcuts", shortcuts_text(window))
    )
    about = QAction("&About optrack", window)
    about.triggered.connect(lambda: QMessageBox.about(window, "About optrack", about_text()))
    help_menu.addAction(shortcuts)
    help_menu.addAction(about)
    return help_menu
