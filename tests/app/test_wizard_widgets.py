"""The wizard's live views draw what the live calibration's state says (offscreen Qt)."""

import time

import numpy as np
from PySide6.QtCore import QThread

from app.wizard.jobs import JobRunner, ProgressPanel
from app.wizard.widgets import (
    COUNT_COLORS,
    CovisibilityGraph,
    ImageTile,
    SensorTable,
    TrajectoryPlot,
    count_level,
)
from optrack.errors import UserError

from .test_main_window import image_array


def near(pixels: np.ndarray, color, tolerance: int = 30) -> np.ndarray:
    return np.abs(pixels.astype(int) - np.array(color)).sum(axis=2) < tolerance


def rgb(qcolor) -> tuple[int, int, int]:
    return (qcolor.red(), qcolor.green(), qcolor.blue())


def test_view_counts_are_red_below_fair_yellow_below_good_green_from_good():
    assert [count_level(n, 5, 20) for n in (0, 4, 5, 19, 20, 300)] == [
        "red",
        "red",
        "yellow",
        "yellow",
        "green",
        "green",
    ]


def test_sensor_table_colours_each_view_count_cell(qtbot):
    table = SensorTable([("sensor", "sensor"), ("views", "views"), ("rms", "RMS (px)")])
    qtbot.addWidget(table)
    table.set_rows(
        {"cam0": {"views": "3", "rms": ""}, "cam1": {"views": "40", "rms": "0.31"}},
        {"cam0": "red", "cam1": "green"},
    )
    assert table.rowCount() == 2
    assert table.text("cam1", "rms") == "0.31"
    views = table.keys.index("views")
    assert table.item(0, views).background().color() == COUNT_COLORS["red"]
    assert table.item(1, views).background().color() == COUNT_COLORS["green"]
    table.set_rows({"cam0": {"views": "12"}, "cam1": {"views": "41"}}, {"cam0": "yellow"})
    assert table.item(0, views).background().color() == COUNT_COLORS["yellow"]
    assert table.text("cam0", "views") == "12"


def test_covisibility_graph_draws_an_edge_per_shared_pair_with_its_count(qtbot):
    graph = CovisibilityGraph()
    qtbot.addWidget(graph)
    graph.resize(320, 260)
    graph.set_graph(
        ["cam0", "cam1", "cam2"],
        calibrated={"cam0", "cam1"},
        edges=[("cam1", "cam0", 14), ("cam1", "cam2", 0), ("cam0", "cam2", 3)],
        thresholds=(5, 10),
    )
    assert graph.edges == {("cam0", "cam1"): 14, ("cam0", "cam2"): 3}
    assert graph.levels == {("cam0", "cam1"): "green", ("cam0", "cam2"): "red"}
    pixels = image_array(graph.grab().toImage())
    where = graph.positions()
    green_nodes = near(pixels, (70, 160, 80))
    grey_nodes = near(pixels, (150, 150, 150))
    for sensor, grid in (("cam0", green_nodes), ("cam1", green_nodes), ("cam2", grey_nodes)):
        x, y = int(where[sensor].x()), int(where[sensor].y())
        assert grid[y - 3 : y + 4, x - 3 : x + 4].all(), sensor
    # The shared-view edge between cam0 and cam1 is drawn in the green edge colour.
    edge = near(pixels, rgb(COUNT_COLORS["green"].darker(130)), tolerance=40)
    assert edge.sum() > 50


def test_image_tile_tints_covered_cells_green_and_leaves_the_rest(qtbot):
    tile = ImageTile("cam0")
    qtbot.addWidget(tile)
    tile.resize(400, 330)
    image = np.full((120, 160), 128, dtype=np.uint8)
    coverage = np.zeros((3, 4))
    coverage[0, 0] = 1.0
    tile.set_view(image, board_seen=True, coverage=coverage, caption="cam0: 7 views")
    pixels = image_array(tile.grab().toImage()).astype(int)
    greenish = (pixels[..., 1] > pixels[..., 0] + 40) & (pixels[..., 1] > pixels[..., 2] + 40)
    height, width = greenish.shape
    top_left = greenish[: height // 2, : width // 3].sum()
    bottom_right = greenish[height // 2 :, width // 2 :].sum()
    assert top_left > 1000
    assert bottom_right == 0
    assert tile.caption == "cam0: 7 views"


def test_trajectory_plot_draws_one_curve_per_sensor(qtbot):
    plot = TrajectoryPlot("Before")
    qtbot.addWidget(plot)
    t = np.linspace(0, 2 * np.pi, 50)
    walk = np.column_stack([np.cos(t), np.sin(t), np.full_like(t, 1.2)])
    plot.set_trajectories({"cam0": walk, "cam1": walk + 0.1})
    assert set(plot.curves) == {"cam0", "cam1"}
    x, y = plot.curves["cam1"].getData()
    np.testing.assert_allclose(x, walk[:, 0] + 0.1)
    plot.set_trajectories({"cam2": walk})
    assert set(plot.curves) == {"cam2"}


def test_jobs_run_off_the_gui_thread_in_order_and_report_errors_as_sentences(qtbot):
    runner = JobRunner()
    panel = ProgressPanel()
    qtbot.addWidget(panel)
    gui_thread = QThread.currentThread()
    seen: list = []

    def slow(progress):
        progress(0.5, "half way")
        time.sleep(0.2)
        return QThread.currentThread() is gui_thread

    def refuse(progress):
        raise UserError("the board was never seen by two sensors at once; move it between them.")

    def crash(progress):
        raise ZeroDivisionError("division by zero")

    panel.begin("working")
    runner.submit("slow", slow, seen.append, seen.append, panel.update_progress)
    runner.submit("refuse", refuse, seen.append, seen.append)
    runner.submit("crash", crash, seen.append, seen.append)
    assert runner.busy  # submit returned at once: the GUI thread is free
    qtbot.waitUntil(lambda: not runner.busy, timeout=5000)
    assert seen[0] is False  # not on the GUI thread
    assert seen[1] == "the board was never seen by two sensors at once; move it between them."
    assert seen[2] == "crash failed unexpectedly (ZeroDivisionError: division by zero)."
    assert panel.bar.value() == 500 and panel.label.text() == "half way"
