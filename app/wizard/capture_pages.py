"""The calibration wizard's capture pages: the extrinsics (3, "move the checkerboard")
and the ground (4, "lay the board on the floor", then solve)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QHBoxLayout, QLabel, QSplitter, QWidget

from app.wizard.jobs import action_button
from app.wizard.page import DONE_STYLE, WizardPage, calibrated_network, rms_text
from app.wizard.widgets import (
    CovisibilityGraph,
    SensorImages,
    SensorTable,
    count_level,
    operator_text,
    views_text,
)
from optrack.calibration.overlap import BoardSuggestion
from optrack.types import NetworkCalibration

if TYPE_CHECKING:
    from optrack.calibration.live import LiveState

__all__ = ["ExtrinsicsPage", "FloorPage"]

# The extrinsics page's 3D view looks at the cameras from this many times their spread
# (plus their height), and from no nearer than this.
FRAME_SPREADS = 3.0
FRAME_MIN_DISTANCE_M = 6.0


# ------------------------------------------------------------- 3. extrinsics


class ExtrinsicsPage(WizardPage):
    """Move the board through the room until every sensor is calibrated."""

    def __init__(self, world_view: bool) -> None:
        super().__init__(
            "3. Extrinsics: move the checkerboard",
            "Walk the board through the room. Hold it still wherever two sensors see it at "
            "once (both images show it with coloured corners). A sensor is calibrated, and "
            "turns green in the graph, once it has shared the board with calibrated sensors "
            "at enough places (its status counts them); keep going until every count is "
            "green.",
        )
        splitter = QSplitter(Qt.Orientation.Vertical)
        self.images = SensorImages(columns=3)
        splitter.addWidget(self.images)
        lower = QWidget()
        row = QHBoxLayout(lower)
        row.setContentsMargins(0, 0, 0, 0)
        self.table = SensorTable(
            [
                ("sensor", "sensor"),
                ("views", "views"),
                ("rms", "RMS (px)"),
                ("capture", "searches/s"),
                ("status", "status"),
            ]
        )
        self.table.setMinimumWidth(300)
        self.table.horizontalHeaderItem(3).setToolTip(
            "How often the sensor's node searches its image for the board (a few per second "
            "are needed; a slow node gives few views)."
        )
        self.graph = CovisibilityGraph()
        row.addWidget(self.table, 3)
        row.addWidget(self.graph, 2)
        self.world = None
        if world_view:
            from app.widgets.world_view import WorldView

            self.world = WorldView(floor_size_m=8.0)
            self.world.setMinimumSize(260, 200)
            row.addWidget(self.world, 3)
        splitter.addWidget(lower)
        splitter.setStretchFactor(0, 3)
        splitter.setStretchFactor(1, 2)
        splitter.setSizes([380, 280])
        self.body.addWidget(splitter, 1)
        self.rms = QLabel("")
        self.body.addWidget(self.rms)
        self.restart_button = action_button(
            "Start over", "Forget this phase's views and capture again."
        )
        self.restart_button.clicked.connect(self.start_capture)
        self.body.addWidget(self.restart_button, 0, Qt.AlignmentFlag.AlignLeft)
        self.all_calibrated = False
        self.capturing = False
        self._drawn: dict[str, tuple] = {}
        self.last_state: LiveState | None = None
        self.guidance: BoardSuggestion | None = None  # drawn in the views (site's frame)

    def initializePage(self) -> None:  # noqa: N802 - Qt
        self.images.set_sensors(self.calibration_wizard.sensors)
        self.all_calibrated = False
        self.start_capture()

    def start_capture(self) -> None:
        self.all_calibrated = False
        self.completeChanged.emit()
        self.start_phase("extrinsics", "Starting the board capture")

    def cleanupPage(self) -> None:  # noqa: N802 - Qt
        self.stop_capture()
        self.show_guidance(None)

    def validatePage(self) -> bool:  # noqa: N802 - Qt
        self.stop_capture()
        self.show_guidance(None)
        return True

    def show_guidance(self, guidance: BoardSuggestion | None) -> None:
        """Draw where the backend suggests holding the board (this page's 3D view, in the
        calibration's frame; the main window's views, in the site's, via the wizard)."""
        same = (guidance is None) == (self.guidance is None) and (
            guidance is None
            or (guidance.sensor, guidance.partners, guidance.center.round(3).tobytes())
            == (
                self.guidance.sensor,
                self.guidance.partners,
                self.guidance.center.round(3).tobytes(),
            )
        )
        if same:
            return
        self.guidance = guidance
        if self.world is not None:
            self.world.set_guidance(guidance.in_frame() if guidance is not None else None)
        self.calibration_wizard.guidance_changed.emit(guidance)

    def show_state(self, state: LiveState) -> None:
        super().show_state(state)
        if state.phase != "extrinsics":
            return
        self.last_state = state
        wizard = self.calibration_wizard
        fair, good = wizard.view_thresholds("extrinsics")
        rows, levels = {}, {}
        for sensor in wizard.sensors:
            live = state.sensors.get(sensor)
            if live is None:
                rows[sensor] = {"status": "no views from its node"}
                levels[sensor] = "red"
                continue
            status = "calibrated" if live.settled else "not yet"
            if live.calibrated and not live.settled:  # joined, on too little shared evidence
                status = f"{live.shared_poses} of {live.shared_needed} shared views"
            if live.calibrated and live.parent:
                status += f" (via {live.parent})"
            rows[sensor] = {
                "views": str(live.views),
                "rms": rms_text(live.rms_px),
                "capture": f"{live.capture_hz:.1f}",
                "status": status,
            }
            levels[sensor] = count_level(live.views, fair, good)
            self.images.set_view(
                sensor,
                live.image,
                live.board_seen,
                caption=f"{sensor}: {views_text(live.views)}" + (" ✓" if live.settled else ""),
            )
        self.table.set_rows(rows, levels)
        # calibrated: on enough shared board poses (calibration_live.min_shared_poses)
        calibrated = {s for s, live in state.sensors.items() if live.settled}
        self.graph.set_graph(wizard.sensors, calibrated, state.covisibility, (fair, good))
        rms = [live.rms_px for live in state.sensors.values() if live.rms_px is not None]
        self.rms.setText(
            f"Reprojection RMS: {max(rms):.2f} px at worst, {np.mean(rms):.2f} px on average "
            f"({len(calibrated)} of {len(wizard.sensors)} sensors calibrated)."
            if rms
            else f"{len(calibrated)} of {len(wizard.sensors)} sensors calibrated."
        )
        if self.world is not None:
            drawn = {
                s: live.world_T_camera.round(3).tobytes()
                for s, live in state.sensors.items()
                if live.calibrated and live.world_T_camera is not None
            }
            if drawn != self._drawn:
                newcomers = set(drawn) != set(self._drawn)
                self._drawn = drawn
                network = calibrated_network(state)
                self.world.set_calibration(network, wizard.view_params.frustum_depth)
                if newcomers and network.sensors:
                    self._frame_cameras(network)  # a camera joined: keep them all in view
        self.show_guidance(
            state.guidance if state.guidance is not None and state.guidance.found else None
        )
        everything = bool(wizard.sensors) and set(wizard.sensors) <= calibrated
        if everything != self.all_calibrated:
            self.all_calibrated = everything
            self.completeChanged.emit()

    def _frame_cameras(self, network: NetworkCalibration) -> None:
        """Look at the floor under the calibrated cameras, from far enough to see them all."""
        from PySide6.QtGui import QVector3D

        centres = np.array([sensor.pose[:3, 3] for sensor in network.sensors.values()])
        middle = centres.mean(axis=0)
        spread = float(np.linalg.norm(centres - middle, axis=1).max())
        self.world.setCameraPosition(
            pos=QVector3D(float(middle[0]), float(middle[1]), 0.0),
            distance=max(FRAME_MIN_DISTANCE_M, FRAME_SPREADS * spread + float(middle[2])),
        )

    def update_buttons(self) -> None:
        self.restart_button.setEnabled(not self.busy)

    def isComplete(self) -> bool:  # noqa: N802 - Qt
        return self.all_calibrated and not self.busy


# ------------------------------------------------------------------ 4. floor


class FloorPage(WizardPage):
    """Lay the board on the floor (one or several places), then solve everything."""

    def __init__(self) -> None:
        super().__init__(
            "4. Ground: lay the board on the floor",
            "Lay the board flat on the floor where the most sensors see it, printed face up, "
            "and press Capture; step out of the way. Several places (press Capture again for "
            "each) make the floor more exact. Then Solve: it adjusts every camera to all views.",
        )
        row = QHBoxLayout()
        self.capture_button = action_button(
            "Capture a floor place", "Capture the board lying at its current place on the floor."
        )
        self.stop_button = action_button("Stop")
        self.solve_button = action_button(
            "Solve", "Bundle adjustment over every view and floor board; the world on the floor."
        )
        for button in (self.capture_button, self.stop_button, self.solve_button):
            row.addWidget(button)
        row.addStretch(1)
        self.body.addLayout(row)
        self.images = SensorImages(columns=3)
        self.body.addWidget(self.images, 1)
        self.floor_views = QLabel("Floor views: 0")
        self.solved = QLabel("")
        self.solved.setWordWrap(True)
        self.solved.setStyleSheet(DONE_STYLE)
        self.body.addWidget(self.floor_views)
        self.body.addWidget(self.solved)
        self.capture_button.clicked.connect(self.capture_place)
        self.stop_button.clicked.connect(self.stop_capture)
        self.solve_button.clicked.connect(self.solve)
        self.capturing = False
        self.floor_count = 0

    def initializePage(self) -> None:  # noqa: N802 - Qt
        self.images.set_sensors(self.calibration_wizard.sensors)
        self.update_buttons()

    def cleanupPage(self) -> None:  # noqa: N802 - Qt
        self.stop_capture()

    def capture_place(self) -> None:
        self.start_phase("floor", "Starting the floor capture")

    def solve(self) -> None:
        live = self.calibration_wizard.live
        self.stop_capture()
        self.run(
            "Solving the network",
            lambda progress: live.solve(progress),
            self._solved,
            sentence="Adjusting every camera to all views…",
        )

    def _solved(self, calibration: NetworkCalibration) -> None:
        self.calibration_wizard.poll()  # the backend's state has the solve now
        rms = [s.reprojection_rms_px for s in calibration.sensors.values()]
        rms = [r for r in rms if r is not None]
        worst = f"; reprojection RMS {max(rms):.2f} px at worst" if rms else ""
        world = (
            "the world's origin is on the floor"
            if self.floor_count
            else "no board lay on the floor: the world is the first camera's frame"
        )
        self.solved.setText(f"Solved {len(calibration.sensors)} cameras{worst}; {world}.")
        self.completeChanged.emit()

    def show_state(self, state: LiveState) -> None:
        super().show_state(state)
        self.floor_count = state.floor_views
        operator = f" ({operator_text(state.operator)})" if state.operator else ""
        self.floor_views.setText(f"Floor views: {state.floor_views}{operator}")
        if state.phase != "floor":
            return
        for sensor in self.calibration_wizard.sensors:
            live = state.sensors.get(sensor)
            if live is not None:
                on_floor = ", on the floor" if live.on_floor else ""
                self.images.set_view(
                    sensor,
                    live.image,
                    live.board_seen,
                    caption=f"{sensor}{on_floor}",
                )

    def update_buttons(self) -> None:
        idle = not self.busy
        self.capture_button.setEnabled(idle)
        self.stop_button.setEnabled(idle and self.capturing)
        self.solve_button.setEnabled(idle)

    def isComplete(self) -> bool:  # noqa: N802 - Qt
        return not self.busy and self.calibration_wizard.solved is not None
