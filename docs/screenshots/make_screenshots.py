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

The calibration wizard's pages (docs/screenshots/wizard-*.png) are taken
against the default embedded site (`make run`'s) started here, its simulated operator
moving the board, laying it down and walking as each page asks (several
minutes on 2 cores); ``--wizard-only`` makes only those, ``--no-wizard``
all the others.
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
    _app = QApplication([sys.argv[0]])
    from app.main_window import MainWindow
    from app.widgets.sensors_panel import SensorsPanel

    def settle(ms: int = 1500) -> None:
        """Let the window lay itself out and paint, as it does on screen."""
        loop = QEventLoop()
        QTimer.singleShot(ms, loop.quit)
        loop.exec()

    if "--wizard-only" in sys.argv[1:]:
        return wizard_screenshots(settle)
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
    if "--no-wizard" not in sys.argv[1:]:
        return wizard_screenshots(settle)
    return 0


def wizard_screenshots(settle) -> int:  # noqa: ANN001 - settle(ms) processes Qt events
    """Each page of the calibration wizard against an embedded simulated site, opened from
    the main window's Calibration menu as an operator would (docs/screenshots/wizard-*.png)."""
    import socket
    import tempfile
    import time

    import yaml

    from app.main import build_parser, choose_source
    from app.main_window import MainWindow

    def wait(condition, seconds: float, what: str) -> None:
        end = time.monotonic() + seconds
        while not condition():
            if time.monotonic() > end:
                raise SystemExit(f"the wizard screenshots stopped: {what} took over {seconds} s.")
            settle(200)

    def shot(wizard, name: str) -> None:
        settle(1200)
        wizard.screenshot().save(str(HERE / name))
        print(f"wrote {HERE / name}")

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    folder = Path(tempfile.mkdtemp(prefix="optrack-wizard-"))
    config = folder / "site.yaml"
    # The default site, as `make run` starts it (the embedded venue: three simulated Kinect
    # v2), on its own port and state folder (the user's calibrations are left alone).
    config.write_text(
        yaml.safe_dump({"bus": {"local_port": port}, "node": {"state_dir": str(folder / "state")}})
    )
    window = MainWindow()
    window.set_source(choose_source(build_parser().parse_args(["--config", str(config)]), window))
    window.show()
    wait(lambda: window.source.connected, 120, "joining the embedded site")
    wait(lambda: len(window.source.nodes_running("detection")) == 3, 120, "the detector nodes")
    wizard = window.open_wizard()
    wizard.resize(1280, 860)
    try:
        network = wizard.network_page
        wait(network.isComplete, 60, "finding the sensors")
        network.print_board(str(folder / "board.pdf"))
        shot(wizard, "wizard-1-network.png")
        wizard.next()

        intrinsics = wizard.intrinsics_page
        intrinsics.sensor.setCurrentIndex(0)
        intrinsics.start_capture()
        sensor = intrinsics.sensor.currentText()
        # the simulated operator shows the board all over the image, turned, until the page
        # calls the lens good
        enough = lambda: intrinsics.lens_good(sensor)  # noqa: E731
        end = time.monotonic() + 240
        while not enough() and time.monotonic() < end:
            settle(500)
        if enough():
            intrinsics.calibrate()  # stops the capture; the tile keeps its coverage
            wait(
                lambda: sensor in intrinsics.results or bool(intrinsics.error.text()),
                120,
                "intrinsics",
            )
        else:
            views = intrinsics.views_seen.get(sensor, 0)
            print(f"{sensor}'s lens not good after 240 s ({views} views)")
            intrinsics.stop_capture()
        shot(wizard, "wizard-2-intrinsics.png")
        wizard.next()

        extrinsics = wizard.extrinsics_page
        # The guidance: where a camera not calibrated yet shares a view with a calibrated one.
        wait(lambda: extrinsics.guidance is not None or extrinsics.isComplete(), 600, "guidance")
        if extrinsics.guidance is not None:
            shot(wizard, "wizard-3-guidance.png")
            window.top_view.grab().save(str(HERE / "top-view-guidance.png"))
        try:
            wait(extrinsics.isComplete, 600, "calibrating every sensor")
        finally:
            shot(wizard, "wizard-3-extrinsics.png")
        wizard.next()

        floor = wizard.floor_page
        floor.capture_button.click()
        wait(lambda: (wizard.last_state.floor_views if wizard.last_state else 0) >= 3, 300, "floor")
        floor.solve_button.click()
        wait(floor.isComplete, 180, "the solve")
        shot(wizard, "wizard-4-floor.png")
        wizard.next()

        refinement = wizard.refinement_page
        refinement.duration.setValue(30)
        refinement.walk_button.click()
        wait(lambda: refinement.report is not None or refinement.error.isVisible(), 400, "walk")
        shot(wizard, "wizard-5-refinement.png")
        wizard.next()

        review = wizard.review_page
        review.save_to(str(folder / "calibration.yaml"))
        wait(lambda: review.saved is not None, 60, "saving")
        review.export_to("openptrack", str(folder / "camera_poses.yaml"))
        wait(lambda: "Exported" in review.done.text(), 60, "exporting")
        shot(wizard, "wizard-6-review.png")
    finally:
        wizard.shut_down()
        window.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
