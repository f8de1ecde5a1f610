"""The Recording dock: record the site's sensors, and steer a recording played through it.

Recording: the operator chooses a folder and presses Record; every detector
node writes its own sensor's frames into that folder on its own computer
(``optrack.runtime.node_recording``; the window never receives a full frame).
The table shows each sensor's frames, size and duration from its node's
status, and its problem as a sentence. Stop closes every recording.

Playback: File → Open recording… (or the dock's button) restarts the
window's embedded site with the recording's sensors as its detector nodes'
sources (:class:`RecordingOpener`), so detection, tracking and the outputs
run on it and the window shows it as live. Pause, Step (one frame on every
sensor) and the speed are commands to the detector nodes; the position, the
duration and each sensor's true frame rate come from their statuses.

Every request runs on a worker thread of the source; its answer comes back on
``SiteSource.command_reply`` (:meth:`RecordingPanel.set_reply`).
"""

from __future__ import annotations

import shutil
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from PySide6.QtCore import QObject, Qt, QTimer, Signal
from PySide6.QtGui import QColor
from PySide6.QtWidgets import (
    QComboBox,
    QFileDialog,
    QGridLayout,
    QGroupBox,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QLineEdit,
    QProgressBar,
    QPushButton,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from app.folders import recordings_folder
from optrack.errors import UserError

# What the playback box says it plays: a recording opened here, the site's own replayed
# sensors (the embedded venue replays its rendering), or live sensors.
LIVE_TEXT = "Live sensors. Open a recording to play it through the site instead."
REPLAYED_TEXT = "Playing the site's own replayed sensors (no recording opened here)."
# The stages a restarted site keeps as the nodes run them (docs/skeleton.md, Recording and
# playback): the skeleton switch and its parameters, so a recording plays back with skeletons.
SKELETON_STAGES = ("skeleton_live", "skeleton", "skeleton_fusion")

__all__ = ["SPEEDS", "RecordingOpener", "RecordingPanel", "default_take_folder", "format_bytes"]

SPEEDS = (0.25, 0.5, 1.0, 2.0, 4.0)
COLUMNS = ("sensor", "frames", "size", "time", "dropped")
COLUMN_TIPS = {
    "frames": "Frames this sensor's node has written into the recording.",
    "size": "Bytes of images written (on the sensor's computer).",
    "time": "Time from the first to the last frame recorded, seconds.",
    "dropped": "Frames left out because the disk could not keep up.",
}
ERROR_COLOR = QColor(200, 40, 40)


def format_bytes(count: float) -> str:
    for unit in ("B", "kB", "MB", "GB"):
        if count < 1000 or unit == "GB":
            return f"{count:.0f} {unit}" if unit == "B" else f"{count:.1f} {unit}"
        count /= 1000.0
    return f"{count:.1f} GB"


def default_take_folder(parent: Path | None = None) -> str:
    """A new take's folder: ``~/optrack-recordings/take-YYYYmmdd-HHMMSS``."""
    root = parent if parent is not None else recordings_folder()
    return str(root / f"take-{time.strftime('%Y%m%d-%H%M%S')}")


class RecordingPanel(QWidget):
    """Record and playback controls (see the module docstring)."""

    record_requested = Signal(str)  # folder
    stop_requested = Signal()
    playback_requested = Signal(str, object)  # action, {arg: value}
    open_requested = Signal()

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self._status: dict[str, dict[str, Any]] = {}
        self._rows: dict[str, int] = {}
        self._pending = ""
        self.recording_path = ""
        self._last_take = ""  # what the last recording became, once stopped

        record_box = self._record_box()
        play_box = self._play_box()

        self.message = QLabel("")
        self.message.setWordWrap(True)
        self.message.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        layout = QVBoxLayout(self)
        layout.addWidget(record_box)
        layout.addWidget(play_box)
        layout.addWidget(self.message)
        layout.addStretch(1)
        self._update_controls()

    def _record_box(self) -> QGroupBox:
        """Record the sensors: the folder, Record/Stop, each sensor's counts and problems."""
        record_box = QGroupBox("Record the sensors")
        self.folder = QLineEdit(default_take_folder())
        self.folder.setToolTip(
            "Each sensor's computer writes its frames into this folder (one take: all the "
            "sensors of a computer in one recording). It must be new, or hold none of these "
            "sensors."
        )
        self.browse = QPushButton("Browse…")
        self.browse.clicked.connect(self._ask_folder)
        self.record_button = QPushButton("● Record")
        self.record_button.setToolTip("Start or stop recording every sensor of the site.")
        self.record_button.clicked.connect(self._record_clicked)
        self.record_state = QLabel("Not recording.")
        self.record_state.setWordWrap(True)
        self.table = QTableWidget(0, len(COLUMNS))
        self.table.setHorizontalHeaderLabels(list(COLUMNS))
        for column, key in enumerate(COLUMNS):
            if key in COLUMN_TIPS:
                self.table.horizontalHeaderItem(column).setToolTip(COLUMN_TIPS[key])
        self.table.verticalHeader().hide()
        self.table.setEditTriggers(QTableWidget.EditTrigger.NoEditTriggers)
        self.table.setWordWrap(False)
        header = self.table.horizontalHeader()
        header.setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)
        header.setStretchLastSection(True)
        self.table.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        self.problems = QLabel("")  # each sensor's recording problem, as a sentence
        self.problems.setWordWrap(True)
        self.problems.setStyleSheet(f"color: {ERROR_COLOR.name()};")
        self._fit_table()
        self._text_color = self.table.palette().text().color()
        folder_row = QHBoxLayout()
        folder_row.addWidget(QLabel("Folder"))
        folder_row.addWidget(self.folder, 1)
        folder_row.addWidget(self.browse)
        button_row = QHBoxLayout()
        button_row.addWidget(self.record_button)
        button_row.addWidget(self.record_state, 1)
        record_layout = QVBoxLayout(record_box)
        record_layout.addLayout(folder_row)
        record_layout.addLayout(button_row)
        record_layout.addWidget(self.table)
        record_layout.addWidget(self.problems)
        return record_box

    def _play_box(self) -> QGroupBox:
        """Play a recording through the site: open, pause, step, speed, position, rates."""
        play_box = QGroupBox("Play a recording through the site")
        self.source_label = QLabel(LIVE_TEXT)
        self.source_label.setWordWrap(True)
        self.open_button = QPushButton("Open recording…")
        self.open_button.setToolTip(
            "Restart the embedded site with a recording's sensors as its detector nodes."
        )
        self.open_button.clicked.connect(self.open_requested)
        self.pause_button = QPushButton("❚❚ Pause")
        self.pause_button.setToolTip("Pause or resume every replayed sensor.")
        self.pause_button.clicked.connect(self._pause_clicked)
        self.step_button = QPushButton("Step ▸")
        self.step_button.setToolTip("While paused: one more frame on every sensor.")
        self.step_button.clicked.connect(lambda: self._request("step"))
        self.speed = QComboBox()
        for speed in SPEEDS:
            self.speed.addItem(f"{speed:g}x", speed)
        self.speed.setCurrentIndex(SPEEDS.index(1.0))
        self.speed.setToolTip("Playback speed, times the recorded pace.")
        self.speed.activated.connect(
            lambda index: self._request("speed", value=float(self.speed.itemData(index)))
        )
        self.position = QProgressBar()
        self.position.setRange(0, 1000)
        self.position.setTextVisible(False)
        self.position.setMaximumHeight(10)
        self.position_label = QLabel("–")
        self.rates = QLabel("")
        self.rates.setWordWrap(True)
        self.rates.setToolTip("Frames each sensor's node processes per second (true rates).")
        source_row = QHBoxLayout()
        source_row.addWidget(self.source_label, 1)
        source_row.addWidget(self.open_button)
        controls = QGridLayout()
        controls.addWidget(self.pause_button, 0, 0)
        controls.addWidget(self.step_button, 0, 1)
        controls.addWidget(QLabel("Speed"), 0, 2, Qt.AlignmentFlag.AlignRight)
        controls.addWidget(self.speed, 0, 3)
        controls.addWidget(self.position, 1, 0, 1, 3)
        controls.addWidget(self.position_label, 1, 3)
        play_layout = QVBoxLayout(play_box)
        play_layout.addLayout(source_row)
        play_layout.addLayout(controls)
        play_layout.addWidget(self.rates)
        return play_box

    # ------------------------------------------------------- operator's intent
    def _ask_folder(self) -> None:
        parent = QFileDialog.getExistingDirectory(
            self, "Folder that will hold the take", str(Path(self.folder.text()).parent)
        )
        if parent:
            self.folder.setText(default_take_folder(Path(parent)))

    @property
    def recording(self) -> bool:
        """True while any detector node says it records."""
        return any(v.get("recording") for v in self._status.values())

    def _record_clicked(self) -> None:
        if self.recording:
            self._pending = "record_stop"
            self.record_state.setText("Stopping…")
            self.stop_requested.emit()
        else:
            folder = self.folder.text().strip()
            if not folder:
                self.show_message("Choose a folder for the recording first.", error=True)
                return
            self._pending = "record_start"
            self.record_state.setText("Starting…")
            self.record_requested.emit(folder)
        self._update_controls()

    def _pause_clicked(self) -> None:
        self._request("resume" if self.paused else "pause")

    def _request(self, action: str, **args: Any) -> None:
        self._pending = action
        self._update_controls()
        self.playback_requested.emit(action, args)

    # ------------------------------------------------------------ site says
    def set_recording_path(self, path: str) -> None:
        """The recording the site now plays ("" for live sensors)."""
        self.recording_path = path
        self._update_controls()

    def reset(self) -> None:
        """Forget the nodes (another site is coming)."""
        self._status.clear()
        self._rows.clear()
        self.table.setRowCount(0)
        self._fit_table()
        self.problems.setText("")
        self._pending = ""
        self._update_controls()

    def set_status(self, node: str, values: dict[str, Any]) -> None:
        if values.get("role") != "detector":
            return
        own = dict(values.get("values") or {})
        own["fps"] = values.get("fps", 0.0)
        own["state"] = values.get("state", "")
        self._status[node] = own
        self._show_row(node, own)
        self._update_controls()

    def _show_row(self, node: str, values: dict[str, Any]) -> None:
        row = self._rows.get(node)
        if row is None:
            row = self._rows[node] = self.table.rowCount()
            self.table.insertRow(row)
            self._fit_table()
        frames = values.get("recording.frames")
        error = str(values.get("recording.error") or "")
        cells = (
            node,
            "" if frames is None else f"{int(frames)}",
            format_bytes(float(values.get("recording.bytes") or 0)) if frames else "",
            f"{float(values.get('recording.seconds') or 0):.1f} s" if frames else "",
            f"{int(values.get('recording.dropped') or 0)}" if frames is not None else "",
        )
        for column, text in enumerate(cells):
            item = self.table.item(row, column)
            if item is None:
                item = QTableWidgetItem()
                self.table.setItem(row, column, item)
            item.setText(text)
            item.setToolTip(error)
            item.setForeground(ERROR_COLOR if error else self._text_color)
        self.problems.setText(
            "\n".join(
                f"{name}: {v.get('recording.error')}"
                for name, v in sorted(self._status.items())
                if v.get("recording.error")
            )
        )

    def _fit_table(self) -> None:
        """As tall as its rows (at least one), so the dock wastes no space."""
        rows = max(1, self.table.rowCount())
        height = self.table.horizontalHeader().sizeHint().height()
        height += rows * self.table.verticalHeader().defaultSectionSize()
        self.table.setFixedHeight(height + 2 * self.table.frameWidth() + 2)

    @property
    def players(self) -> dict[str, dict[str, Any]]:
        """The detector nodes that play a recording, with their status values."""
        return {n: v for n, v in self._status.items() if "playback.paused" in v}

    @property
    def paused(self) -> bool:
        return any(v.get("playback.paused") for v in self.players.values())

    def _update_controls(self) -> None:
        busy = self._pending != ""
        recording = self.recording
        self.record_button.setText("■ Stop" if recording else "● Record")
        self.record_button.setEnabled(not busy and bool(self._status))
        self.folder.setEnabled(not recording)
        self.browse.setEnabled(not recording)
        if not busy:
            self._show_record_state(recording)
        players = self.players
        playing = bool(players)
        paused = self.paused
        self.pause_button.setText("▶ Resume" if paused else "❚❚ Pause")
        self.pause_button.setEnabled(playing and not busy)
        self.step_button.setEnabled(playing and paused and not busy)
        self.speed.setEnabled(playing and not busy)
        path = self.recording_path
        self.source_label.setText(
            f"Playing {path}" if path else REPLAYED_TEXT if playing else LIVE_TEXT
        )
        self.source_label.setToolTip(path)
        if not playing:
            self.position.setValue(0)
            self.position_label.setText("–")
            self.rates.setText("")
            return
        position = max(float(v.get("playback.position_s") or 0) for v in players.values())
        duration = max(float(v.get("playback.duration_s") or 0) for v in players.values())
        self.position.setValue(int(1000 * position / duration) if duration > 0 else 0)
        self.position_label.setText(f"{position:.1f} / {duration:.1f} s")
        speeds = {float(v.get("playback.speed") or 1.0) for v in players.values()}
        if len(speeds) == 1 and not self.speed.view().isVisible():
            speed = speeds.pop()
            if speed in SPEEDS:
                self.speed.setCurrentIndex(SPEEDS.index(speed))
        rates = "  ·  ".join(
            f"{n} {float(v.get('fps') or 0):.1f}" for n, v in sorted(players.items())
        )
        self.rates.setText(f"Frames per second: {rates}")

    def _show_record_state(self, recording: bool) -> None:
        if recording:
            folders = sorted({str(v.get("recording.folder")) for v in self._status.values()})
            count = sum(1 for v in self._status.values() if v.get("recording"))
            self.record_state.setText(f"Recording {count} sensor(s) into {', '.join(folders)}.")
        else:
            self.record_state.setText(self._last_take or "Not recording.")

    def set_reply(self, action: str, ok: bool, sentence: str, result: object) -> None:
        """A source's answer to one of this dock's requests."""
        if action != self._pending and action not in ("record_start", "record_stop"):
            return
        self._pending = ""
        if not ok:
            self.show_message(sentence, error=True)
        elif action == "record_start":
            for node in dict(result):  # type: ignore[call-overload]
                self._status.setdefault(node, {})["recording"] = True  # until its status says
            self.show_message(f"Recording started on {len(result)} sensor(s).")  # type: ignore[arg-type]
        elif action == "record_stop":
            answers = dict(result)  # type: ignore[call-overload]
            for node in answers:
                self._status.setdefault(node, {})["recording"] = False
            folders = sorted({str(r.get("folder")) for r in answers.values()})
            self._last_take = (
                f"Recorded {len(answers)} sensor(s) into {', '.join(folders)} (final counts "
                "in the table)."
            )
            self.record_state.setText(self._last_take)
            self.show_message("")
            self.folder.setText(default_take_folder(Path(self.folder.text()).parent))
        else:
            self.show_message("")
            for node, answer in dict(result).items():  # type: ignore[call-overload]
                values = self._status.setdefault(node, {})
                for key, value in answer.items():
                    values[f"playback.{key}"] = value
        self._update_controls()

    def show_message(self, sentence: str, error: bool = False) -> None:
        self.message.setText(sentence)
        color = ERROR_COLOR.name() if error else self.palette().text().color().name()
        self.message.setStyleSheet(f"color: {color};")


class RecordingOpener(QObject):
    """File → Open recording…: (re)start the window's embedded site with a recording's
    sensors as its detector nodes (``optrack run --headless --recording PATH --loop``),
    and join it. The previous site is stopped without blocking the window."""

    def __init__(self, window: Any) -> None:
        super().__init__(window)
        self.window = window
        self.config: str | None = None  # the site configuration when no site runs yet
        self._written: Path | None = None  # the folder of the configs written for restarts
        self._restarts = 0

    def open(self, path: str) -> bool:
        from optrack.recording import Recording

        window = self.window
        try:
            recording = Recording(path)
        except UserError as error:
            window.log_panel.append("error", str(error))
            window.recording.show_message(str(error), error=True)
            return False
        old = window.embedded_site
        if old is None and window.source.connected:
            sentence = (
                f"This window joined {window.source.describe()} but did not start it, so it "
                f"cannot play a recording there; run 'optrack run --recording {path}' on that "
                "site's computer."
            )
            window.log_panel.append("error", sentence)
            window.recording.show_message(sentence, error=True)
            return False
        window.log_panel.append(
            "info",
            f"Playing {recording.path} ({len(recording.sensor_ids)} sensors: "
            f"{', '.join(recording.sensor_ids)}) through the embedded site: the site restarts "
            "with the recording's sensors, so track IDs start again at 1; the outputs are "
            "kept. File → Back to live sensors returns to the site's own sensors.",
        )
        self._restart(str(recording.path))
        return True

    def back_to_live(self) -> bool:
        """File → Back to live sensors: restart the embedded site with its own sensors
        (the outputs kept); False when no recording plays here."""
        window = self.window
        if window.embedded_site is None or not window.recording.recording_path:
            return False
        window.log_panel.append(
            "info", "Back to live sensors: the embedded site restarts with its own sensors."
        )
        self._restart(None)
        return True

    def _restart(self, path: str | None) -> None:
        """Stop the embedded site (if one runs) and start it again playing ``path``
        (None: its own sensors), with the outputs the window shows now and the skeleton
        stages as its nodes run them."""
        window = self.window
        old = window.embedded_site
        config = self._config_with_outputs(old.config if old is not None else self.config)
        self._leave_source()
        window.recording.set_recording_path(path or "")  # the dock says it at once
        if old is not None and old.running:
            old.ended.disconnect()  # the window's "site stopped" message: not for this stop
            old.ended.connect(lambda *_: self._start(path, config))
            old.process.terminate()
            kill_ms = int(1000 * max(window._site_stop_timeout_s, 1.0))
            QTimer.singleShot(kill_ms, lambda: old.running and old.process.kill())
        else:
            self._start(path, config)

    def _config_with_outputs(self, config: str | None) -> str | None:
        """``config`` with the destinations the Outputs dock shows turned on (those the
        operator added live included) and the skeleton stages as the site's nodes run them
        (switched on live included), written next to the window's other state, so a
        restarted site streams where this one did and fits skeletons as it did."""
        import yaml

        from optrack.outputs.streams import OUTPUT_KINDS
        from optrack.outputs.udp import join_destinations

        window = self.window
        shown = [d for d in window.outputs.destinations if d.get("enabled", True)]
        skeleton = {
            stage: window.parameters.values[stage].as_dict()
            for stage in SKELETON_STAGES
            if stage in window._stage_reporter and stage in window.parameters.values
        }
        if not shown and not skeleton:
            return config
        data = yaml.safe_load(Path(config).read_text(encoding="utf-8")) if config else {}
        data = {**(data or {}), **skeleton}
        if shown:
            outputs = dict(data.get("outputs") or {})
            for kind in OUTPUT_KINDS:
                outputs[kind] = join_destinations(d["address"] for d in shown if d["kind"] == kind)
            data["outputs"] = outputs
        if self._written is None:
            self._written = Path(tempfile.mkdtemp(prefix="optrack-window-"))
        self._restarts += 1
        path = self._written / f"site-{self._restarts}.yaml"
        path.write_text(yaml.safe_dump(data), encoding="utf-8")
        return str(path)

    def close(self) -> None:
        """Remove the configurations written for restarts (the window closes)."""
        if self._written is not None:
            shutil.rmtree(self._written, ignore_errors=True)
            self._written = None

    def _leave_source(self) -> None:
        from app.source import SiteSource

        previous = self.window.source
        self.window.set_source(SiteSource(self.window))
        previous.close()
        self.window.recording.reset()

    def _start(self, path: str | None, config: str | None) -> None:
        from app.bus_source import BusSource
        from app.embedded_site import EmbeddedSite
        from optrack.runtime.config import load_node_config

        window = self.window
        if window._shutting_down:
            return
        settings = load_node_config(config)
        name = str(settings["site"].name)
        command = [sys.executable, "-m", "optrack.cli", "run", "--headless"]
        if config:
            command += ["--config", config]
        if path:
            command += ["--recording", path, "--loop"]
        site = EmbeddedSite(config, window, command=command)
        alive = threading.Event()
        alive.set()
        site.ended.connect(lambda code, last: alive.clear())
        source = BusSource(
            name,
            settings["bus"],
            window,
            retry_while=alive,
            label=(
                f"Playing {Path(path).name} on the embedded site '{name}' "
                "(File → Back to live sensors)"
                if path
                else f"Live sensors of the embedded site '{name}'"
            ),
        )
        window.run_embedded_site(site, stop_timeout_s=3 * float(settings["site"].stop_timeout_s))
        site.start()
        previous = window.source
        window.set_source(source)
        previous.close()
        window.recording.set_recording_path(path or "")
