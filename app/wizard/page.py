"""The calibration wizard's page: what every one of its six pages has.

Every page shows what the live calibration's state says (the wizard polls
``LiveCalibration.state()`` and hands each snapshot to the page on screen:
:meth:`WizardPage.show_state`) and sends the operator's requests to the
backend through the wizard's job runner, off the GUI thread. What goes wrong
is shown on the page as the backend's sentence (:meth:`WizardPage.show_error`).
The pages keep no calibration of their own: what was solved, refined or
calibrated is in the backend's state (:class:`~optrack.calibration.live.LiveState`).

The pages: :mod:`app.wizard.setup_pages` (network and checkerboard,
intrinsics), :mod:`app.wizard.capture_pages` (extrinsics, floor),
:mod:`app.wizard.result_pages` (refinement, review).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from PySide6.QtWidgets import QLabel, QVBoxLayout, QWizardPage

from app.wizard.jobs import ProgressPanel
from optrack.types import NetworkCalibration, SensorCalibration, as_matrix4

if TYPE_CHECKING:
    from app.wizard.wizard import CalibrationWizard
    from optrack.calibration.live import LiveState

__all__ = [
    "DONE_STYLE",
    "ERROR_STYLE",
    "MESSAGE_STYLE",
    "NO_SESSION",
    "WizardPage",
    "calibrated_network",
    "rms_text",
]

ERROR_STYLE = "QLabel { color: #b00020; font-weight: bold; }"
MESSAGE_STYLE = "QLabel { color: #1b4f8a; }"
DONE_STYLE = "QLabel { color: #1e6b2a; }"
NO_SESSION = (
    "The wizard is not connected to a site's sensors; go back to the first page and look for "
    "them again."
)


def rms_text(value: float | None) -> str:
    """A reprojection RMS in a table cell ("" before it is known)."""
    return "" if value is None else f"{value:.2f}"


def calibrated_network(state: LiveState) -> NetworkCalibration:
    """The sensors of a live state that have a pose, as a calibration to draw."""
    return NetworkCalibration(
        sensors={
            sensor: SensorCalibration(
                world_T_camera=as_matrix4(live.world_T_camera), intrinsics=live.intrinsics
            )
            for sensor, live in state.sensors.items()
            if live.calibrated and live.world_T_camera is not None
        }
    )


class WizardPage(QWizardPage):
    """A page with an instruction, the backend's message, an error line and a progress bar.

    Subclasses put their widgets in :attr:`body` and override :meth:`show_state`.
    """

    def __init__(self, title: str, instruction: str) -> None:
        super().__init__()
        self.setTitle(title)
        layout = QVBoxLayout(self)
        self.instruction = QLabel(instruction)
        self.instruction.setWordWrap(True)
        layout.addWidget(self.instruction)
        self.body = QVBoxLayout()
        layout.addLayout(self.body, 1)
        self.message = QLabel("")
        self.message.setWordWrap(True)
        self.message.setStyleSheet(MESSAGE_STYLE)
        self.error = QLabel("")
        self.error.setWordWrap(True)
        self.error.setStyleSheet(ERROR_STYLE)
        self.error.setVisible(False)
        self.progress = ProgressPanel()
        layout.addWidget(self.message)
        layout.addWidget(self.error)
        layout.addWidget(self.progress)
        self.busy = False
        self.pending = 0  # jobs submitted by run() and not ended yet

    @property
    def calibration_wizard(self) -> CalibrationWizard:
        return self.wizard()  # type: ignore[return-value]

    # ------------------------------------------------------------ feedback
    def show_state(self, state: LiveState) -> None:
        """Draw a snapshot of the live calibration (called ~5 times a second)."""
        self.message.setText(state.message)

    def show_error(self, sentence: str) -> None:
        self.error.setText(sentence)
        self.error.setVisible(bool(sentence))

    capturing: Any = False

    def start_phase(self, phase: str, title: str) -> None:
        """Ask the site to capture for ``phase`` (on the worker); ``capturing`` says so."""
        live = self.calibration_wizard.live
        self.capturing = True
        self.run(
            title,
            lambda progress: live.start(phase),
            failed=lambda _: setattr(self, "capturing", False),
        )

    def stop_capture(self) -> None:
        if self.capturing:
            live = self.calibration_wizard.live
            self.capturing = False
            self.run("Stopping the capture", lambda progress: live.stop())

    def run(
        self,
        title: str,
        call: Callable[[Any], Any],
        done: Callable[[Any], None] | None = None,
        sentence: str = "",
        failed: Callable[[str], None] | None = None,
    ) -> None:
        """Run ``call(progress)`` on the wizard's worker; the progress bar shows ``sentence``
        until it ends; its error sentence is shown on the page."""
        if self.calibration_wizard.live is None:
            self.show_error(NO_SESSION)
            if failed is not None:
                failed(NO_SESSION)
            return
        self.show_error("")
        # Busy until every job asked for has ended (Solve after a capture queues "stop" then
        # "solve": the page is not done when the first one ends).
        self.pending += 1
        self.set_busy(True)
        if sentence:
            self.progress.begin(sentence)

        def ended() -> None:
            self.pending -= 1
            if not self.pending:
                self.progress.end()
                self.set_busy(False)

        def finished(result: Any) -> None:
            ended()
            if done is not None:
                done(result)

        def refused(text: str) -> None:
            ended()
            self.show_error(text)
            if failed is not None:
                failed(text)

        self.calibration_wizard.runner.submit(
            title, call, finished, refused, self.progress.update_progress
        )

    def set_busy(self, busy: bool) -> None:
        self.busy = busy
        self.update_buttons()
        self.completeChanged.emit()

    def update_buttons(self) -> None:
        """Enable the page's buttons for what can be done now."""
