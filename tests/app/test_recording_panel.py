"""The Recording dock against real detector nodes on a loopback bus (no display needed):
clicks record the site's sensors, pause, step and speed their playback; refusals come
back as sentences in the dock."""

from __future__ import annotations

import threading

import pytest

from app.bus_source import BusSource
from app.source import SiteSource
from app.widgets.recording_panel import RecordingPanel, format_bytes
from optrack.detection.params import detection_params
from optrack.net import BUS_PARAMS, Bus
from optrack.net.clock import CLOCK_PARAMS, ClockServer, ClockSync
from optrack.recording import Recording
from optrack.runtime.calibration_store import CalibrationStore
from optrack.runtime.config import NODE_PARAMS
from optrack.runtime.detector_node import DetectorNode
from optrack.runtime.replay import LiveReplay
from optrack.runtime.venue import venue_recording
from optrack.types import DetectionBatch

from .conftest import VENUE, free_port

SENSORS = ("kinect2_0", "kinect2_1")


class NobodyHere:
    """Finds nobody: the nodes keep the replay's pace on a busy computer."""

    def process(self, frame):
        return DetectionBatch(sensor_id=frame.sensor_id, stamp=frame.timestamp)


@pytest.fixture
def small_site(tmp_path):
    """A hub and two detector nodes replaying the embedded venue (started paused), as
    threads of this process; yields (nodes, bus params)."""
    venue = venue_recording(VENUE["scenario"], VENUE["seed"], VENUE["venue_seconds"])
    params = BUS_PARAMS.create({"local_port": free_port(), "connect_timeout_s": 5.0})
    hub = Bus("rectest", "tracker", params, host=True)
    ClockServer(hub)
    nodes, threads, buses = {}, [], [hub]
    for sensor in SENSORS:
        bus = Bus("rectest", sensor, params)
        buses.append(bus)
        replay = LiveReplay(venue, sensor, loop="restart", paused=True)
        replay.open()
        node = DetectorNode(
            bus,
            replay,
            detection_params("kinect2"),
            NODE_PARAMS.create(
                {"preview_hz": 0.0, "status_period_s": 0.2, "data_folder": str(tmp_path)}
            ),
            ClockSync(bus, CLOCK_PARAMS.create()),
            CalibrationStore(tmp_path / "state" / sensor),
            factory=lambda info, pose, detection: NobodyHere(),
        )
        replay.streams = ("depth",)
        thread = threading.Thread(target=node.run, daemon=True)
        thread.start()
        nodes[sensor], _ = node, threads.append(thread)
    yield nodes, params
    for node in nodes.values():
        node.stop()
    for thread in threads:
        thread.join(10)
    for bus in reversed(buses):
        bus.close()


@pytest.fixture
def dock(qtbot, small_site):
    """The dock wired to a bus source as the main window wires it."""
    nodes, params = small_site
    panel = RecordingPanel()
    qtbot.addWidget(panel)
    source = BusSource("rectest", params)
    panel.record_requested.connect(source.start_recording)
    panel.stop_requested.connect(source.stop_recording)
    panel.playback_requested.connect(lambda action, args: source.playback(action, **args))
    source.status.connect(panel.set_status)
    source.command_reply.connect(panel.set_reply)
    qtbot.waitUntil(lambda: set(panel._status) == set(SENSORS), timeout=15000)
    yield panel, nodes
    source.close()


def frames(nodes) -> dict[str, int]:
    return {name: node.frames for name, node in nodes.items()}


def test_record_click_records_every_sensor_and_stop_closes_a_readable_take(qtbot, dock, tmp_path):
    panel, nodes = dock
    panel.pause_button.click()  # the replays start paused: play them
    qtbot.waitUntil(lambda: min(frames(nodes).values()) > 0, timeout=5000)
    take = tmp_path / "take"
    panel.folder.setText(str(take))
    panel.record_button.click()
    qtbot.waitUntil(
        lambda: "Recording 2 sensor(s) into" in panel.record_state.text(), timeout=10000
    )
    assert panel.record_button.text() == "■ Stop"
    qtbot.waitUntil(lambda: all(n.recorder.frames >= 5 for n in nodes.values()), timeout=10000)
    qtbot.waitUntil(lambda: int(panel.table.item(0, 1).text() or 0) > 0, timeout=5000)
    assert panel.table.item(0, 2).text().endswith(("kB", "MB"))
    panel.record_button.click()
    qtbot.waitUntil(lambda: panel.record_state.text().startswith("Recorded"), timeout=10000)
    qtbot.waitUntil(
        lambda: all(n.recorder.result()["closed"] for n in nodes.values()), timeout=20000
    )
    recording = Recording(take)
    assert sorted(recording.sensor_ids) == list(SENSORS)
    for sensor in SENSORS:
        count = recording.count(sensor)
        row = panel._rows[sensor]
        # the dock shows the node's status: the same count as what reads back
        qtbot.waitUntil(
            lambda r=row, c=count: panel.table.item(r, 1).text() == str(c), timeout=5000
        )
        assert count >= 5
    assert panel.record_button.text() == "● Record"
    assert panel.folder.text() != str(take)  # a new take's folder is proposed


def test_pause_step_and_speed_from_the_dock_reach_every_sensor(qtbot, dock):
    panel, nodes = dock
    assert panel.pause_button.text() == "▶ Resume"  # the site resumes a recording it starts
    panel.pause_button.click()
    qtbot.waitUntil(lambda: min(frames(nodes).values()) >= 10, timeout=10000)
    qtbot.waitUntil(lambda: panel.pause_button.isEnabled(), timeout=5000)
    panel.pause_button.click()
    qtbot.waitUntil(lambda: panel.step_button.isEnabled(), timeout=5000)
    qtbot.wait(300)
    held = frames(nodes)
    qtbot.wait(1000)
    assert frames(nodes) == held
    assert panel.pause_button.text() == "▶ Resume"
    panel.step_button.click()
    qtbot.waitUntil(lambda: all(n.frames == held[k] + 1 for k, n in nodes.items()), timeout=5000)
    qtbot.wait(400)
    assert frames(nodes) == {k: v + 1 for k, v in held.items()}
    panel.speed.setCurrentIndex(panel.speed.findData(2.0))
    panel.speed.activated.emit(panel.speed.currentIndex())
    qtbot.waitUntil(lambda: all(n.sensor.speed == 2.0 for n in nodes.values()), timeout=5000)
    qtbot.waitUntil(lambda: "/" in panel.position_label.text(), timeout=5000)
    assert panel.position_label.text().endswith(f"/ {nodes['kinect2_0'].sensor.length:.1f} s")


def test_a_refusal_comes_back_as_a_sentence_in_the_dock(qtbot, dock, tmp_path):
    panel, _ = dock
    a_file = tmp_path / "notes.txt"
    a_file.write_text("not a folder")
    panel.folder.setText(str(a_file))
    panel.record_button.click()
    qtbot.waitUntil(lambda: "is a file" in panel.message.text(), timeout=10000)
    assert panel.record_button.text() == "● Record" and panel.record_button.isEnabled()


def test_without_a_site_the_dock_says_nothing_was_started(qtbot):
    panel = RecordingPanel()
    qtbot.addWidget(panel)
    source = SiteSource()
    panel.record_requested.connect(source.start_recording)
    source.command_reply.connect(panel.set_reply)
    panel._pending = "record_start"
    panel.record_requested.emit("/tmp/take")
    assert panel.message.text() == "No site connected: no recording was started."
    assert not panel.record_button.isEnabled()  # no detector node: nothing to record


def test_sizes_read_as_an_operator_expects():
    assert [format_bytes(n) for n in (512, 2_500, 3_400_000, 7_100_000_000)] == [
        "512 B",
        "2.5 kB",
        "3.4 MB",
        "7.1 GB",
    ]


def test_the_playback_box_says_what_plays_never_nothing_beside_a_running_bar(qtbot):
    """The embedded venue replays its rendering: its nodes report a playback position
    with no recording opened here; the box says what plays, beside the running bar."""
    from app.widgets.recording_panel import LIVE_TEXT, REPLAYED_TEXT

    panel = RecordingPanel()
    qtbot.addWidget(panel)
    assert panel.source_label.text() == LIVE_TEXT
    panel.set_status(
        "kinect2_0",
        {
            "role": "detector",
            "fps": 12.0,
            "values": {
                "playback.paused": False,
                "playback.position_s": 5.0,
                "playback.duration_s": 20.0,
            },
        },
    )
    assert panel.pause_button.isEnabled() and panel.position.value() == 250
    assert panel.source_label.text() == REPLAYED_TEXT
    assert "nothing to play" not in panel.source_label.text()
    panel.set_recording_path("/data/take-1")
    assert panel.source_label.text() == "Playing /data/take-1"


def test_file_dialogs_start_in_the_users_optrack_folders(qtbot, monkeypatch, tmp_path):
    """The wizard's Save…, File → Open calibration… and Open recording… start in
    ~/optrack-calibrations and ~/optrack-recordings (made when missing), never in the
    folder the program was started from."""
    from PySide6.QtWidgets import QFileDialog

    from app.main_window import MainWindow
    from app.wizard.wizard import CalibrationWizard

    monkeypatch.setenv("HOME", str(tmp_path))
    asked: list[str] = []

    def file_dialog(parent, title, start, *rest):  # the operator cancels
        asked.append(start)
        return "", ""

    def folder_dialog(parent, title, start, *rest):
        asked.append(start)
        return ""

    monkeypatch.setattr(QFileDialog, "getSaveFileName", file_dialog)
    monkeypatch.setattr(QFileDialog, "getOpenFileName", file_dialog)
    monkeypatch.setattr(QFileDialog, "getExistingDirectory", folder_dialog)
    wizard = CalibrationWizard(None, world_view=False)
    qtbot.addWidget(wizard)
    wizard.review_page._ask_save()
    assert asked[-1] == str(tmp_path / "optrack-calibrations" / "calibration.yaml")
    assert (tmp_path / "optrack-calibrations").is_dir()
    window = MainWindow.__new__(MainWindow)  # the dialogs only: no site, no GL
    MainWindow._ask_calibration(window)
    assert asked[-1] == str(tmp_path / "optrack-calibrations")
    MainWindow._ask_recording(window)
    assert asked[-1] == str(tmp_path / "optrack-recordings")
