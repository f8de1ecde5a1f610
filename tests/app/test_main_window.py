"""The main window on a real X server (Xvfb) with OpenGL: run by `make test-gl`."""

import os
import subprocess
import sys
import time

import msgspec
import numpy as np
import pytest
import yaml
from PySide6.QtGui import QImage

from optrack.bench.site_process import descendants
from optrack.geometry import make_pose
from optrack.types import (
    Detection,
    DetectionBatch,
    Intrinsics,
    NetworkCalibration,
    RGBDFrame,
    SensorCalibration,
    Track,
    TrackBatch,
)

pytestmark = pytest.mark.opengl

KINECT = Intrinsics(525.0, 525.0, 319.5, 239.5, width=640, height=480)


def image_array(image: QImage) -> np.ndarray:
    """RGB copy of a QImage as an HxWx3 array."""
    image = image.convertToFormat(QImage.Format.Format_RGB888)
    height, width, stride = image.height(), image.width(), image.bytesPerLine()
    raw = np.array(image.constBits(), dtype=np.uint8, copy=True)[: height * stride]
    return raw.reshape(height, stride)[:, : width * 3].reshape(height, width, 3)


@pytest.fixture
def window(qtbot):
    from app.main_window import MainWindow

    window = MainWindow()
    qtbot.addWidget(window)
    window.show()
    qtbot.waitExposed(window)
    return window


def test_main_window_shows_the_floor_grid_in_opengl(window):
    assert window.world.width() > 300 and window.world.height() > 200
    frame = image_array(window.world.grabFramebuffer())
    background = np.array([25, 28, 34])
    grid = np.abs(frame.astype(int) - background).sum(axis=2) > 60
    assert grid.mean() > 0.005  # grid lines were drawn
    assert grid.mean() < 0.5  # and the background is still the background
    assert window.site_label.text() == "No site connected"


def test_without_a_site_every_view_says_so_and_nothing_is_invented(window):
    assert window.top_view.overlay.text() == "No site connected"
    assert window.world.overlay.text() == "No site connected"
    assert window.tracks_table.caption.text() == "No site connected"
    assert window.tracks_table.model.rowCount() == 0
    assert window.top_view.track_positions() == {}
    assert not window.outputs.add_button.isEnabled()
    assert {"detection", "tracking", "view"} <= set(window.parameters.schemas)
    window.parameters.editors["detection"]["voxel_size"].slider.setValue(3)
    assert window.log_panel.lines()[-1].endswith(
        "No site connected: detection.voxel_size was not sent to any node."
    )


def test_window_shows_what_its_source_reports(qtbot, window):
    source = window.source
    looking_down = make_pose(np.diag([1.0, -1.0, -1.0]), [0.0, 0.0, 3.0])
    calibration = NetworkCalibration(
        sensors={
            "ceiling": SensorCalibration(
                world_T_camera=tuple(map(tuple, looking_down)), intrinsics=KINECT
            )
        }
    )
    source.calibration.emit(calibration)
    assert set(window.world.cameras) == {"ceiling"}
    assert window.top_view.footprints["ceiling"].shape == (4, 2)
    assert window.sensors.table.rowCount() == 1
    source.tracks.emit(
        TrackBatch(stamp=1.0, seq=30, tracks=[Track(1, 0.5, 0.25, 1.75, age=1.0, confidence=0.8)])
    )
    assert window.tracks_table.model.rowCount() == 1
    assert window.top_view.track_positions() == {1: (0.5, 0.25)}
    assert set(window.world.people) == {1}
    depth = np.full((48, 64), 3.0, dtype=np.float32)
    preview = RGBDFrame(depth, KINECT.scaled(0.1), sensor_id="ceiling")
    batch = DetectionBatch(
        "ceiling", 1.0, detections=[Detection(0.5, 0.25, 0.9, 1.75, 1.2, box=(30, 20, 6, 10))]
    )
    source.preview.emit("ceiling", preview, batch)
    assert window.sensors.preview.boxes and window.sensors.preview.image is not None
    cloud = window.world.clouds["ceiling"].pos
    np.testing.assert_allclose(cloud[:, 2], 0.0, atol=1e-5)  # a floor 3 m below the camera
    source.status.emit(
        "detector/ceiling",
        {"sensor": "ceiling", "fps": 30.0, "params": {"detection": {"voxel_size": 0.08}}},
    )
    assert window.sensors.status_text("ceiling")["fps"] == "30.0"
    assert window.parameters.editors["detection"]["voxel_size"].value() == 0.08
    source.log.emit("error", "sensor 'ceiling' stopped sending frames; check its cable.")
    assert window.log_panel.lines()[-1].endswith(
        "Error: sensor 'ceiling' stopped sending frames; check its cable."
    )


def test_view_parameters_change_the_window_not_the_nodes(qtbot, window):
    with qtbot.assertNotEmitted(window.source.log):
        window.parameters.edit("view", "trail_seconds", 2.0)
        window.parameters.edit("view", "track_radius", 0.4)
    assert window.top_view.trails.seconds == 2.0 and window.world.trails.seconds == 2.0
    assert window.world.track_radius == 0.4


def test_optrack_gui_starts_its_site_takes_a_screenshot_and_quits(tmp_path, site_config):
    """The default: the window starts the embedded site; quitting stops it, exit status 0,
    and every process the site started (its nodes, the fork server) has ended."""
    shot = tmp_path / "window.png"
    optrack = os.path.join(os.path.dirname(sys.executable), "optrack")
    stderr = tmp_path / "stderr.txt"
    with stderr.open("w") as err:
        process = subprocess.Popen(
            [optrack, "gui", "--config", str(site_config), "--screenshot", str(shot)]
            + ["--quit-after", "3"],
            stdout=subprocess.DEVNULL,
            stderr=err,
        )
        names: dict[int, str] = {}  # every process the site started, by its name
        deadline = time.monotonic() + 120
        while process.poll() is None and time.monotonic() < deadline:
            for pid in descendants(process.pid):
                names[pid] = _comm(pid) if _alive(pid) else names.get(pid, "?")
            time.sleep(0.1)
        code = process.wait(max(0.0, deadline - time.monotonic()))
    assert code == 0, stderr.read_text()
    image = QImage(str(shot))
    assert (image.width(), image.height()) == (1280, 800)
    pixels = image_array(image)
    assert len(np.unique(pixels.reshape(-1, 3), axis=0)) > 10
    assert {"tracker", "kinect2_0"} <= set(names.values()), names  # the site's nodes ran
    # The fork server and multiprocessing's resource tracker end when the launcher does
    # (their pipe from it closes), then tear their imports down (0.4 s on a quiet computer).
    deadline = time.monotonic() + 5.0
    while any(_alive(pid) for pid in names) and time.monotonic() < deadline:
        time.sleep(0.05)
    leftover = {pid: name for pid, name in names.items() if _alive(pid)}
    assert not leftover, f"the embedded site's processes outlived the window: {leftover}"


def _comm(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/comm") as comm:
            return comm.read().strip()
    except FileNotFoundError:
        return "?"


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def test_optrack_gui_without_a_site(tmp_path):
    shot = tmp_path / "window.png"
    optrack = os.path.join(os.path.dirname(sys.executable), "optrack")
    result = subprocess.run(
        [optrack, "gui", "--no-site", "--screenshot", str(shot), "--quit-after", "1"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    assert QImage(str(shot)).width() == 1280


def test_a_calibration_file_shows_its_cameras_without_a_site(window, tmp_path):
    looking_down = make_pose(np.diag([1.0, -1.0, -1.0]), [1.0, 2.0, 3.0])
    path = tmp_path / "network.yaml"
    path.write_text(
        yaml.safe_dump(
            {
                "format": "optrack-calibration",
                "version": 1,
                "sensors": {
                    "door": {
                        "world_T_camera": looking_down.tolist(),
                        "intrinsics": msgspec.to_builtins(KINECT),
                    }
                },
            }
        )
    )
    assert window.open_calibration(str(path))
    assert set(window.world.cameras) == {"door"}
    assert window.top_view.footprints["door"].shape == (4, 2)
    assert window.site_label.text() == "No site connected"  # a file is not a site
    assert not window.open_calibration(str(tmp_path / "missing.yaml"))
    assert "missing.yaml" in window.log_panel.lines()[-1]
    assert "Error:" in window.log_panel.lines()[-1]


def test_help_menu_lists_the_guides_shortcuts_version_and_folders(window):
    from PySide6.QtWidgets import QMenu

    from app.help_menu import about_text, shortcuts_text
    from optrack import __version__

    menus = {m.title().replace("&", ""): m for m in window.menuBar().findChildren(QMenu)}
    assert {"File", "View", "Calibration", "Help", "Guides"} <= set(menus)
    guides = menus["Guides"].actions()
    assert guides[0].text() == "The operator window and the calibration wizard"
    assert all(os.path.isfile(a.data()) for a in guides), [a.data() for a in guides]
    help_titles = [a.text().replace("&", "") for a in menus["Help"].actions()]
    assert help_titles[-2:] == ["Keyboard shortcuts", "About optrack"]
    shortcuts = shortcuts_text(window)
    assert "File → Quit" in shortcuts and "Guides → The operator window" in shortcuts
    about = about_text()
    assert __version__ in about
    assert "optrack-calibrations" in about and "optrack-recordings" in about


def test_view_reset_layout_brings_every_dock_back(qtbot, window):
    from PySide6.QtCore import Qt

    view = next(a.menu() for a in window.menuBar().actions() if a.text().replace("&", "") == "View")
    reset = next(a for a in view.actions() if a.text().replace("&", "") == "Reset layout")
    window.docks["Outputs"].hide()
    window.docks["Tracks"].setFloating(True)
    window.removeDockWidget(window.docks["Top view"])
    reset.trigger()
    qtbot.wait(50)
    assert all(dock.isVisible() for dock in window.docks.values())
    assert not window.docks["Tracks"].isFloating()
    assert window.dockWidgetArea(window.docks["Top view"]) == Qt.DockWidgetArea.RightDockWidgetArea
    assert window.dockWidgetArea(window.docks["Sensors"]) == Qt.DockWidgetArea.LeftDockWidgetArea
