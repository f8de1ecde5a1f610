"""The calibration wizard's last pages: the refinement from one person walking (5,
optional) and the review (6: per-sensor quality; save, export, send)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QComboBox, QFileDialog, QHBoxLayout, QLabel, QSpinBox

from app.folders import calibrations_folder, start_in
from app.wizard.jobs import action_button
from app.wizard.page import DONE_STYLE, WizardPage, rms_text
from app.wizard.widgets import SensorTable, TrajectoryPlot, count_level
from optrack.calibration.quality import CalibrationQuality

if TYPE_CHECKING:
    from optrack.calibration.files import CalibrationFile
    from optrack.calibration.live import LiveState, RefinementReport

__all__ = ["EXPORTS", "RefinementPage", "ReviewPage"]


# ------------------------------------------------------------- 5. refinement


class RefinementPage(WizardPage):
    """Optional: one person walks alone; each sensor's view of them aligns the cameras."""

    def __init__(self, duration_s: float) -> None:
        super().__init__(
            "5. Refinement (optional): one person walks",
            "Ask one person to walk alone through every sensor's view for the time below, "
            "everyone else out of the room. The sensors' trajectories of that person are then "
            "aligned. Next without walking keeps the checkerboard's calibration.",
        )
        row = QHBoxLayout()
        self.duration = QSpinBox()
        self.duration.setRange(10, 600)
        self.duration.setSuffix(" s")
        self.duration.setValue(round(duration_s))
        self.duration.setToolTip("How long the person walks.")
        self.walk_button = action_button("Start walking", "Collect the walker's detections.")
        self.refine_button = action_button(
            "Refine now", "Stop collecting and align the sensors' trajectories."
        )
        row.addWidget(QLabel("Walk for"))
        row.addWidget(self.duration)
        row.addWidget(self.walk_button)
        row.addWidget(self.refine_button)
        self.countdown = QLabel("")
        row.addWidget(self.countdown)
        row.addStretch(1)
        self.body.addLayout(row)
        plots = QHBoxLayout()
        self.before = TrajectoryPlot("Before")
        self.after = TrajectoryPlot("After")
        plots.addWidget(self.before)
        plots.addWidget(self.after)
        self.body.addLayout(plots, 1)
        self.samples = QLabel("")
        self.samples.setWordWrap(True)
        self.figure = QLabel("")
        self.figure.setWordWrap(True)
        self.figure.setStyleSheet(DONE_STYLE)
        self.body.addWidget(self.samples)
        self.body.addWidget(self.figure)
        self.walk_button.clicked.connect(self.start_walk)
        self.refine_button.clicked.connect(self.refine)
        self.timer = QTimer(self)
        self.timer.setInterval(250)
        self.timer.timeout.connect(self._tick)
        self.walking = False
        self.ends_at = 0.0
        self.shown: RefinementReport | None = None  # the report the plots show

    @property
    def report(self) -> RefinementReport | None:
        """The backend's refinement (None until one ran since the last solve)."""
        return self.calibration_wizard.refinement

    def cleanupPage(self) -> None:  # noqa: N802 - Qt
        self._stop_walk()

    def validatePage(self) -> bool:  # noqa: N802 - Qt
        self._stop_walk()
        return True

    def start_walk(self) -> None:
        from time import monotonic

        live = self.calibration_wizard.live
        self.walking = True
        self.ends_at = monotonic() + self.duration.value()
        self.timer.start()
        self._tick()
        self.run(
            "Starting the walk",
            lambda progress: live.start("refinement"),
            failed=lambda _: self._stop_walk(send=False),
        )

    def _tick(self) -> None:
        from time import monotonic

        left = self.ends_at - monotonic()
        if left <= 0:
            self.timer.stop()
            self.countdown.setText("")
            if self.walking:
                self.refine()
            return
        self.countdown.setText(f"{math.ceil(left)} s left")

    def _stop_walk(self, send: bool = True) -> None:
        self.timer.stop()
        self.countdown.setText("")
        if self.walking:
            self.walking = False
            if send:
                live = self.calibration_wizard.live
                self.run("Stopping the walk", lambda progress: live.stop())
        self.update_buttons()

    def refine(self) -> None:
        live = self.calibration_wizard.live
        self._stop_walk()
        self.run(
            "Refining from the walk",
            lambda progress: live.refine(progress),
            self._refined,
            sentence="Aligning the sensors' trajectories…",
        )

    def _refined(self, report: RefinementReport) -> None:
        self.calibration_wizard.poll()  # the backend's state has the report: show_state draws it

    def show_report(self, report: RefinementReport) -> None:
        """Plot the trajectories before and after and say how far the sensors disagree."""
        self.shown = report
        self.before.set_trajectories(report.trajectories_before)
        self.after.set_trajectories(report.trajectories_after)
        # Nothing corrected: the after plot would only repeat the before plot.
        self.after.setVisible(bool(report.corrections))
        refused, board = report.refused, report.board_rms_px
        before = f"{100 * report.error_before_m:.1f} cm on average"
        self.figure.setText(
            (
                f"The sensors disagree on where the person was by {before} before "
                f"refinement and {100 * report.error_after_m:.1f} cm after."
                if report.corrections
                else "Nothing changed: no correction from the walk was applied; the sensors "
                f"disagree on where the person was by {before}."
            )
            + (
                f" Not refined (too few detections): {', '.join(report.skipped)}."
                if report.skipped
                else ""
            )
            + (
                " Kept the checkerboard's pose for "
                + ", ".join(
                    f"{s} (the walk's correction puts its board views {rms:.1f} px off, "
                    f"against {board.get(s, math.nan):.1f} px)"
                    for s, rms in sorted(refused.items())
                )
                + ": the board is the more exact there."
                if refused
                else ""
            )
        )

    def show_state(self, state: LiveState) -> None:
        super().show_state(state)
        if state.refinement_samples:
            counts = ", ".join(f"{s} {n}" for s, n in sorted(state.refinement_samples.items()))
            self.samples.setText(f"Detections of the walker: {counts}.")
        if state.phase == "refinement" and state.walk:
            # The walk so far, as each sensor sees it with the calibration being refined; the
            # after plot comes with the refinement.
            self.before.set_trajectories(state.walk)
            self.after.setVisible(False)
        if state.refinement is not None and state.refinement is not self.shown:
            self.show_report(state.refinement)

    def update_buttons(self) -> None:
        idle = not self.busy
        self.walk_button.setEnabled(idle and not self.walking)
        self.refine_button.setEnabled(idle)
        self.duration.setEnabled(not self.walking)

    def isComplete(self) -> bool:  # noqa: N802 - Qt
        return not self.busy


# ----------------------------------------------------------------- 6. review

EXPORTS = {
    "openptrack": ("OpenPTrack camera_poses.yaml", "camera_poses.yaml"),
    "ros": ("ROS static transforms", "static_transforms.yaml"),
}


class ReviewPage(WizardPage):
    """Per-sensor quality; save, export and send the calibration to the nodes."""

    def __init__(self) -> None:
        super().__init__(
            "6. Review, save and send",
            "Check each sensor's figures. Save the calibration (the previous file is kept as "
            ".bak), export it for other tools if you need to, and send it to the nodes: they "
            "use it from their next frame.",
        )
        self.table = SensorTable(
            [
                ("sensor", "sensor"),
                ("views", "views"),
                ("rms", "RMS (px)"),
                ("refinement", "refinement moved it"),
                ("height", "height (m)"),
            ]
        )
        self.body.addWidget(self.table, 1)
        self.summary = QLabel("")
        self.summary.setWordWrap(True)
        self.body.addWidget(self.summary)
        row = QHBoxLayout()
        self.save_button = action_button("Save…", "Write the calibration file.")
        self.export_choice = QComboBox()
        for key, (title, _) in EXPORTS.items():
            self.export_choice.addItem(title, key)
        self.export_button = action_button("Export…", "Write the calibration for another tool.")
        self.publish_button = action_button(
            "Send to the nodes", "Every node stores the calibration and uses it."
        )
        row.addWidget(self.save_button)
        row.addSpacing(16)
        row.addWidget(self.export_choice)
        row.addWidget(self.export_button)
        row.addSpacing(16)
        row.addWidget(self.publish_button)
        row.addStretch(1)
        self.body.addLayout(row)
        self.done = QLabel("")
        self.done.setWordWrap(True)
        self.done.setStyleSheet(DONE_STYLE)
        self.body.addWidget(self.done)
        self.save_button.clicked.connect(self._ask_save)
        self.export_button.clicked.connect(self._ask_export)
        self.publish_button.clicked.connect(self.publish)
        self.saved: Path | None = None
        self.published = False
        self.outcomes: list[str] = []
        self.file: Any = None  # the CalibrationFile shown

    def initializePage(self) -> None:  # noqa: N802 - Qt
        wizard = self.calibration_wizard
        self.outcomes = []
        self.done.setText("")
        self.file = None
        if wizard.calibration is None:
            self.summary.setText("Nothing solved yet: go back to the ground page and Solve.")
            self.update_buttons()
            return
        live = wizard.live
        self.run(
            "Reading the calibration",
            lambda progress: live.calibration_file(),
            self.show_file,
        )

    def show_file(self, calibration: CalibrationFile) -> None:
        """Per-sensor quality of the calibration as it will be saved."""
        self.file = calibration
        quality = CalibrationQuality.of(calibration.quality)
        self._show_sensors(calibration, quality)
        self.summary.setText(_summary(calibration, quality))
        self.update_buttons()

    def _show_sensors(self, calibration: CalibrationFile, quality: CalibrationQuality) -> None:
        from optrack.geometry import rotation_angle_deg

        fair, good = self.calibration_wizard.view_thresholds("extrinsics")
        rows, levels = {}, {}
        refused = quality.refinement_refused
        for sensor in sorted(calibration.sensors):
            entry = calibration.sensors[sensor]
            row = {
                "views": str(entry.views),
                "rms": rms_text(entry.reprojection_rms_px),
                "height": f"{entry.pose[2, 3]:.2f}",
                "refinement": "kept the board's pose" if sensor in refused else "not refined",
            }
            if entry.refinement is not None:
                delta = np.asarray(entry.refinement, dtype=float)
                row["refinement"] = (
                    f"{100 * np.linalg.norm(delta[:3, 3]):.1f} cm, "
                    f"{rotation_angle_deg(delta, np.eye(4)):.2f}°"
                )
            rows[sensor] = row
            levels[sensor] = count_level(entry.views, fair, good)
        self.table.set_rows(rows, levels)

    def _say(self, sentence: str) -> None:
        self.outcomes.append(sentence)
        self.done.setText(" ".join(self.outcomes))

    def save_to(self, path: str) -> None:
        """Save the calibration to ``path`` (on the worker); say where, and the backup."""
        live = self.calibration_wizard.live

        def saved(written: Path) -> None:
            self.saved = Path(written)
            backup = self.saved.with_name(self.saved.name + ".bak")
            kept = f"; the previous file is kept as {backup.name}" if backup.exists() else ""
            self._say(f"Saved to {self.saved}{kept}.")
            self.update_buttons()

        self.run("Saving the calibration", lambda progress: live.save(path), saved)

    def export_to(self, kind: str, path: str) -> None:
        """Write the saved calibration for another tool (``kind`` in :data:`EXPORTS`)."""
        from optrack.calibration.files import (
            load_calibration,
            openptrack_camera_poses,
            ros_static_transforms,
        )
        from optrack.io.files import atomic_write_text

        source = self.saved

        def export(progress: Any) -> Path:
            calibration = load_calibration(source)
            text = (
                openptrack_camera_poses(calibration)
                if kind == "openptrack"
                else ros_static_transforms(calibration)
            )
            atomic_write_text(Path(path), text)
            return Path(path)

        self.run(
            "Exporting the calibration",
            export,
            lambda written: self._say(f"Exported {EXPORTS[kind][0]} to {written}."),
        )

    def publish(self) -> None:
        live = self.calibration_wizard.live

        def sent(_: Any) -> None:
            self.published = True
            self._say("Sent to the nodes.")

        self.run("Sending the calibration", lambda progress: live.publish(), sent)

    def _ask_save(self) -> None:
        path, _ = QFileDialog.getSaveFileName(
            self,
            "Save the calibration",
            start_in(calibrations_folder(), "calibration.yaml"),
            "Calibration (*.yaml *.yml)",
        )
        if path:
            self.save_to(path)

    def _ask_export(self) -> None:
        kind = self.export_choice.currentData()
        title, name = EXPORTS[kind]
        folder = (
            self.saved.parent if self.saved is not None else Path(start_in(calibrations_folder()))
        )
        path, _ = QFileDialog.getSaveFileName(
            self, f"Export as {title}", str(folder / name), "YAML (*.yaml)"
        )
        if path:
            self.export_to(kind, path)

    def update_buttons(self) -> None:
        ready = not self.busy and self.calibration_wizard.calibration is not None
        self.save_button.setEnabled(ready)
        self.publish_button.setEnabled(ready)
        self.export_button.setEnabled(ready and self.saved is not None)
        self.export_button.setToolTip(
            "Write the calibration for another tool."
            if self.saved is not None
            else "Save the calibration first; the export is made from the saved file."
        )


def _summary(calibration: CalibrationFile, quality: CalibrationQuality) -> str:
    """One paragraph: how many sensors, their RMS, where the world is, the refinement."""
    parts = [f"{len(calibration.sensors)} sensors calibrated"]
    if quality.reprojection_rms_px is not None:
        parts.append(f"reprojection RMS {quality.reprojection_rms_px:.2f} px")
    parts.append(
        f"{quality.floor_views} floor views: the world's origin is on the floor"
        if calibration.world == "floor"
        else f"no floor: the world is the frame of {calibration.world}"
    )
    if quality.refinement_error_after_m is not None:
        before = quality.refinement_error_before_m or math.nan
        parts.append(
            "refined from a walk: the sensors agree within "
            f"{100 * quality.refinement_error_after_m:.1f} cm ({100 * before:.1f} cm before)"
        )
        if quality.refinement_refused:
            parts.append(
                f"{', '.join(quality.refinement_refused)} kept the checkerboard's pose (the "
                "walk's correction contradicted its board views)"
            )
    else:
        parts.append("not refined")
    return "; ".join(parts) + "."
