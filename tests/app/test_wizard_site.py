"""The calibration wizard against the embedded simulated site (the done-when check): opened
from the main window's Calibration menu, driven through its six pages while the site's
simulated operator moves the board and lays it on the floor; the saved calibration is
compared with the simulation's truth. OpenGL (the 3D view of the extrinsics page): run
under Xvfb."""

import time

import numpy as np
import pytest
import yaml
from pytestqt.exceptions import TimeoutError as WaitTimeout

from app.main import build_parser, choose_source
from app.main_window import MainWindow
from app.wizard.widgets import COUNT_COLORS, count_level
from optrack.calibration.files import load_calibration
from optrack.calibration.quality import calibration_errors
from optrack.sim.world import Simulation

from .conftest import free_port

pytestmark = pytest.mark.opengl


SENSORS = 2


def truth_poses() -> dict[str, np.ndarray]:
    """The simulated sensors' true poses (the simulated operator's scenes use the same)."""
    sensors = Simulation("calibration", seed=0, sensors=SENSORS).sensors
    return {f"cam{k}": np.asarray(sensor.world_T_camera) for k, sensor in enumerate(sensors)}


@pytest.fixture
def calibration_site(tmp_path):
    """A site of two simulated sensors of the 'calibration' scenario (rendered live:
    their simulated operator carries the board between them), on its own loopback port."""
    path = tmp_path / "site.yaml"
    uris = ",".join(f"sim://calibration/{k}?sensors={SENSORS}&id=cam{k}" for k in range(SENSORS))
    path.write_text(
        yaml.safe_dump(
            {
                "bus": {"local_port": free_port()},
                "site": {"name": "wizardtest", "sensors": uris, "report_s": 0.0},
                "node": {"state_dir": str(tmp_path / "state"), "status_period_s": 0.5},
                "outputs": {"udp": ""},
            }
        )
    )
    return path


@pytest.fixture
def window(qtbot, calibration_site):
    window = MainWindow()
    qtbot.addWidget(window)
    args = build_parser().parse_args(["--config", str(calibration_site)])
    window.set_source(choose_source(args, window))
    window.show()
    qtbot.waitUntil(lambda: window.source.connected, timeout=60000)
    # The wizard finds the sensors from their detector nodes' statuses: wait for them.
    qtbot.waitUntil(lambda: len(window.source.nodes_running("detection")) == SENSORS, timeout=60000)
    yield window
    window.close()


def waited(qtbot, condition, seconds: float, what: str, wizard) -> float:
    """Wait for ``condition``; on time-out say what the page showed."""
    start = time.monotonic()
    try:
        qtbot.waitUntil(condition, timeout=int(seconds * 1000))
    except WaitTimeout:
        page = wizard.currentPage()
        state = wizard.last_state
        seen = "no state"
        if state is not None:
            seen = f"phase {state.phase}, {state.instants} instants, " + ", ".join(
                f"{s}: {v.views} views, {v.frames} frames at {v.capture_hz:.1f} Hz"
                + (", board seen" if v.board_seen else "")
                for s, v in sorted(state.sensors.items())
            )
        raise AssertionError(
            f"{what} did not happen within {seconds:.0f} s; the page said: "
            f"'{page.message.text()}' / error '{page.error.text()}'; {seen}"
        ) from None
    return time.monotonic() - start


def test_wizard_calibrates_the_simulated_site_within_3_cm_and_half_a_degree(
    qtbot, window, tmp_path
):
    truth = truth_poses()
    wizard = window.open_wizard()
    assert wizard.bus is window.source.bus

    # 1. Network and checkerboard: the site's sensors, the default board.
    network = wizard.network_page
    waited(qtbot, network.isComplete, 60, "finding the sensors", wizard)
    assert sorted(wizard.sensors) == sorted(truth)
    assert network.sensor_list.count() == len(truth)
    wizard.next()
    assert wizard.currentPage() is wizard.intrinsics_page

    # 2. Intrinsics, optional. Calibrating without views is refused with the backend's
    # sentence, on the page; then Next keeps the sensors' own intrinsics.
    intrinsics = wizard.intrinsics_page
    intrinsics.calibrate_button.click()
    waited(qtbot, lambda: intrinsics.error.isVisible(), 30, "the refusal", wizard)
    refusal = intrinsics.error.text()
    assert refusal.endswith(".") and len(refusal.split()) > 5, refusal
    waited(qtbot, intrinsics.isComplete, 30, "the page to be free again", wizard)
    wizard.next()

    # 3. Extrinsics: the simulated operator moves the board until every sensor is calibrated.
    extrinsics = wizard.extrinsics_page
    assert wizard.currentPage() is extrinsics
    took = waited(qtbot, extrinsics.isComplete, 420, "calibrating every sensor", wizard)
    print(f"every sensor calibrated {took:.0f} s after the extrinsics page opened")
    state = extrinsics.last_state
    fair, good = wizard.view_thresholds("extrinsics")
    views = extrinsics.table.keys.index("views")
    for sensor, live in state.sensors.items():
        cell = extrinsics.table.item(extrinsics.table.rows[sensor], views)
        assert cell.text() == str(live.views)
        assert cell.background().color() == COUNT_COLORS[count_level(live.views, fair, good)]
    shared = {tuple(sorted((a, b))): n for a, b, n in state.covisibility if n > 0}
    assert extrinsics.graph.edges == shared and shared
    assert set(extrinsics.world.cameras) == set(truth)  # a frustum per calibrated sensor
    wizard.next()

    # 4. Ground: the operator lays the board on the floor; then solve.
    floor = wizard.floor_page
    assert wizard.currentPage() is floor
    floor.capture_button.click()
    took = waited(
        qtbot,
        lambda: wizard.last_state is not None and wizard.last_state.floor_views >= 3,
        300,
        "three floor views",
        wizard,
    )
    print(f"three floor views {took:.0f} s after Capture")
    floor.solve_button.click()
    waited(qtbot, floor.isComplete, 120, "the solve", wizard)
    assert "the world's origin is on the floor" in floor.solved.text()
    wizard.next()

    # 5. Refinement, optional: skipped here (live walks on a loaded 2-core machine are
    # stamped too late to refine reliably; see docs/gui.md).
    assert wizard.currentPage() is wizard.refinement_page
    wizard.next()

    # 6. Review: save (twice: the first file is kept as a backup), export, send.
    review = wizard.review_page
    assert wizard.currentPage() is review
    waited(qtbot, lambda: review.table.rowCount() == len(truth), 30, "the review", wizard)
    assert "the world's origin is on the floor; not refined" in review.summary.text()
    path = tmp_path / "calibration.yaml"
    review.save_to(str(path))
    waited(qtbot, lambda: review.saved is not None and not review.busy, 30, "saving", wizard)
    review.save_to(str(path))
    waited(
        qtbot, lambda: "kept as calibration.yaml.bak" in review.done.text(), 30, "saving", wizard
    )
    review.export_to("openptrack", str(tmp_path / "camera_poses.yaml"))
    waited(qtbot, lambda: "Exported" in review.done.text(), 30, "exporting", wizard)
    poses = yaml.safe_load((tmp_path / "camera_poses.yaml").read_text())["poses"]
    assert set(poses) == set(truth)
    review.publish()
    waited(qtbot, lambda: review.published, 30, "sending", wizard)

    saved = load_calibration(path)
    assert (tmp_path / "calibration.yaml.bak").is_file()
    errors = calibration_errors({s: e.pose for s, e in saved.sensors.items()}, truth)
    print(
        f"saved calibration against the truth: {1000 * errors.max_position_error_m:.1f} mm, "
        f"{errors.max_rotation_error_deg:.3f} deg at worst"
    )
    assert set(saved.sensors) == set(truth)
    assert errors.max_position_error_m < 0.03
    assert errors.max_rotation_error_deg < 0.5
    # The floor is the world's z = 0: each camera's height as the truth has it.
    for sensor, pose in truth.items():
        assert abs(saved.sensors[sensor].pose[2, 3] - pose[2, 3]) < 0.03
    wizard.accept()


def test_the_calibration_menu_opens_the_wizard_which_says_when_there_is_no_site(qtbot):
    window = MainWindow()
    qtbot.addWidget(window)
    window.show()
    menu = next(a.menu() for a in window.menuBar().actions() if a.text() == "&Calibration")
    menu.actions()[0].trigger()
    wizard = window.wizard
    assert wizard is not None and wizard.isVisible()
    assert wizard.network_page.error.text().startswith("No site connected")
    assert not wizard.button(wizard.WizardButton.NextButton).isEnabled()
    menu.actions()[0].trigger()  # a second time: the same wizard comes to the front
    assert window.wizard is wizard
    window.close()
