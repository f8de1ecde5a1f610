"""The embedded site: ``optrack run --headless`` started by the window, as a child process.

The site runs in its own processes (a detector per sensor, the tracker, the
outputs), exactly as ``optrack run`` runs it; the window joins its bus like
any other GUI. What the site writes on stderr comes back line by line: the
venue-rendering progress bar for the status bar, everything else for the Log.
Closing the window stops the site (SIGTERM: it stops its nodes in order).
"""

from __future__ import annotations

import sys
from pathlib import Path

from PySide6.QtCore import QObject, QProcess, Signal

__all__ = ["EmbeddedSite"]


class EmbeddedSite(QObject):
    """One ``optrack run --headless [--config FILE]`` process."""

    line = Signal(str)  # a finished line of the site's output
    progress = Signal(str)  # the line being rewritten (a progress bar)
    ended = Signal(int, str)  # exit code, the site's last line (its error sentence)

    def __init__(
        self,
        config: str | Path | None = None,
        parent: QObject | None = None,
        command: list[str] | None = None,
    ) -> None:
        """``command`` replaces ``optrack run --headless`` (a program and its arguments)."""
        super().__init__(parent)
        self.config = str(config) if config else None
        self.command = command or [sys.executable, *self.argv]
        self.process = QProcess(self)
        self.process.setProcessChannelMode(QProcess.ProcessChannelMode.MergedChannels)
        self.process.readyReadStandardOutput.connect(self._read)
        self.process.finished.connect(self._finished)
        self._partial = ""
        self._last_line = ""
        self._stopping = False

    @property
    def argv(self) -> list[str]:
        argv = ["-m", "optrack.cli", "run", "--headless"]
        if self.config:
            argv += ["--config", self.config]
        return argv

    def start(self) -> None:
        self.process.start(self.command[0], self.command[1:])

    @property
    def running(self) -> bool:
        return self.process.state() != QProcess.ProcessState.NotRunning

    def _read(self) -> None:
        text = self._partial + bytes(self.process.readAllStandardOutput()).decode(
            "utf-8", "replace"
        )
        *done, self._partial = text.split("\n")
        for chunk in done:
            final = chunk.split("\r")[-1].strip()
            if final:
                self._last_line = final
                self.line.emit(final)
        if "\r" in self._partial:
            shown = self._partial.split("\r")
            current = shown[-1].strip() or (shown[-2].strip() if len(shown) > 1 else "")
            if current:
                self.progress.emit(current)

    def _finished(self, code: int, status: QProcess.ExitStatus) -> None:
        self._read()
        if self._partial.strip():
            self._last_line = self._partial.split("\r")[-1].strip()
            self.line.emit(self._last_line)
            self._partial = ""
        if status == QProcess.ExitStatus.CrashExit and not self._stopping:
            code = -1
        self.ended.emit(code, self._last_line)

    def stop(self, timeout_s: float) -> None:
        """Ask the site to stop (it stops its nodes in order); kill it after ``timeout_s``."""
        if not self.running:
            return
        self._stopping = True
        self.process.terminate()
        if not self.process.waitForFinished(int(timeout_s * 1000)):
            self.process.kill()
            self.process.waitForFinished(2000)
