"""The calibration wizard against the embedded simulated site (the done-when check): opened
from the main window's Calibration menu, driven through its six pages, each doing its work,
while the site's simulated operator shows the board to one sensor, moves it between the
sensors, lays it on the floor and walks when the page asks; the saved calibration is
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
from optrack.calibration.session import pick_image
from optrack.sim.sensor import SimulatedSensor
from optrack.sim.world import Simulation

from .conftest import free_port

pytestmark = pytest.mark.opengl


SENSORS = 2
# Views of cam0 the intrinsics page collects before calibrating (calibrating needs
# calibration_intrinsics.min_views = 4; more, at other places and turns, pin the lens down).
INTRINSICS_VIEWS = 14
# How long the simulated person walks on the refinement page (the wizard asks for 60 s;
# the simulated walker's route around the room takes about 20 s).
WALK_SECONDS = 20
# The refinement must not make the calibration worse than the checkerboard's by more than
# this (people detections are centimetre-noisy; the board's calibration is millimetre-exact).
REFINE_SLACK_M = 0.01
REFINE_SLACK_DEG = 0.2


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


def true_intrinsics(sensor: int):
    """The intrinsics of the image a simulated sensor's node finds the board in."""
    info = SimulatedSensor.from_uri(f"sim://calibration/{sensor}?sensors={SENSORS}").info
    return pick_image(info)[1]


def test_wizard_calibrates_the_simulated_site_within_3_cm_and_half_a_degree(
    qtbot, window, tmp_path
):
    truth = truth_poses()
    wizard = window.open_wizard()
    assert wizard.bus is window.source.bus
    started = time.monotonic()

    # 1. Network and checkerboard: the site's sensors, the default board.
    network = wizard.network_page
    waited(qtbot, network.isComplete, 60, "finding the sensors", wizard)
    assert sorted(wizard.sensors) == sorted(truth)
    assert network.sensor_list.count() == len(truth)
    wizard.next()
    assert wizard.currentPage() is wizard.intrinsics_page

    # 2. Intrinsics of cam0. Calibrating without views is refused with the backend's
    # sentence, on the page; then the simulated operator shows the board to cam0 all over
    # its image, turned many ways, and its lens is calibrated from those views.
    intrinsics = wizard.intrinsics_page
    intrinsics.sensor.setCurrentText("cam0")
    intrinsics.calibrate_button.click()
    waited(qtbot, lambda: intrinsics.error.isVisible(), 30, "the refusal", wizard)
    refusal = intrinsics.error.text()
    assert refusal.endswith(".") and len(refusal.split()) > 5, refusal
    waited(qtbot, intrinsics.isComplete, 30, "the page to be free again", wizard)
    intrinsics.start_button.click()
    took = waited(
        qtbot,
        lambda: intrinsics.views_seen.get("cam0", 0) >= INTRINSICS_VIEWS,
        90,
        f"{INTRINSICS_VIEWS} intrinsics views of cam0",
        wizard,
    )
    print(f"{INTRINSICS_VIEWS} intrinsics views {took:.0f} s after Start capture")
    # The coverage overlay: corners seen in many cells of cam0's image, not in one spot.
    assert intrinsics.tile.coverage is not None and (intrinsics.tile.coverage > 0).sum() >= 6
    intrinsics.calibrate_button.click()
    waited(qtbot, lambda: "cam0" in intrinsics.results, 60, "the intrinsics", wizard)
    lens, true_lens = intrinsics.results["cam0"], true_intrinsics(0)
    print(
        f"cam0 intrinsics: fx {lens.intrinsics.fx:.1f} (true {true_lens.fx:.1f}), "
        f"cx {lens.intrinsics.cx:.1f} ({true_lens.cx:.1f}), cy {lens.intrinsics.cy:.1f} "
        f"({true_lens.cy:.1f}) px, RMS {lens.rms:.2f} px over {len(lens.used)} views"
    )
    assert abs(lens.intrinsics.fx / true_lens.fx - 1) < 0.02
    assert abs(lens.intrinsics.fy / true_lens.fy - 1) < 0.02
    assert abs(lens.intrinsics.cx - true_lens.cx) < 0.02 * true_lens.width
    assert abs(lens.intrinsics.cy - true_lens.cy) < 0.02 * true_lens.height
    views = intrinsics.table.keys.index("intrinsics")
    assert (
        intrinsics.table.item(intrinsics.table.rows["cam0"], views).text().startswith("calibrated")
    )
    wizard.next()

    # 3. Extrinsics: the simulated operator moves the board until every sensor is calibrated
    # (cam0 with the intrinsics just calibrated).
    extrinsics = wizard.extrinsics_page
    assert wizard.currentPage() is extrinsics
    took = waited(qtbot, extrinsics.isComplete, 420, "calibrating every sensor", wizard)
    print(f"every sensor calibrated {took:.0f} s after the extrinsics page opened")
    state = extrinsics.last_state
    assert state.sensors["cam0"].intrinsics == lens.intrinsics
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
    solved = calibration_errors({s: e.pose for s, e in wizard.solved.sensors.items()}, truth)
    wizard.next()

    # 5. Refinement: one simulated person walks; the sensors' trajectories of them are
    # aligned when the walk ends. The sensors agree no worse after, and the calibration is
    # no worse than the checkerboard's (against the truth): a correction the board's views
    # contradict is refused (on this site Algorithm 1's usually are).
    refinement = wizard.refinement_page
    assert wizard.currentPage() is refinement
    refinement.duration.setValue(WALK_SECONDS)
    refinement.walk_button.click()
    took = waited(
        qtbot,
        lambda: refinement.report is not None or refinement.error.isVisible(),
        WALK_SECONDS + 120,
        "the refinement",
        wizard,
    )
    assert refinement.report is not None, refinement.error.text()
    waited(qtbot, refinement.isComplete, 30, "the page to be free again", wizard)
    report = refinement.report
    refined = calibration_errors({s: e.pose for s, e in report.calibration.sensors.items()}, truth)
    print(
        f"walk and refinement {took:.0f} s; the sensors disagree by "
        f"{100 * report.error_before_m:.1f} cm before, {100 * report.error_after_m:.1f} cm "
        f"after; against the truth: {1000 * solved.max_position_error_m:.1f} mm, "
        f"{solved.max_rotation_error_deg:.3f} deg solved -> "
        f"{1000 * refined.max_position_error_m:.1f} mm, "
        f"{refined.max_rotation_error_deg:.3f} deg refined; detections "
        + ", ".join(f"{s} {len(t)}" for s, t in sorted(report.trajectories_before.items()))
        + f"; applied to {sorted(report.corrections)}, refused for {report.refused} "
        f"(board RMS {report.board_rms_px} -> {report.board_rms_refined_px})"
    )
    assert not report.skipped and set(report.trajectories_before) == set(truth)
    assert report.error_after_m <= report.error_before_m
    assert refinement.before.curves and refinement.after.curves
    if report.corrections:
        assert "after" in refinement.figure.text()
    else:  # every correction refused: said, and no after plot repeating the before plot
        assert refinement.figure.text().startswith("Nothing changed")
        assert refinement.after.isHidden()
    assert refined.max_position_error_m <= solved.max_position_error_m + REFINE_SLACK_M
    assert refined.max_rotation_error_deg <= solved.max_rotation_error_deg + REFINE_SLACK_DEG
    wizard.next()

    # 6. Review: save (twice: the first file is kept as a backup), export, send.
    review = wizard.review_page
    assert wizard.currentPage() is review
    waited(qtbot, lambda: review.table.rowCount() == len(truth), 30, "the review", wizard)
    assert "refined from a walk" in review.summary.text()
    for sensor in truth:  # a sensor the walk did not move says why
        kept = review.table.text(sensor, "refinement") == "kept the board's pose"
        assert kept == (sensor in report.refused)
    assert "the world's origin is on the floor" in review.summary.text()
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
    print(f"six pages in {time.monotonic() - started:.0f} s")

    saved = load_calibration(path)
    assert (tmp_path / "calibration.yaml.bak").is_file()
    errors = calibration_errors({s: e.pose for s, e in saved.sensors.items()}, truth)
    print(
        f"saved calibration against the truth: {1000 * errors.max_position_error_m:.1f} mm, "
        f"{errors.max_rotation_error_deg:.3f} deg at worst"
    )
    assert set(saved.sensors) == set(truth)
    saved_lens = saved.sensors["cam0"].intrinsics
    assert (saved_lens.fx, saved_lens.cy) == pytest.approx((lens.intrinsics.fx, lens.intrinsics.cy))
    # The refined calibration was saved: each sensor's walk correction, or none where the
    # checkerboard's pose was kept.
    for sensor, entry in saved.sensors.items():
        assert (entry.refinement is not None) == (sensor in report.corrections)
        assert np.allclose(entry.pose, report.calibration.pose(sensor), atol=1e-6)
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
