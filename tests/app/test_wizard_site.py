"""The newcomer's run: the calibration wizard against an embedded simulated site, opened
from the main window's Calibration menu and driven through its six pages to Finish with
the real widgets, each doing its work, while the site's simulated operator shows the
board to one sensor, moves it between the sensors, lays it on the floor and walks when
the page asks; the saved calibration is compared with the simulation's truth. The default
site is the one `make run` starts (`optrack gui`: no sensors configured, the embedded venue
of three simulated Kinect v2); the others are 2, 4 and 6 simulated sensors.
OpenGL (the 3D view of the extrinsics page): run under Xvfb."""

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


# site -> (scenario, sensors, sim:// options; None: no sensors configured, `make run`'s
# embedded venue), the sensor whose lens the intrinsics page calibrates (None: Next keeps
# the sensors' own intrinsics).
SITES = {
    "default": ("mixed", 3, None, None),
    "two": ("calibration", 2, "", "cam0"),
    "four": ("mixed", 4, "&seconds=900", None),
    "six": ("mixed", 6, "&seconds=900", None),
}
# The intrinsics page checks the lens after each view (OpenCV's standard deviations of fx,
# fy, cx, cy against calibration_intrinsics.good_std_px) and says where the board is still
# missing; the operator calibrates once the page calls the lens good (the simulated
# operator's first 12-13 places take about 40 s; it goes round again while the lens is not
# good).
INTRINSICS_SECONDS = 240
# The simulated person walks until every sensor has detected them this often (a sensor
# with fewer than calibration_refinement.min_detections = 20 is not refined); then Refine
# now. The walker's route around the room takes about 20 s; a loaded computer's nodes
# detect fewer times a second, so the walk lasts longer there: a sensor searching at
# 0.7 Hz (seen in a CI run on two busy cores) needs over 40 s in view. The page's walk is
# set to end after WALK_SECONDS, long enough for that; the test clicks Refine now as soon
# as every sensor has its detections, so a fast machine's walk stays short.
WALK_SECONDS = 180
WALK_DETECTIONS = 30
# The refinement must not make the calibration worse than the checkerboard's by more than
# this (people detections are centimetre-noisy; the board's calibration is millimetre-exact).
REFINE_SLACK_M = 0.01
REFINE_SLACK_DEG = 0.2
# Page 5 is optional: the walk and its refinement on the default site (the newcomer's run)
# and on four sensors (where some sensors' corrections are refused and the others' must
# not make the sensors disagree more); the two- and six-sensor sites go on without
# walking, which keeps the checkerboard's calibration (that path checked on real sites;
# the walk's 20-25 s and its detections spared on the slowest site).
WALKED = ("default", "four")
# Issue 18's target: every camera within 2 cm and 0.3 degree of the truth, on every site
# (on the two-sensor site with the lens page 2 calibrated for cam0).
TARGET = (0.02, 0.3)


def truth_poses(site: str) -> dict[str, np.ndarray]:
    """The simulated sensors' true poses (the simulated operator's scenes use the same)."""
    scenario, count, options, _ = SITES[site]
    sensors = Simulation(scenario, seed=0, people=0, sensors=count).sensors
    if options is None:
        return {s.id: np.asarray(s.world_T_camera) for s in sensors}
    return {f"cam{k}": np.asarray(s.world_T_camera) for k, s in enumerate(sensors)}


def site_config(tmp_path, site: str) -> str:
    """The site's configuration: its own loopback port and state folder (other sites on
    this computer, and the user's calibrations, are left alone) and, except on the
    default site, its sensors; everything else as `make run` has it."""
    scenario, count, options, _ = SITES[site]
    config = {
        "bus": {"local_port": free_port()},
        "node": {"state_dir": str(tmp_path / "state")},
    }
    if options is not None:
        uris = [f"sim://{scenario}/{k}?sensors={count}{options}&id=cam{k}" for k in range(count)]
        config["site"] = {"name": f"wizard{site}", "sensors": ",".join(uris)}
    path = tmp_path / "site.yaml"
    path.write_text(yaml.safe_dump(config))
    return str(path)


@pytest.fixture
def window(qtbot, request, tmp_path):
    """The main window and its embedded site, started as `optrack gui --config FILE` does."""
    site = request.param
    window = MainWindow()
    qtbot.addWidget(window)
    args = build_parser().parse_args(["--config", site_config(tmp_path, site)])
    window.set_source(choose_source(args, window))
    window.show()
    qtbot.waitUntil(lambda: window.source.connected, timeout=90000)
    # The wizard finds the sensors from their detector nodes' statuses: wait for them.
    count = SITES[site][1]
    qtbot.waitUntil(lambda: len(window.source.nodes_running("detection")) == count, timeout=90000)
    window.site_name = site
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


def true_intrinsics(site: str, sensor: int):
    """The intrinsics of the image a simulated sensor's node finds the board in."""
    scenario, count, options, _ = SITES[site]
    uri = f"sim://{scenario}/{sensor}?sensors={count}{options}"
    return pick_image(SimulatedSensor.from_uri(uri).info)[1]


def camera_errors(errors, poses, truth) -> str:
    """Each camera's position and rotation error after the best rigid fit, its height
    error in the world frame (the floor's z = 0) and the floor's tilt in it."""
    return "; ".join(
        f"{s} {1000 * errors.position_m[s]:.1f} mm {errors.rotation_deg[s]:.3f} deg, "
        f"height {1000 * (poses[s][2, 3] - truth[s][2, 3]):+.1f} mm, "
        f"floor tilt {errors.ground_deg[s]:.3f} deg"
        for s in sorted(truth)
    )


def click_next(wizard) -> None:
    """The Next button, as the operator presses it (enabled only when the page is done)."""
    button = wizard.button(wizard.WizardButton.NextButton)
    assert button.isEnabled() and button.isVisible()
    button.click()


def network_page(qtbot, wizard, truth) -> None:
    """1. Network and checkerboard: the site's sensors, the default board."""
    network = wizard.network_page
    waited(qtbot, network.isComplete, 60, "finding the sensors", wizard)
    assert sorted(wizard.sensors) == sorted(truth)
    assert network.sensor_list.count() == len(truth)
    click_next(wizard)
    assert wizard.currentPage() is wizard.intrinsics_page


def intrinsics_page(qtbot, wizard, site: str, sensor: str | None):
    """2. Intrinsics of ``sensor`` (None: Next, the sensors' own intrinsics kept).
    Calibrating without views is refused with the backend's sentence, on the page; then
    the simulated operator shows the board to the sensor all over its image, turned many
    ways, while the page says where the board is still missing, until it calls the lens
    good; its lens is calibrated from those views."""
    intrinsics = wizard.intrinsics_page
    if sensor is None:
        waited(qtbot, intrinsics.isComplete, 30, "the intrinsics page", wizard)
        click_next(wizard)
        return None
    intrinsics.sensor.setCurrentText(sensor)
    intrinsics.calibrate_button.click()
    waited(qtbot, lambda: intrinsics.error.isVisible(), 30, "the refusal", wizard)
    refusal = intrinsics.error.text()
    assert refusal.endswith(".") and len(refusal.split()) > 5, refusal
    waited(qtbot, intrinsics.isComplete, 30, "the page to be free again", wizard)
    intrinsics.start_button.click()
    # Until the lens is good the page names a region of the image and a turn.
    waited(
        qtbot,
        lambda: (
            intrinsics.message.text().startswith("Show the board near the ")
            or intrinsics.lens_good(sensor)
        ),
        INTRINSICS_SECONDS,
        "the page's advice",
        wizard,
    )
    took = waited(
        qtbot,
        lambda: intrinsics.lens_good(sensor),
        INTRINSICS_SECONDS,
        f"{sensor}'s lens called good",
        wizard,
    )
    assert intrinsics.message.text().startswith(f"{sensor}'s lens is good")
    print(
        f"{sensor}'s lens good {took:.0f} s after Start capture, "
        f"{intrinsics.views_seen[sensor]} views"
    )
    # The coverage overlay: corners seen in many cells of the image, not in one spot.
    assert intrinsics.tile.coverage is not None and (intrinsics.tile.coverage > 0).sum() >= 6
    intrinsics.calibrate_button.click()
    waited(qtbot, lambda: sensor in intrinsics.results, 60, "the intrinsics", wizard)
    lens, true_lens = intrinsics.results[sensor], true_intrinsics(site, int(sensor[3:]))
    print(
        f"{sensor} intrinsics: fx {lens.intrinsics.fx:.1f} (true {true_lens.fx:.1f}), "
        f"cx {lens.intrinsics.cx:.1f} ({true_lens.cx:.1f}), cy {lens.intrinsics.cy:.1f} "
        f"({true_lens.cy:.1f}) px, RMS {lens.rms:.2f} px over {len(lens.used)} views, "
        f"known to {lens.uncertainty_px:.2f} px"
    )
    assert lens.good
    assert abs(lens.intrinsics.fx / true_lens.fx - 1) < 0.02
    assert abs(lens.intrinsics.fy / true_lens.fy - 1) < 0.02
    assert abs(lens.intrinsics.cx - true_lens.cx) < 0.02 * true_lens.width
    assert abs(lens.intrinsics.cy - true_lens.cy) < 0.02 * true_lens.height
    views = intrinsics.table.keys.index("intrinsics")
    cell = intrinsics.table.item(intrinsics.table.rows[sensor], views)
    assert cell.text().startswith("calibrated, good")
    # The backend's state can show the result before the calibrating job has ended; Next
    # is enabled once the page is free again (the operator waits for it too).
    waited(qtbot, intrinsics.isComplete, 30, "the page to be free again", wizard)
    click_next(wizard)
    return lens


def extrinsics_page(qtbot, wizard, truth, sensor: str | None, lens) -> None:
    """3. Extrinsics: the simulated operator moves the board until every sensor is
    calibrated (a lens calibrated on page 2 used for its sensor)."""
    extrinsics = wizard.extrinsics_page
    assert wizard.currentPage() is extrinsics
    took = waited(qtbot, extrinsics.isComplete, 420, "calibrating every sensor", wizard)
    print(f"every sensor calibrated {took:.0f} s after the extrinsics page opened")
    # Next is enabled once every sensor shares two board poses with calibrated ones
    # (calibration_live.min_shared_poses); the page asks to go on until the counts turn
    # green: the operator goes on until none is red.
    fair, good = wizard.view_thresholds("extrinsics")

    def none_red() -> bool:
        state = extrinsics.last_state
        return extrinsics.isComplete() and all(v.views >= fair for v in state.sensors.values())

    took += waited(qtbot, none_red, 300, f"{fair} views of every sensor", wizard)
    print(f"{fair} views of every sensor {took:.0f} s after the extrinsics page opened")
    state = extrinsics.last_state
    print(
        "shared board poses: "
        + ", ".join(f"{s} {v.shared_poses}" for s, v in sorted(state.sensors.items()))
        + "; searches a second: "
        + ", ".join(f"{s} {v.capture_hz:.1f}" for s, v in sorted(state.sensors.items()))
    )
    for name, live in state.sensors.items():  # calibrated on two shared board poses at least
        assert live.settled and live.shared_poses >= live.shared_needed >= 2, name
        assert extrinsics.table.text(name, "status").startswith("calibrated")
    if sensor is not None:
        assert state.sensors[sensor].intrinsics == lens.intrinsics
    views = extrinsics.table.keys.index("views")
    for name, live in state.sensors.items():
        cell = extrinsics.table.item(extrinsics.table.rows[name], views)
        assert cell.text() == str(live.views)
        assert cell.background().color() == COUNT_COLORS[count_level(live.views, fair, good)]
    shared = {tuple(sorted((a, b))): n for a, b, n in state.covisibility if n > 0}
    assert extrinsics.graph.edges == shared and shared
    assert set(extrinsics.world.cameras) == set(truth)  # a frustum per calibrated sensor
    click_next(wizard)


def floor_page(qtbot, wizard, truth):
    """4. Ground: the operator lays the board on the floor; then solve."""
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
    # Several places make the floor more exact (the page says so; one board's views left a
    # camera 6 m away over 2 cm off in height): Solve once the operator has laid the board
    # at every place it planned (the site status says when: operator.until).
    took += waited(
        qtbot, wizard.live.operator.finished, 240, "the board laid at every floor place", wizard
    )
    print(f"three floor views, every floor place, {took:.0f} s after Capture")
    floor.solve_button.click()
    waited(qtbot, floor.isComplete, 120, "the solve", wizard)
    assert "the world's origin is on the floor" in floor.solved.text()
    poses = {s: e.pose for s, e in wizard.solved.sensors.items()}
    solved = calibration_errors(poses, truth)
    print(
        f"solved, {wizard.last_state.floor_views} floor views: "
        + camera_errors(solved, poses, truth)
    )
    click_next(wizard)
    return solved


def refinement_page(qtbot, wizard, truth, solved):
    """5. Refinement: one simulated person walks; the sensors' trajectories of them are
    aligned when the walk ends. The sensors agree no worse after, and the calibration is
    no worse than the checkerboard's (against the truth): a correction the board's views
    contradict is refused (on these sites Algorithm 1's usually are)."""
    refinement = wizard.refinement_page
    assert wizard.currentPage() is refinement
    refinement.duration.setValue(WALK_SECONDS)
    started = time.monotonic()
    refinement.walk_button.click()

    def detected() -> bool:
        samples = wizard.last_state.refinement_samples if wizard.last_state else {}
        enough = all(samples.get(sensor, 0) >= WALK_DETECTIONS for sensor in truth)
        return enough and refinement.refine_button.isEnabled()

    waited(qtbot, detected, WALK_SECONDS + 60, "the walker detected by every sensor", wizard)
    # The walk is drawn while the person walks (issue 18 item 8), before any refinement.
    assert refinement.report is None and set(refinement.before.curves) == set(truth)
    refinement.refine_button.click()
    waited(
        qtbot,
        lambda: refinement.report is not None or refinement.error.isVisible(),
        120,
        "the refinement",
        wizard,
    )
    took = time.monotonic() - started
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
    click_next(wizard)
    return report


def no_walk(wizard) -> None:
    """5. Refinement skipped: Next without walking keeps the checkerboard's calibration."""
    refinement = wizard.refinement_page
    assert wizard.currentPage() is refinement
    assert refinement.report is None and not refinement.walking
    click_next(wizard)


def review_page(qtbot, wizard, truth, report, tmp_path):
    """6. Review: save (twice: the first file is kept as a backup), export, send
    (``report``: the walk's refinement, None when page 5 was skipped)."""
    review = wizard.review_page
    assert wizard.currentPage() is review
    waited(qtbot, lambda: review.table.rowCount() == len(truth), 30, "the review", wizard)
    if report is None:
        assert "not refined" in review.summary.text()
        assert all(review.table.text(s, "refinement") == "not refined" for s in truth)
    else:
        assert "refined from a walk" in review.summary.text()
    for sensor in truth:  # a sensor the walk did not move says why
        kept = review.table.text(sensor, "refinement") == "kept the board's pose"
        assert kept == (report is not None and sensor in report.refused)
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
    return path


@pytest.mark.parametrize("window", sorted(SITES), indirect=True)
def test_the_wizard_calibrates_the_simulated_site_from_page_1_to_finish(qtbot, window, tmp_path):
    site = window.site_name
    truth = truth_poses(site)
    sensor = SITES[site][3]
    menu = next(a.menu() for a in window.menuBar().actions() if a.text() == "&Calibration")
    menu.actions()[0].trigger()  # Calibration → Calibrate…
    wizard = window.wizard
    assert wizard.bus is window.source.bus
    started = time.monotonic()
    network_page(qtbot, wizard, truth)
    lens = intrinsics_page(qtbot, wizard, site, sensor)
    extrinsics_page(qtbot, wizard, truth, sensor, lens)
    solved = floor_page(qtbot, wizard, truth)
    if site in WALKED:
        report = refinement_page(qtbot, wizard, truth, solved)
    else:
        report = no_walk(wizard)
    path = review_page(qtbot, wizard, truth, report, tmp_path)
    wizard.button(wizard.WizardButton.FinishButton).click()
    assert not wizard.isVisible()
    took = time.monotonic() - started
    print(f"{site} site: page 1 to Finish in {took:.0f} s (issue 18's target: 240 s)")

    saved = load_calibration(path)
    assert (tmp_path / "calibration.yaml.bak").is_file()
    poses = {s: e.pose for s, e in saved.sensors.items()}
    errors = calibration_errors(poses, truth)
    worst = max(errors.rotation_deg, key=errors.rotation_deg.get)
    print(
        f"saved calibration against the truth: {1000 * errors.max_position_error_m:.1f} mm, "
        f"{errors.max_rotation_error_deg:.3f} deg at worst ({worst}'s rotation); views "
        + ", ".join(f"{s} {e.views}" for s, e in sorted(saved.sensors.items()))
    )
    print("per camera: " + camera_errors(errors, poses, truth))
    assert set(saved.sensors) == set(truth)
    if sensor is not None:
        saved_lens = saved.sensors[sensor].intrinsics
        assert (saved_lens.fx, saved_lens.cy) == pytest.approx(
            (lens.intrinsics.fx, lens.intrinsics.cy)
        )
    # The refined calibration was saved: each sensor's walk correction, or none where the
    # checkerboard's pose was kept (every sensor's without a walk).
    final = report.calibration if report is not None else wizard.solved
    corrected = report.corrections if report is not None else {}
    for name, entry in saved.sensors.items():
        assert (entry.refinement is not None) == (name in corrected)
        assert np.allclose(entry.pose, final.pose(name), atol=1e-6)
    position_m, rotation_deg = TARGET
    assert errors.max_position_error_m <= position_m, errors.as_dict()
    assert errors.max_rotation_error_deg <= rotation_deg, errors.as_dict()
    # The floor is the world's z = 0: each camera's height as the truth has it.
    for name, pose in truth.items():
        height = saved.sensors[name].pose[2, 3]
        assert abs(height - pose[2, 3]) < position_m, (name, height, pose[2, 3])


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


def test_the_world_view_draws_the_guidance_region_and_the_board_closed(qtbot):
    """Page 3's 3D view and the main window's World 3D: the floor region in green and the
    suggested board's outline, every side of it drawn; None clears them."""
    from PySide6.QtGui import QVector3D

    from app.widgets.world_view import GUIDANCE_COLOR, WorldView
    from optrack.calibration.board import Checkerboard
    from optrack.calibration.overlap import SensorView, suggest_board

    from .test_main_window import image_array

    sensors = Simulation("mixed", seed=0, people=0).sensors
    views = {s.id: SensorView(s.world_T_camera, s.model.intrinsics, 0.5, 4.5) for s in sensors}
    guidance = suggest_board(
        views, "kinect2_1", ["kinect2_0", "kinect2_2"], Checkerboard(6, 5, 0.15)
    )
    assert guidance.found
    view = WorldView()
    qtbot.addWidget(view)
    view.resize(640, 480)
    view.show()
    qtbot.waitExposed(view)
    view.overlay.show_message("")
    x, y, z = (float(c) for c in guidance.center)
    view.setCameraPosition(pos=QVector3D(x, y, z), distance=4.0, elevation=50, azimuth=-60)
    view.set_guidance(guidance)
    region, board = view.guidance_items
    outline = board.pos
    assert len(outline) == 5 and np.allclose(outline[0], outline[-1])  # closed
    assert np.allclose(outline[:4], guidance.corners)
    assert len(region.pos) == len(guidance.region)
    green = np.array(GUIDANCE_COLOR[:3]) * 255
    pixels = image_array(view.grabFramebuffer()).astype(int)
    ratio = pixels.shape[1] / view.width()
    mvp = view.projectionMatrix((0, 0, view.width(), view.height()), view.getViewport())
    mvp = mvp * view.viewMatrix()
    corners = guidance.corners
    for k in range(4):  # the middle of every side is green on screen
        middle = (corners[k] + corners[(k + 1) % 4]) / 2
        ndc = mvp.map(QVector3D(*(float(c) for c in middle)))
        u = round((ndc.x() + 1) / 2 * view.width() * ratio)
        v = round((1 - ndc.y()) / 2 * view.height() * ratio)
        patch = pixels[max(v - 4, 0) : v + 5, max(u - 4, 0) : u + 5]
        assert (np.abs(patch - green).sum(axis=2) < 90).any(), (k, u, v)
    view.set_guidance(None)
    assert view.guidance_items == []
    view.close()
