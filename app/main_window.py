"""The operator's main window: one window for the whole site.

The window only shows what its :class:`~app.source.SiteSource` reports and
sends the operator's requests back to it; it computes nothing a node
computes. Docks: Sensors, Parameters (left), World 3D (centre), Top view and
Tracks (right), Log and Outputs (bottom).
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
from PySide6.QtCore import QPoint, Qt
from PySide6.QtGui import QAction, QImage, QKeySequence, QPainter
from PySide6.QtWidgets import QDockWidget, QFileDialog, QLabel, QMainWindow, QWidget

from app.embedded_site import EmbeddedSite
from app.folders import calibrations_folder, recordings_folder, start_in
from app.help_menu import add_help_menu
from app.source import NO_SITE, SiteSource, node_schemas
from app.view_params import VIEW_PARAMS
from app.widgets.insecure_warning import InsecureWarning
from app.widgets.log_panel import LogPanel, QtLogHandler
from app.widgets.outputs_panel import OutputsPanel
from app.widgets.parameters_panel import ParametersPanel
from app.widgets.recording_panel import RecordingOpener, RecordingPanel
from app.widgets.sensors_panel import SensorsPanel
from app.widgets.top_view import TopView
from app.widgets.tracks_table import TracksTable
from app.widgets.world_view import WorldView
from optrack import __version__
from optrack.errors import UserError
from optrack.geometry import backproject_points, transform_points
from optrack.types import DetectionBatch, NetworkCalibration, RGBDFrame, TrackBatch


def preview_cloud(
    frame: RGBDFrame, world_T_camera: np.ndarray, stride: int
) -> tuple[np.ndarray, np.ndarray | None]:
    """A preview frame's points in the world (every ``stride``-th pixel) and their colours."""
    points, pixels = backproject_points(frame.depth_m(), frame.intrinsics, stride)
    colors = None
    if frame.color is not None and frame.color.shape[:2] == frame.depth.shape:
        colors = frame.color[pixels[:, 0], pixels[:, 1]]
    return transform_points(world_T_camera, points), colors


class MainWindow(QMainWindow):
    """Docks around the 3D world; everything fed by one :class:`SiteSource`."""

    def __init__(self, source: SiteSource | None = None) -> None:
        super().__init__()
        self.setWindowTitle(f"optrack {__version__}")
        self.resize(1280, 800)
        self.view_params = VIEW_PARAMS.create()
        self._panels()
        self._arrange_docks()
        self._default_layout = self.saveState()  # View → Reset layout goes back to it
        self.site_label = QLabel(NO_SITE)
        self.site_label.setAlignment(Qt.AlignmentFlag.AlignLeft)
        self.statusBar().addWidget(self.site_label)
        self.progress_label = QLabel("")
        self.statusBar().addPermanentWidget(self.progress_label)
        self.insecure_warning = InsecureWarning(self)  # while the site runs without keys
        self.statusBar().addPermanentWidget(self.insecure_warning)
        self._menus()
        self._connect_panels()

        self.calibration: NetworkCalibration | None = None
        self._connections: list[tuple[Any, Any]] = []
        self._site_clouds: set[str] = set()
        self._stage_reporter: dict[str, str] = {}
        self._max_depth: dict[str, float] = {}  # each sensor's detection.max_distance, m
        self.embedded_site: EmbeddedSite | None = None
        self.wizard = None  # the calibration wizard, once opened (Calibration menu)
        self._site_stop_timeout_s = 0.0
        self._waiting_text = ""
        self._shutting_down = False
        self.source = SiteSource(self)
        self.set_source(source if source is not None else self.source)

    def _panels(self) -> None:
        view = self.view_params
        self.world = WorldView(
            trail_seconds=view.trail_seconds, track_radius=view.track_radius, parent=self
        )
        self.setCentralWidget(self.world)
        self.sensors = SensorsPanel(stale_after=view.status_timeout)
        self.parameters = ParametersPanel()
        self.top_view = TopView(trail_seconds=view.trail_seconds)
        self.tracks_table = TracksTable()
        self.log_panel = LogPanel(max_lines=view.log_lines)
        self.outputs = OutputsPanel()
        self.recording = RecordingPanel()

    def _arrange_docks(self) -> None:
        """Sensors, Parameters and Recording (tabs, left), Top view over Tracks (right), Log
        and Outputs (tabs, bottom)."""
        self.docks: dict[str, QDockWidget] = {}
        left, right, bottom = (
            Qt.DockWidgetArea.LeftDockWidgetArea,
            Qt.DockWidgetArea.RightDockWidgetArea,
            Qt.DockWidgetArea.BottomDockWidgetArea,
        )
        self._dock("Sensors", self.sensors, left)
        self._dock("Parameters", self.parameters, left)
        self._dock("Recording", self.recording, left)
        self._dock("Top view", self.top_view, right)
        self._dock("Tracks", self.tracks_table, right)
        self._dock("Log", self.log_panel, bottom)
        self._dock("Outputs", self.outputs, bottom)
        self.tabifyDockWidget(self.docks["Sensors"], self.docks["Parameters"])
        self.tabifyDockWidget(self.docks["Parameters"], self.docks["Recording"])
        self.docks["Sensors"].raise_()
        self.splitDockWidget(self.docks["Top view"], self.docks["Tracks"], Qt.Orientation.Vertical)
        self.tabifyDockWidget(self.docks["Log"], self.docks["Outputs"])
        self.docks["Log"].raise_()
        self.resizeDocks(
            [self.docks["Sensors"], self.docks["Top view"]], [330, 440], Qt.Orientation.Horizontal
        )
        self.resizeDocks(
            [self.docks["Top view"], self.docks["Tracks"]], [420, 260], Qt.Orientation.Vertical
        )
        self.resizeDocks([self.docks["Log"]], [150], Qt.Orientation.Vertical)
        self.setCorner(Qt.Corner.BottomRightCorner, right)
        self.setCorner(Qt.Corner.BottomLeftCorner, left)

    def _connect_panels(self) -> None:
        """The panels' requests go to the window's source (whichever it is by then)."""
        self.parameters.set_schemas(node_schemas())
        self.parameters.set_schemas(
            {"view": VIEW_PARAMS}, {"view": self.view_params.as_dict()}, local=True
        )
        self.parameters.changed.connect(self._parameters_changed)
        self.parameters.problem.connect(lambda text: self.log_panel.append("warning", text))
        self.outputs.add_requested.connect(
            lambda kind, address: self.source.add_output(kind, address)
        )
        self.outputs.remove_requested.connect(
            lambda kind, address: self.source.remove_output(kind, address)
        )
        self.outputs.enable_requested.connect(
            lambda kind, address, on: self.source.enable_output(kind, address, on)
        )
        self.recording.record_requested.connect(lambda folder: self.source.start_recording(folder))
        self.recording.stop_requested.connect(lambda: self.source.stop_recording())
        self.recording.playback_requested.connect(
            lambda action, args: self.source.playback(action, **args)
        )
        self.recording.open_requested.connect(self._ask_recording)
        self.recording_opener = RecordingOpener(self)
        self.log_handler = QtLogHandler(logging.WARNING)
        self.log_handler.message.connect(self.log_panel.append)
        for name in ("optrack", "app"):
            logging.getLogger(name).addHandler(self.log_handler)

    def _dock(self, title: str, widget: QWidget, area: Qt.DockWidgetArea) -> None:
        dock = QDockWidget(title, self)
        dock.setObjectName(title.replace(" ", "_").lower())
        dock.setWidget(widget)
        self.addDockWidget(area, dock)
        self.docks[title] = dock

    def _menus(self) -> None:
        file_menu = self.menuBar().addMenu("&File")
        open_calibration = QAction("&Open calibration…", self)
        open_calibration.triggered.connect(self._ask_calibration)
        file_menu.addAction(open_calibration)
        open_recording = QAction("Open &recording…", self)
        open_recording.setToolTip("Play a recording through the embedded site (Recording dock).")
        open_recording.triggered.connect(self._ask_recording)
        file_menu.addAction(open_recording)
        self.back_to_live = QAction("&Back to live sensors", self)
        self.back_to_live.setToolTip("Stop playing the recording: the site's own sensors again.")
        self.back_to_live.triggered.connect(lambda: self.recording_opener.back_to_live())
        file_menu.addAction(self.back_to_live)
        file_menu.aboutToShow.connect(
            lambda: self.back_to_live.setEnabled(bool(self.recording.recording_path))
        )
        file_menu.addSeparator()
        load = QAction("&Load parameter preset…", self)
        load.triggered.connect(self.parameters._ask_load)
        save = QAction("&Save parameter preset…", self)
        save.triggered.connect(self.parameters._ask_save)
        quit_action = QAction("&Quit", self)
        # the desktop's Quit keys; Ctrl+Q where the platform names none (no desktop running)
        quit_keys = QKeySequence.keyBindings(QKeySequence.StandardKey.Quit)
        quit_action.setShortcuts(quit_keys or [QKeySequence("Ctrl+Q")])
        quit_action.triggered.connect(self.close)
        for action in (load, save):
            file_menu.addAction(action)
        file_menu.addSeparator()
        file_menu.addAction(quit_action)
        view_menu = self.menuBar().addMenu("&View")
        for dock in self.docks.values():
            view_menu.addAction(dock.toggleViewAction())
        calibration_menu = self.menuBar().addMenu("&Calibration")
        calibrate = QAction("&Calibrate…", self)
        calibrate.setToolTip("Calibrate the site's sensors step by step (the calibration wizard).")
        calibrate.triggered.connect(self.open_wizard)
        calibration_menu.addAction(calibrate)
        add_help_menu(self, view_menu, self.reset_layout)

    def reset_layout(self) -> None:
        """Every dock shown, docked and back where it was when the window opened."""
        for dock in self.docks.values():
            dock.setFloating(False)
            dock.show()
        self.restoreState(self._default_layout)
        self.docks["Sensors"].raise_()
        self.docks["Log"].raise_()

    # ------------------------------------------------------------------ source
    def set_source(self, source: SiteSource) -> None:
        """Listen to ``source`` (and stop listening to the previous one)."""
        for signal, slot in self._connections:
            signal.disconnect(slot)
        self.source = source
        self._site_clouds.clear()
        self._stage_reporter.clear()
        self._max_depth.clear()
        self._connections = [
            (source.tracks, self.show_tracks),
            (source.calibration, self.show_calibration),
            (source.status, self.show_status),
            (source.preview, self.show_preview),
            (source.cloud, self.show_cloud),
            (source.schemas, self.show_schemas),
            (source.log, self.log_panel.append),
            (source.connection, self.show_connection),
            (source.command_reply, self.recording.set_reply),
            (source.skeletons, self.show_skeletons),
        ]
        for signal, slot in self._connections:
            signal.connect(slot)
        self.show_connection(source.describe() if source.connected else "")

    def run_embedded_site(self, site: EmbeddedSite, stop_timeout_s: float) -> None:
        """Own the embedded site: show what it says, stop it when the window closes."""
        self.embedded_site = site
        self._site_stop_timeout_s = stop_timeout_s
        self._waiting_text = "Starting the embedded site…"
        site.line.connect(lambda line: self.log_panel.append("info", line))
        site.progress.connect(self.progress_label.setText)
        site.line.connect(lambda _: self.progress_label.setText(""))
        site.ended.connect(self._embedded_site_ended)
        self.show_connection("")

    def _embedded_site_ended(self, code: int, last_line: str) -> None:
        self._waiting_text = ""
        self.progress_label.setText("")
        if self._shutting_down:
            return
        if code != 0:
            self.log_panel.append(
                "error", f"The embedded site stopped (exit status {code}): {last_line}"
            )
        else:
            self.log_panel.append("warning", "The embedded site stopped.")
        self.show_connection("")

    def show_connection(self, description: str) -> None:
        connected = bool(description)
        text = description if connected else (self._waiting_text or NO_SITE)
        self.site_label.setText(text)
        self.top_view.overlay.show_message("" if connected else NO_SITE)
        self.world.overlay.show_message("" if connected else NO_SITE)
        self.outputs.set_connected(connected, text)
        self.tracks_table.set_site(text if not connected else f"{text}: waiting for tracks")

    def show_skeletons(self, batch: Any) -> None:
        """The skeletons (a ``SkeletonBatch``): drawn in the 3D view, state in the table."""
        self.tracks_table.set_skeletons(batch)
        self.world.set_skeletons(batch)

    def show_tracks(self, batch: TrackBatch) -> None:
        self.tracks_table.set_batch(batch)
        self.top_view.set_batch(batch)
        self.world.set_batch(batch)

    def show_calibration(self, calibration: NetworkCalibration) -> None:
        self.calibration = calibration
        self._draw_calibration()
        for sensor_id in sorted(calibration.sensors):
            self.sensors.add_sensor(sensor_id)

    def _draw_calibration(self) -> None:
        if self.calibration is None:
            return
        max_depth = {
            sensor: self._max_depth.get(sensor, self.view_params.coverage_depth)
            for sensor in self.calibration.sensors
        }
        self.top_view.set_calibration(self.calibration, max_depth)
        self.world.set_calibration(self.calibration, self.view_params.frustum_depth)

    def open_calibration(self, path: str) -> bool:
        """Show a calibration file's cameras (what a site would use), or say why not."""
        from optrack.calibration.files import load_network

        try:
            calibration = load_network(path)
        except UserError as error:
            self.log_panel.append("error", str(error))
            return False
        self.show_calibration(calibration)
        self.log_panel.append(
            "info", f"Showing the {len(calibration.sensors)} cameras of the calibration {path}."
        )
        return True

    def _ask_calibration(self) -> None:
        path, _ = QFileDialog.getOpenFileName(
            self,
            "Open a calibration file",
            start_in(calibrations_folder()),
            "Calibration (*.yaml *.yml)",
        )
        if path:
            self.open_calibration(path)

    def open_recording(self, path: str) -> bool:
        """Play a recording through the embedded site (restarted with its sensors), or say
        why not (Log and Recording dock)."""
        return self.recording_opener.open(path)

    def _ask_recording(self) -> None:
        path = QFileDialog.getExistingDirectory(
            self, "Open a recording (its folder)", start_in(recordings_folder())
        )
        if path:
            self.open_recording(path)

    def show_status(self, node: str, values: dict) -> None:
        self.sensors.set_status(node, values)
        self.recording.set_status(node, values)
        self.outputs.set_status(node, values)
        detection = (values.get("params") or {}).get("detection") or {}
        if values.get("role") == "detector" and "max_distance" in detection:
            depth = float(detection["max_distance"])
            if self._max_depth.get(node) != depth:
                self._max_depth[node] = depth  # a detector node is named after its sensor
                self._draw_calibration()
        # Several nodes may run a stage (one detector per sensor): the panel follows the
        # first that reported it, so that it does not flip between their values.
        for stage, stage_values in (values.get("params") or {}).items():
            if self._stage_reporter.setdefault(stage, node) == node:
                self.parameters.set_values(stage, stage_values)

    def show_preview(self, sensor_id: str, frame: RGBDFrame, batch: DetectionBatch | None) -> None:
        self.sensors.set_preview(sensor_id, frame, batch)
        if sensor_id in self._site_clouds:
            return
        if self.calibration is not None and sensor_id in self.calibration.sensors:
            points, colors = preview_cloud(
                frame, self.calibration.pose(sensor_id), self.view_params.cloud_stride
            )
            self.world.set_cloud(sensor_id, points, colors)

    def show_cloud(self, sensor_id: str, points: np.ndarray) -> None:
        self._site_clouds.add(sensor_id)
        self.world.set_cloud(sensor_id, points, None)

    def show_schemas(self, schemas: dict, values: dict) -> None:
        self.parameters.set_schemas(schemas, values)

    # ------------------------------------------------------- operator's intent
    def _parameters_changed(self, stage: str, values: dict[str, Any]) -> None:
        if stage == "view":
            self._apply_view(values)
        else:
            self.source.set_params(stage, values)

    def _apply_view(self, values: dict[str, Any]) -> None:
        self.view_params.update(values)
        view = self.view_params
        self.top_view.set_trail_seconds(view.trail_seconds)
        self.world.trails.seconds = view.trail_seconds
        self.world.track_radius = view.track_radius
        if "skeletons" in values:
            self.world.set_show_skeletons(bool(view.skeletons))
        self.sensors.stale_after = view.status_timeout
        self.log_panel.max_lines = view.log_lines
        if {"frustum_depth", "coverage_depth"} & set(values):
            self._draw_calibration()

    def screenshot(self) -> QImage:
        """The window as the operator sees it. ``QWidget.grab`` renders the 3D view
        without what pyqtgraph paints over it with QPainter (camera names, track ids),
        so the view's own framebuffer is laid over it, then the view's message."""
        image = self.grab().toImage()
        if self.world.isVisible():
            painter = QPainter(image)
            ratio = image.devicePixelRatio()
            origin = self.world.mapTo(self, QPoint(0, 0))
            frame = self.world.grabFramebuffer()
            frame.setDevicePixelRatio(ratio)
            painter.drawImage(origin, frame)
            if self.world.overlay.isVisible():
                painter.drawPixmap(origin + self.world.overlay.pos(), self.world.overlay.grab())
            painter.end()
        return image

    def open_wizard(self):  # noqa: ANN201 - a CalibrationWizard, imported when asked for
        """Open the calibration wizard against the window's site (its bus), or bring the open
        one to the front; without a site the wizard's first page says so."""
        from app.bus_source import BusSource
        from app.wizard.wizard import CalibrationWizard

        if self.wizard is not None and self.wizard.isVisible():
            self.wizard.raise_()
            self.wizard.activateWindow()
            return self.wizard
        bus = self.source.bus if isinstance(self.source, BusSource) else None
        self.wizard = CalibrationWizard(bus, self)
        self.wizard.guidance_changed.connect(self.top_view.set_guidance)
        self.wizard.guidance_changed.connect(self.world.set_guidance)
        self.wizard.show()
        return self.wizard

    def shut_down(self) -> None:
        """Leave the bus and stop the embedded site; idempotent."""
        if self._shutting_down:
            return
        self._shutting_down = True
        if self.wizard is not None:
            self.wizard.shut_down()  # it uses the source's bus: before the source closes
        for name in ("optrack", "app"):
            logging.getLogger(name).removeHandler(self.log_handler)
        for signal, slot in self._connections:
            signal.disconnect(slot)
        self._connections = []
        self.source.close()
        if self.embedded_site is not None:
            self.statusBar().showMessage("Stopping the embedded site…")
            self.embedded_site.stop(self._site_stop_timeout_s)
        self.recording_opener.close()

    def closeEvent(self, event) -> None:  # noqa: N802 - Qt
        self.shut_down()
        super().closeEvent(event)
