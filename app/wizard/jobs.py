"""Calibration work off the GUI thread: a job runs one backend call on a worker thread
and reports its progress, result or error back to the GUI thread as Qt signals.

The wizard runs its jobs one after the other (a pool of one thread), in the
order the operator asked for them: a capture is stopped before the solve
that uses its views starts. ``LiveCalibration.state()`` is the only backend
call made on the GUI thread (it is a cheap snapshot).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from PySide6.QtCore import QObject, QRunnable, QThreadPool, Signal
from PySide6.QtWidgets import QHBoxLayout, QLabel, QProgressBar, QPushButton, QWidget

from optrack.errors import UserError

__all__ = ["Job", "JobRunner", "ProgressPanel"]

log = logging.getLogger("app.wizard")

Progress = Callable[[float, str], None]


class Job(QObject):
    """One call on the worker thread. Signals reach the GUI thread (the job lives there)."""

    progress = Signal(float, str)  # fraction 0..1, sentence
    done = Signal(object)  # the call's result
    failed = Signal(str)  # one sentence for the operator
    ended = Signal()  # after done or failed

    def __init__(self, title: str, call: Callable[[Progress], Any]) -> None:
        super().__init__()
        self.title = title
        self.call = call
        self.running = False

    def run(self) -> None:
        """Run the call (on a worker thread) and emit its outcome."""
        try:
            result = self.call(self.progress.emit)
        except UserError as error:
            self.failed.emit(str(error))
        except Exception as error:  # noqa: BLE001 - a defect must reach the operator, not vanish
            log.exception("%s failed", self.title)
            self.failed.emit(f"{self.title} failed unexpectedly ({type(error).__name__}: {error}).")
        else:
            self.done.emit(result)
        self.ended.emit()


class _Runnable(QRunnable):
    def __init__(self, job: Job) -> None:
        super().__init__()
        self.job = job

    def run(self) -> None:
        self.job.run()


class JobRunner(QObject):
    """Runs jobs one at a time, in order, on its own worker thread."""

    busy_changed = Signal(bool)

    def __init__(self, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.pool = QThreadPool(self)
        self.pool.setMaxThreadCount(1)
        self.jobs: list[Job] = []  # queued or running; kept alive until they end

    @property
    def busy(self) -> bool:
        return bool(self.jobs)

    def submit(
        self,
        title: str,
        call: Callable[[Progress], Any],
        done: Callable[[Any], None] | None = None,
        failed: Callable[[str], None] | None = None,
        progress: Callable[[float, str], None] | None = None,
    ) -> Job:
        """Queue ``call(progress)``; ``done(result)`` or ``failed(sentence)`` run on the GUI thread."""
        job = Job(title, call)
        if done is not None:
            job.done.connect(done)
        if failed is not None:
            job.failed.connect(failed)
        if progress is not None:
            job.progress.connect(progress)
        job.ended.connect(lambda: self._ended(job))
        self.jobs.append(job)
        if len(self.jobs) == 1:
            self.busy_changed.emit(True)
        self.pool.start(_Runnable(job))
        return job

    def _ended(self, job: Job) -> None:
        if job in self.jobs:
            self.jobs.remove(job)
        if not self.jobs:
            self.busy_changed.emit(False)

    def wait(self, timeout_ms: int = -1) -> bool:
        """Block until every queued job has run (closing the wizard); True when they did."""
        return self.pool.waitForDone(timeout_ms)


class ProgressPanel(QWidget):
    """A progress bar and the job's sentence; hidden while nothing runs."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        layout = QHBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        self.bar = QProgressBar()
        self.bar.setRange(0, 1000)
        self.bar.setTextVisible(False)
        self.bar.setMaximumWidth(220)
        self.label = QLabel("")
        self.label.setWordWrap(True)
        layout.addWidget(self.bar)
        layout.addWidget(self.label, 1)
        self.setVisible(False)

    def begin(self, sentence: str) -> None:
        self.bar.setValue(0)
        self.label.setText(sentence)
        self.setVisible(True)

    def update_progress(self, fraction: float, sentence: str) -> None:
        self.bar.setValue(round(1000 * min(max(fraction, 0.0), 1.0)))
        if sentence:
            self.label.setText(sentence)

    def end(self) -> None:
        self.setVisible(False)


def action_button(text: str, tip: str = "") -> QPushButton:
    button = QPushButton(text)
    if tip:
        button.setToolTip(tip)
    return button
