"""The wizard's pages show what the live calibration's state says (offscreen Qt, no site:
the states are built here, as LiveCalibration.state() returns them)."""

import numpy as np
import pytest

from app.wizard.widgets import COUNT_COLORS
from app.wizard.wizard import WIZARD_PARAMS, CalibrationWizard
from optrack.calibration.live import LiveState, SensorLive
from optrack.calibration.printable import board_label
from optrack.geometry import make_pose
from optrack.types import Intrinsics

KINECT = Intrinsics(365.0, 365.0, 256.0, 212.0, width=512, height=424)
SENSORS = ["cam0", "cam1", "cam2"]


def matrix(pose):
    return tuple(tuple(float(v) for v in row) for row in pose)


def sensor(name, views, calibrated, rms=None, **extra):
    pose = make_pose(np.diag([1.0, -1.0, -1.0]), [float(SENSORS.index(name)), 0.0, 2.5])
    return SensorLive(
        sensor=name,
        views=views,
        rms_px=rms,
        calibrated=calibrated,
        image=np.full((106, 128, 3), 90, dtype=np.uint8),
        board_seen=views > 0,
        coverage=None,
        world_T_camera=pose if calibrated else None,
        intrinsics=KINECT,
        **extra,
    )


def state(phase, sensors, covisibility=(), floor_views=0, message="", **extra):
    return LiveState(
        phase=phase,
        sensors={s.sensor: s for s in sensors},
        covisibility=list(covisibility),
        floor_views=floor_views,
        refinement_samples={},
        message=message,
        **extra,
    )


@pytest.fixture
def wizard(qtbot):
    wizard = CalibrationWizard(None, world_view=False)
    qtbot.addWidget(wizard)
    wizard.sensors = list(SENSORS)
    return wizard


def test_without_a_site_page_one_says_so_and_next_stays_off(wizard):
    page = wizard.network_page
    assert page.error.text().startswith("No site connected")
    assert not page.isComplete()
    params = WIZARD_PARAMS.create()
    assert (page.cols.value(), page.rows.value()) == (params.board_cols, params.board_rows)
    assert page.square.value() == pytest.approx(params.board_square * 1000)


def test_print_a_board_writes_the_pdf_and_a_symmetric_board_is_refused(wizard, tmp_path):
    page = wizard.network_page
    assert page.print_board(str(tmp_path / "board.pdf"))
    pdf = (tmp_path / "board.pdf").read_bytes()
    assert pdf.startswith(b"%PDF") and board_label(page.board()).encode()[:40] in pdf
    assert "Wrote" in page.printed.text()
    page.cols.setValue(8)
    page.rows.setValue(6)
    assert not page.print_board(str(tmp_path / "symmetric.pdf"))
    assert "looks the same after a half turn" in page.error.text()
    assert not (tmp_path / "symmetric.pdf").exists()
    assert not page.validatePage()  # and the wizard does not go on with it


def test_extrinsics_page_colours_counts_draws_covisibility_and_enables_next(wizard):
    page = wizard.extrinsics_page
    page.images.set_sensors(SENSORS)
    fair, good = wizard.view_thresholds("extrinsics")
    early = state(
        "extrinsics",
        [
            sensor("cam0", good + 3, True, 0.21),
            sensor("cam1", fair, True, 0.34, parent="cam0"),
            sensor("cam2", fair - 1, False),
        ],
        covisibility=[("cam0", "cam1", fair), ("cam1", "cam2", 0)],
        message="Move the board where cam2 and a calibrated sensor both see it.",
    )
    page.show_state(early)
    views = page.table.keys.index("views")
    colours = [page.table.item(page.table.rows[s], views).background().color() for s in SENSORS]
    assert colours == [COUNT_COLORS["green"], COUNT_COLORS["yellow"], COUNT_COLORS["red"]]
    assert page.table.text("cam1", "status") == "calibrated (via cam0)"
    assert page.table.text("cam2", "rms") == ""
    assert page.graph.edges == {("cam0", "cam1"): fair}
    assert page.graph.calibrated == {"cam0", "cam1"}
    assert page.message.text() == early.message
    assert "0.34 px at worst" in page.rms.text() and "2 of 3 sensors" in page.rms.text()
    assert page.images.tiles["cam2"].caption == f"cam2: {fair - 1} views"
    assert not page.isComplete()
    done = state(
        "extrinsics",
        [sensor(s, good, True, 0.3) for s in SENSORS],
        covisibility=[("cam0", "cam1", good), ("cam1", "cam2", good)],
    )
    page.show_state(done)
    assert page.isComplete()
    assert page.graph.edges == {("cam0", "cam1"): good, ("cam1", "cam2"): good}


def test_intrinsics_page_shows_the_coverage_of_the_sensor_it_captures(wizard):
    page = wizard.intrinsics_page
    page.sensor.addItems(SENSORS)
    page.sensor.setCurrentText("cam1")
    coverage = np.zeros((6, 8))
    coverage[2:4, 3:5] = 0.7
    cam1 = sensor("cam1", 9, False)
    cam1.coverage = coverage
    page.show_state(state("intrinsics", [cam1]))
    assert page.tile.coverage is not None and page.tile.coverage.max() == pytest.approx(0.7)
    assert page.tile.caption == "cam1: 9 views"
    assert page.table.text("cam1", "views") == "9"
    assert page.table.text("cam0", "intrinsics") == "the sensor's own"
    assert page.isComplete()  # optional: Next keeps the sensors' own intrinsics


def lens(std_px):
    """The lens check of some views, as the backend's IntrinsicsResult carries it."""
    from optrack.calibration.board import CoverageMap
    from optrack.calibration.intrinsics import IntrinsicsResult

    regions = np.full((3, 3), 40)
    regions[2, 0] = 3  # few corners near the bottom-left corner
    return IntrinsicsResult(
        intrinsics=KINECT,
        rms=0.07,
        per_view_rms=[0.07] * 9,
        used=list(range(9)),
        rejected=[],
        coverage=CoverageMap(512, 424),
        std_px=std_px,
        regions=regions,
        turns=(4, 3, 0, 5),
    )


def test_intrinsics_page_says_where_the_board_is_missing_until_the_lens_is_good(wizard):
    """While capturing, the tile's caption says how well the lens is known, the page's
    sentence (the backend's advice) where to show the board; the table says whether the
    calibrated lens is good."""
    page = wizard.intrinsics_page
    page.sensor.addItems(SENSORS)
    page.sensor.setCurrentText("cam1")
    unsure = lens((0.6, 0.55, 0.83, 0.7))
    cam1 = sensor("cam1", 9, False, lens=unsure)
    page.show_state(state("intrinsics", [cam1], message=unsure.advice("cam1")))
    assert page.tile.caption == "cam1: 9 views, lens known to 0.83 px"
    assert page.message.text() == (
        "Show the board near the bottom-left corner of cam1's image, tilted up: the lens "
        "is known to 0.83 px, good from 0.5 px."
    )
    assert not page.lens_good("cam1")
    good = lens((0.3, 0.3, 0.42, 0.4))
    page.show_state(state("intrinsics", [sensor("cam1", 12, False, lens=good)]))
    assert page.tile.caption == "cam1: 12 views, lens good" and page.lens_good("cam1")
    assert good.advice("cam1").startswith("cam1's lens is good: focal lengths and image centre")
    wizard.last_state = state("idle", [], intrinsics_results={"cam1": good, "cam2": unsure})
    page.show_state(wizard.last_state)
    assert page.table.text("cam1", "intrinsics") == "calibrated, good (±0.42 px), RMS 0.07 px"
    assert page.table.text("cam2", "intrinsics").startswith("calibrated, not good yet (±0.83 px)")


def test_floor_page_counts_floor_views_and_needs_a_solve(wizard):
    page = wizard.floor_page
    page.images.set_sensors(SENSORS)
    page.show_state(
        state(
            "floor",
            [sensor("cam0", 2, True, on_floor=True), sensor("cam1", 0, True)],
            floor_views=4,
            operator="laying the board at place 2 of 3",
        )
    )
    assert page.floor_views.text() == "Floor views: 4 (laying the board at place 2 of 3)"
    assert page.images.tiles["cam0"].caption == "cam0, on the floor"
    assert not page.isComplete()  # nothing solved yet
    page.show_state(state("floor", [sensor("cam0", 1, True)], operator="lay_board"))
    assert page.floor_views.text() == (
        "Floor views: 0 (the simulated operator lays the board on the floor)"
    )


def test_a_site_without_sensors_is_said_in_a_sentence_on_page_one(qtbot):
    """The backend's refusal (no detector node answers on this bus) reaches the page."""
    from optrack.net.bus import Bus
    from optrack.net.config import BUS_PARAMS

    from .conftest import free_port

    hub = Bus("empty", "hub", BUS_PARAMS.create({"local_port": free_port()}), host=True)
    wizard = CalibrationWizard(hub, world_view=False)
    qtbot.addWidget(wizard)
    try:
        page = wizard.network_page
        assert page.sensors_note.text() == "Looking for the site's sensors…"
        qtbot.waitUntil(lambda: bool(page.error.text()), timeout=30000)
        sentence = page.error.text()
        assert sentence.endswith(".")
        assert "sensor" in sentence.lower() or "node" in sentence.lower()
        assert page.sensors_note.text() == "No sensors."
        assert not page.isComplete() and page.retry.isEnabled()
    finally:
        wizard.shut_down()
        hub.close()


def test_refinement_page_plots_trajectories_before_and_after_and_the_error_figure(wizard):
    from optrack.calibration.live import RefinementReport
    from optrack.types import NetworkCalibration, SensorCalibration

    page = wizard.refinement_page
    t = np.linspace(0.0, 2 * np.pi, 40)
    walk = np.column_stack([np.cos(t), np.sin(t), np.full_like(t, 1.1)])
    report = RefinementReport(
        calibration=NetworkCalibration(
            sensors={"cam0": SensorCalibration(world_T_camera=matrix(np.eye(4)))}
        ),
        error_before_m=0.112,
        error_after_m=0.0198,
        trajectories_before={"cam0": walk, "cam1": walk + 0.1},
        trajectories_after={"cam0": walk, "cam1": walk + 0.01},
        corrections={"cam1": make_pose(np.eye(3), [0.09, 0.0, 0.0])},
        skipped=["cam2"],
        refused={"cam3": 3.14},
        board_rms_px={"cam3": 0.12},
    )
    # The backend's snapshot after refine(): the wizard takes it, the page draws it.
    refined = state("idle", [], refinement=report, calibration=report.calibration)
    wizard.take_state(refined)
    page.show_state(refined)
    assert page.report is report
    assert set(page.before.curves) == set(page.after.curves) == {"cam0", "cam1"}
    assert "11.2 cm on average before refinement and 2.0 cm after" in page.figure.text()
    assert "cam2" in page.figure.text()
    # A sensor whose board views the walk's correction contradicts keeps the board's pose.
    assert "checkerboard's pose for cam3" in page.figure.text()
    assert "3.1 px off, against 0.1 px" in page.figure.text()
    assert wizard.refined and wizard.calibration is report.calibration


def test_the_wizards_file_dialogs_start_in_the_users_calibrations_folder(
    wizard, monkeypatch, tmp_path
):
    """Print a board…, Save… and Export… start in ~/optrack-calibrations, never in the
    folder the program was started from (issue 18 item 3)."""
    from PySide6.QtWidgets import QFileDialog

    monkeypatch.setenv("HOME", str(tmp_path))
    asked: list[str] = []

    def file_dialog(parent, title, start, *rest):  # the operator cancels
        asked.append(start)
        return "", ""

    monkeypatch.setattr(QFileDialog, "getSaveFileName", file_dialog)
    folder = tmp_path / "optrack-calibrations"
    wizard.network_page._ask_print()
    assert asked[-1] == str(folder / "board.pdf")
    wizard.review_page._ask_save()
    assert asked[-1] == str(folder / "calibration.yaml")
    wizard.review_page._ask_export()
    assert asked[-1] == str(folder / "camera_poses.yaml")


def test_a_page_is_busy_until_every_job_it_asked_for_has_ended(qtbot, wizard):
    """Solve right after a floor capture queues two jobs, stop and solve: the page said it
    was done when the stop ended, before the solve had said anything (six sensors)."""
    import threading
    from types import SimpleNamespace

    page = wizard.floor_page
    wizard.live = SimpleNamespace()  # a session is open; these jobs do not use it
    gate, ended = threading.Event(), []
    page.run("first", lambda progress: "first", ended.append)
    page.run("second", lambda progress: gate.wait(10) and "second", ended.append, "Solving…")
    qtbot.waitUntil(lambda: ended == ["first"], timeout=5000)
    assert page.busy and not page.solve_button.isEnabled()
    assert not page.progress.isHidden()  # the solve's progress stays up
    gate.set()
    qtbot.waitUntil(lambda: ended == ["first", "second"], timeout=5000)
    assert not page.busy and page.solve_button.isEnabled() and page.progress.isHidden()


def test_refinement_page_draws_the_walk_while_the_person_walks(wizard):
    """Issue 18 item 8: the plots were empty during the walk (only the counts changed)."""
    page = wizard.refinement_page
    t = np.linspace(0.0, np.pi, 15)
    walk = np.column_stack([np.cos(t), np.sin(t), np.full_like(t, 1.1)])
    walking = state("refinement", [], walk={"cam0": walk, "cam1": walk[:9] + 0.05})
    walking.refinement_samples.update({"cam0": 15, "cam1": 9})
    page.show_state(walking)
    assert set(page.before.curves) == {"cam0", "cam1"}
    x, y = page.before.curves["cam1"].getData()
    np.testing.assert_allclose(y, walk[:9, 1] + 0.05)
    assert page.after.isHidden()  # nothing refined yet: no empty after plot
    assert page.samples.text() == "Detections of the walker: cam0 15, cam1 9."


def test_review_page_shows_each_sensors_quality_from_the_calibration_file(wizard):
    from optrack.calibration.files import CalibrationFile, SensorEntry

    pose = make_pose(np.diag([1.0, -1.0, -1.0]), [1.0, 0.0, 2.5])
    moved = make_pose(translation=[0.03, 0.04, 0.0])
    calibration = CalibrationFile(
        sensors={
            "cam0": SensorEntry(world_T_camera=matrix(pose), views=40, reprojection_rms_px=0.08),
            "cam1": SensorEntry(
                world_T_camera=matrix(pose),
                views=3,
                reprojection_rms_px=0.31,
                refinement=matrix(moved),
            ),
        },
        world="floor",
        quality={
            "reprojection_rms_px": 0.2,
            "floor_views": 6,
            "refinement_error_before_m": 0.05,
            "refinement_error_after_m": 0.02,
            "refinement_refused": ["cam0"],
        },
    )
    page = wizard.review_page
    page.show_file(calibration)
    assert page.table.text("cam0", "views") == "40"
    assert page.table.text("cam1", "rms") == "0.31"
    assert page.table.text("cam1", "refinement") == "5.0 cm, 0.00°"
    assert page.table.text("cam0", "refinement") == "kept the board's pose"
    assert page.table.text("cam0", "height") == "2.50"
    views = page.table.keys.index("views")
    assert (
        page.table.item(page.table.rows["cam1"], views).background().color()
        == (COUNT_COLORS["red"])
    )
    assert page.summary.text() == (
        "2 sensors calibrated; reprojection RMS 0.20 px; 6 floor views: the world's origin is "
        "on the floor; refined from a walk: the sensors agree within 2.0 cm (5.0 cm before); "
        "cam0 kept the checkerboard's pose (the walk's correction contradicted its board views)."
    )


def test_one_view_is_one_view_not_one_views(wizard):
    page = wizard.extrinsics_page
    page.images.set_sensors(SENSORS)
    page.show_state(state("extrinsics", [sensor("cam0", 1, False), sensor("cam1", 2, False)]))
    assert page.images.tiles["cam0"].caption == "cam0: 1 view"
    assert page.images.tiles["cam1"].caption == "cam1: 2 views"
    intrinsics = wizard.intrinsics_page
    intrinsics.sensor.addItems(SENSORS)
    intrinsics.sensor.setCurrentText("cam1")
    intrinsics.show_state(state("intrinsics", [sensor("cam1", 1, False)]))
    assert intrinsics.tile.caption == "cam1: 1 view"


def test_a_refinement_that_changed_nothing_says_so_and_shows_no_after_plot(wizard):
    from optrack.calibration.live import RefinementReport
    from optrack.types import NetworkCalibration, SensorCalibration

    page = wizard.refinement_page
    walk = np.column_stack([np.linspace(0, 1, 20), np.zeros(20), np.full(20, 1.1)])
    report = RefinementReport(
        calibration=NetworkCalibration(
            sensors={"cam0": SensorCalibration(world_T_camera=matrix(np.eye(4)))}
        ),
        error_before_m=0.031,
        error_after_m=0.031,
        trajectories_before={"cam0": walk, "cam1": walk},
        trajectories_after={"cam0": walk, "cam1": walk},
    )
    page.show_report(report)
    text = page.figure.text()
    assert text.startswith("Nothing changed: no correction from the walk was applied")
    assert "3.1 cm on average" in text and "after" not in text
    assert page.after.isHidden()


def sides(corners):
    """The middle of each side of a board's outline (x, y)."""
    return [(corners[k, :2] + corners[(k + 1) % len(corners), :2]) / 2 for k in range(4)]


def green_at(view, point, reach: int = 3) -> bool:
    """Whether the Top view paints the guidance's green within ``reach`` pixels of the
    world point (x, y)."""
    from PySide6.QtCore import QPointF

    from app.widgets.top_view import GUIDANCE_COLOR

    view.resize(600, 600)
    view.setRange(xRange=(-3, 3), yRange=(-3, 3), padding=0)
    image = view.grab().toImage()
    scene = view.plotItem.vb.mapViewToScene(QPointF(float(point[0]), float(point[1])))
    at = view.mapFromScene(scene)
    ratio = image.devicePixelRatio()
    for du in range(-reach, reach + 1):
        for dv in range(-reach, reach + 1):
            colour = image.pixelColor(round((at.x() + du) * ratio), round((at.y() + dv) * ratio))
            rgb = np.array([colour.red(), colour.green(), colour.blue()])
            if np.abs(rgb - np.array(GUIDANCE_COLOR)).sum() < 60:
                return True
    return False


def test_the_extrinsics_page_says_where_to_hold_the_board_and_the_top_view_shows_it(qtbot):
    """The backend's guidance (optrack.runtime.calibration_guidance, real geometry): the
    page says it in a sentence, the main window's Top view draws the region and the board
    while the page is on screen, and clears them when the page is left."""
    from app.main_window import MainWindow
    from optrack.calibration.synthetic import look_at
    from optrack.runtime.calibration_guidance import BoardGuide

    window = MainWindow()
    qtbot.addWidget(window)
    wizard = CalibrationWizard(None, window, world_view=False)
    qtbot.addWidget(wizard)
    wizard.guidance_changed.connect(window.top_view.set_guidance)
    wizard.sensors = ["cam0", "cam1"]
    page = wizard.extrinsics_page
    page.images.set_sensors(wizard.sensors)
    guide = BoardGuide(wizard.board)
    guide.set_pose("cam0", look_at(np.array([-2.5, -2.0, 2.3]), np.array([0.0, 0.5, 0.9])))
    guide.set_pose("cam1", look_at(np.array([2.5, -2.0, 2.3]), np.array([0.0, 0.5, 0.9])))
    advised = guide.advise(
        state("extrinsics", [sensor("cam0", 12, True), sensor("cam1", 2, False)])
    )
    page.show_state(advised)
    x, y, _ = advised.guidance.center
    assert page.message.text().startswith(f"For cam1: stand at about ({x:.1f}, {y:.1f})")
    assert "facing cam1 and cam0" in page.message.text()
    region, board, label = window.top_view.guidance_items
    assert len(region.data) == len(advised.guidance.region) > 0
    x, y = board.getData()
    assert np.allclose(x[:4], advised.guidance.corners[:, 0])
    assert len(x) == 5 and (x[4], y[4]) == (x[0], y[0])  # closed
    assert label.textItem.toPlainText() == "board for cam1"
    # Drawn closed, as the screenshot shows it: the middle of every side is green.
    assert all(green_at(window.top_view, side) for side in sides(advised.guidance.corners))
    page.cleanupPage()  # Back: the views forget it
    assert window.top_view.guidance_items == []
    window.close()


def test_a_sensor_on_one_shared_board_pose_is_not_called_calibrated_and_next_waits(qtbot):
    """A sensor joined the network at its first shared view; the page calls it calibrated
    only once it shares calibration_live.min_shared_poses board poses: until then its
    status counts them, it is not green, Next waits, and the guide says where the next
    pose goes (away from the one it has) in a sentence that starts with the count."""
    from optrack.calibration.synthetic import look_at
    from optrack.runtime.calibration_guidance import BoardGuide

    wizard = CalibrationWizard(None, world_view=False)
    qtbot.addWidget(wizard)
    wizard.sensors = ["cam0", "cam1"]
    page = wizard.extrinsics_page
    page.images.set_sensors(wizard.sensors)
    rough = {
        "cam0": look_at(np.array([-2.5, -2.0, 2.3]), np.array([0.0, 0.5, 0.9])),
        "cam1": look_at(np.array([2.5, -2.0, 2.3]), np.array([0.0, 0.5, 0.9])),
    }
    guide = BoardGuide(wizard.board)
    for name, pose in rough.items():
        guide.set_pose(name, pose)
    shared = np.array([[0.0, 0.6, 1.3]])  # the one pose both share (the rough frame here)
    live = {}
    for name in rough:
        live[name] = sensor(name, 6, True, 0.2, shared_poses=1, shared_needed=2)
        live[name].world_T_camera = rough[name]
        live[name].shared_centers = shared
    advised = guide.advise(state("extrinsics", list(live.values()), [("cam0", "cam1", 6)]))
    page.show_state(advised)
    assert page.table.text("cam0", "status") == "1 of 2 shared views"
    assert page.graph.calibrated == set() and not page.isComplete()
    assert page.images.tiles["cam0"].caption == "cam0: 6 views"
    guidance = advised.guidance
    assert guidance is not None and guidance.found and guidance.sensor == "cam0"
    assert guidance.partners == ("cam1",)
    x, y, _ = guidance.center
    assert page.message.text().startswith(f"cam0: 1 of 2 shared views; stand at about ({x:.1f}")
    assert np.linalg.norm(guidance.center - shared[0]) >= guide.params.place_spacing
    for name in rough:  # a second pose shared: calibrated, green, Next
        live[name].shared_poses = 2
    done = guide.advise(state("extrinsics", list(live.values()), [("cam0", "cam1", 12)]))
    assert done.guidance is None
    page.show_state(done)
    assert page.table.text("cam0", "status") == "calibrated"
    assert page.graph.calibrated == {"cam0", "cam1"} and page.isComplete()
