"""Make the screenshots of docs/gui.md and the README (run under Xvfb):

    QT_QPA_PLATFORM=xcb xvfb-run -a -s "-screen 0 1280x1024x24" \\
        .venv/bin/python docs/screenshots/make_screenshots.py

Every picture shows real values: the window without a site, the Parameters
panel built from optrack's schemas, and the Sensors dock showing PCL's real
Kinect frame of five people with the boxes optrack's detector finds in it
(from ../shared/data). The main window against the embedded site is taken
by the application itself:

    QT_QPA_PLATFORM=xcb xvfb-run -a -s "-screen 0 1280x1024x24" \
        .venv/bin/optrack gui --screenshot docs/screenshots/main-window.png --quit-after 30
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parent.parent
SHARED_DATA = REPO.parent / "shared" / "data"
sys.path.insert(0, str(REPO))


def five_people():
    """PCL's five-people Kinect frame and what optrack's detector finds in it."""
    from optrack.detection.params import detection_params
    from optrack.detection.pipeline import PeopleDetector
    from optrack.io.pcd import read_pcd
    from optrack.types import Intrinsics, RGBDFrame

    kinect = Intrinsics(525.0, 525.0, 319.5, 239.5, width=640, height=480)
    cloud = read_pcd(SHARED_DATA / "pcl" / "five_people.pcd")
    points = cloud.points.reshape(480, 640, 3)
    colors = cloud.colors.reshape(480, 640, 3)
    detector = PeopleDetector(
        detection_params("pcl"), ground=(-0.0103586, 0.997011, 0.0765573, -1.26614)
    )
    batch = detector.process_cloud(points, kinect, color=colors)
    depth = points[..., 2].astype(np.float32)
    return RGBDFrame(depth, kinect, sensor_id="corridor", color=colors), batch


def main() -> int:
    from PySide6.QtCore import QEventLoop, QTimer
    from PySide6.QtWidgets import QApplication

    from app.main import configure_qt

    configure_qt()
    app = QApplication([sys.argv[0]])
    from app.main_window import MainWindow
    from app.widgets.sensors_panel import SensorsPanel

    def settle(ms: int = 1500) -> None:
        """Let the window lay itself out and paint, as it does on screen."""
        loop = QEventLoop()
        QTimer.singleShot(ms, loop.quit)
        loop.exec()

    window = MainWindow()
    window.log_panel.append("info", "No site connected (--no-site).")
    window.show()
    settle()
    window.screenshot().save(str(HERE / "main-window-no-site.png"))
    window.docks["Parameters"].raise_()
    window.parameters.pages.setCurrentIndex(0)
    settle()
    window.docks["Parameters"].grab().save(str(HERE / "parameters.png"))
    window.close()

    if SHARED_DATA.is_dir():
        frame, batch = five_people()
        panel = SensorsPanel()
        panel.resize(360, 560)
        panel.show()
        panel.set_preview("corridor", frame, batch)
        panel.stream_choice.setCurrentIndex(panel.stream_choice.findData("color"))
        settle()
        panel.grab().save(str(HERE / "sensors-preview-colour.png"))
        panel.stream_choice.setCurrentIndex(panel.stream_choice.findData("depth"))
        settle()
        panel.grab().save(str(HERE / "sensors-preview-depth.png"))
    else:
        print(f"no real data at {SHARED_DATA}: the Sensors screenshots were not made.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
