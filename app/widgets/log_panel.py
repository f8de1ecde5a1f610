"""The Log dock: what went wrong, as sentences, newest last.

Messages come from the site (``SiteSource.log``), from the window itself, and
from Python's ``logging`` in this process (warnings and errors of ``optrack``
and ``app``), through :class:`QtLogHandler`, which is safe to call from any
thread.
"""

from __future__ import annotations

import logging
import time

from PySide6.QtCore import QObject, Signal
from PySide6.QtGui import QColor
from PySide6.QtWidgets import QListWidget, QListWidgetItem, QVBoxLayout, QWidget

LEVEL_COLORS = {"info": None, "warning": QColor(180, 110, 0), "error": QColor(200, 30, 30)}


class _Bridge(QObject):
    message = Signal(str, str)


class QtLogHandler(logging.Handler):
    """A ``logging`` handler that re-emits records as the Qt signal ``message(level, text)``."""

    def __init__(self, level: int = logging.WARNING) -> None:
        super().__init__(level)
        self._bridge = _Bridge()
        self.message = self._bridge.message

    def emit(self, record: logging.LogRecord) -> None:  # type: ignore[override]
        if record.levelno >= logging.ERROR:
            level = "error"
        elif record.levelno >= logging.WARNING:
            level = "warning"
        else:
            level = "info"
        try:
            text = record.getMessage()
        except (TypeError, ValueError):
            text = str(record.msg)
        self._bridge.message.emit(level, text)


class LogPanel(QWidget):
    """Time, level and sentence, one line each; keeps the last ``max_lines``."""

    def __init__(self, max_lines: int = 2000, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.max_lines = max_lines
        self.list = QListWidget()
        self.list.setWordWrap(True)
        self.list.setUniformItemSizes(False)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.addWidget(self.list)

    def append(self, level: str, text: str) -> None:
        level = level if level in LEVEL_COLORS else "info"
        stamp = time.strftime("%H:%M:%S")
        prefix = "" if level == "info" else f"{level.capitalize()}: "
        item = QListWidgetItem(f"{stamp}  {prefix}{text}")
        color = LEVEL_COLORS[level]
        if color is not None:
            item.setForeground(color)
        item.setData(0x0100, level)  # Qt.UserRole
        at_bottom = self.list.verticalScrollBar().value() >= self.list.verticalScrollBar().maximum()
        self.list.addItem(item)
        while self.list.count() > self.max_lines:
            self.list.takeItem(0)
        if at_bottom:
            self.list.scrollToBottom()

    def lines(self) -> list[str]:
        return [self.list.item(i).text() for i in range(self.list.count())]
