"""The status bar's warning that the site the window shows runs insecure (no keys)."""

from __future__ import annotations

from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QLabel, QWidget

__all__ = ["INSECURE_TEXT", "INSECURE_TIP", "InsecureWarning"]

INSECURE_TEXT = "⚠ Insecure site"
INSECURE_TIP = (
    "This site runs insecure (started with --insecure or bus.insecure): its links have no "
    "TLS and no access control, so anyone on its network can watch its tracks, change its "
    "parameters and send it commands.\n"
    "To secure it: make its keys with 'optrack site init --out FOLDER --nodes ... --stations "
    "...', copy the folder to every computer, set bus.keys to it (and this station's "
    "bus.identity) and start the site without --insecure (docs/runtime.md, Securing a site)."
)


class InsecureWarning(QLabel):
    """Shown while the window's source says its site is insecure (a source's ``insecure``:
    it joined without keys, or a node's status says so); it looks twice a second, so it
    follows the window to whichever source it shows."""

    def __init__(self, window: QWidget) -> None:
        super().__init__(INSECURE_TEXT)
        self._window = window
        self.setToolTip(INSECURE_TIP)
        self.setStyleSheet("color: #c62828; font-weight: bold;")
        self.hide()
        self._timer = QTimer(self)
        self._timer.timeout.connect(self.check)
        self._timer.start(500)

    def check(self) -> None:
        source = getattr(self._window, "source", None)
        self.setVisible(bool(getattr(source, "insecure", False)))
