"""A sentence laid over a view while it has nothing to show ("No site connected")."""

from __future__ import annotations

from PySide6.QtCore import QEvent, QObject, Qt
from PySide6.QtWidgets import QLabel, QWidget


class Overlay(QLabel):
    """A centred, word-wrapped message on top of ``host``; hidden when empty."""

    def __init__(self, host: QWidget, text: str = "") -> None:
        super().__init__(host)
        self.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.setWordWrap(True)
        self.setAttribute(Qt.WidgetAttribute.WA_TransparentForMouseEvents)
        self.setStyleSheet(
            "QLabel { color: #e8e8e8; background: rgba(30, 33, 40, 190); "
            "border-radius: 6px; padding: 10px; font-size: 13pt; }"
        )
        host.installEventFilter(self)
        self.show_message(text)

    def show_message(self, text: str) -> None:
        self.setText(text)
        self.setVisible(bool(text))
        self._place()

    def eventFilter(self, watched: QObject, event: QEvent) -> bool:  # noqa: N802 - Qt
        if event.type() == QEvent.Type.Resize:
            self._place()
        return False

    def _place(self) -> None:
        host = self.parentWidget()
        width = min(max(host.width() - 40, 120), 420)
        self.setFixedWidth(width)
        self.adjustSize()
        self.move((host.width() - width) // 2, (host.height() - self.height()) // 2)
        self.raise_()
