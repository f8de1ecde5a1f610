"""The Tracks table and the Top view show the tracker's TrackBatch as it is."""

import numpy as np
import pytest
from PySide6.QtCore import Qt

from app.source import NO_SITE
from app.trails import TrailHistory
from app.widgets.top_view import TopView
from app.widgets.tracks_table import TracksTable
from optrack.geometry import make_pose
from optrack.types import (
    Intrinsics,
    NetworkCalibration,
    SensorCalibration,
    Track,
    TrackBatch,
    TrackStatus,
)

KINECT = Intrinsics(525.0, 525.0, 319.5, 239.5, width=640, height=480)


def batch(stamp: float, *tracks: Track, seq: int = 0) -> TrackBatch:
    return TrackBatch(stamp=stamp, seq=seq, tracks=list(tracks))


def two_people(stamp: float = 10.0) -> TrackBatch:
    return batch(
        stamp,
        Track(7, 1.25, -0.5, 1.72, age=3.5, confidence=0.91, status=TrackStatus.NORMAL),
        Track(3, -2.0, 2.125, 1.6, age=0.2, confidence=0.4, status=TrackStatus.MISSING),
        seq=42,
    )


def table_rows(table: TracksTable) -> list[list[str]]:
    model = table.model
    return [
        [model.index(r, c).data() for c in range(model.columnCount())]
        for r in range(model.rowCount())
    ]


def test_table_lists_every_track_sorted_by_id_with_units(qtbot):
    table = TracksTable()
    qtbot.addWidget(table)
    assert table.caption.text() == NO_SITE and table.model.rowCount() == 0
    table.set_batch(two_people())
    assert table_rows(table) == [
        ["3", "-2.00", "2.12", "1.60", "0.2", "0.40", "missing"],
        ["7", "1.25", "-0.50", "1.72", "3.5", "0.91", "normal"],
    ]
    headers = [table.model.headerData(c, Qt.Orientation.Horizontal, 0) for c in range(7)]
    assert headers == ["ID", "x (m)", "y (m)", "height (m)", "age (s)", "confidence", "status"]
    assert table.caption.text() == "2 people tracked at t = 10.00 s (frame 42)"


def test_table_drops_tracks_the_tracker_no_longer_reports(qtbot):
    table = TracksTable()
    qtbot.addWidget(table)
    table.set_batch(two_people())
    table.set_batch(batch(10.1, Track(7, 1.3, -0.5, 1.72)))
    assert [row[0] for row in table_rows(table)] == ["7"]
    table.set_batch(batch(10.2))
    assert table.model.rowCount() == 0
    assert table.caption.text().startswith("0 people tracked")


def test_trails_keep_the_last_seconds_and_forget_old_ids():
    trails = TrailHistory(seconds=1.0)
    for k in range(30):
        t = 0.125 * k
        tracks = [Track(1, t, 0.0, 1.7)] + ([Track(2, 0.0, t, 1.7)] if t < 1.0 else [])
        trails.update(batch(t, *tracks))
    assert trails.ids() == [1]  # id 2 was last seen more than a second ago
    path = trails.trail(1)
    assert path[0, 0] == 2.625 and path[-1, 0] == 3.625 and len(path) == 9
    # Frames of several sensors reach the tracker slightly out of order: the trail keeps
    # them all, in stamp order.
    trails.update(batch(3.6, Track(1, 3.6, 0.0, 1.7)))
    path = trails.trail(1)
    assert len(path) == 10 and list(path[-3:, 0]) == [3.5, 3.6, 3.625]
    trails.update(batch(0.0, Track(1, 5.0, 5.0, 1.7)))  # time went back: a replay restarted
    np.testing.assert_allclose(trails.trail(1), [[5.0, 5.0]])


def test_top_view_draws_tracks_with_their_ids_and_trails(qtbot):
    view = TopView(trail_seconds=5.0)
    qtbot.addWidget(view)
    view.resize(500, 500)
    for k in range(10):
        view.set_batch(batch(k * 0.1, Track(4, 0.1 * k, 1.0, 1.8), Track(9, -1.0, -0.1 * k, 1.7)))
    assert view.track_positions() == {
        4: pytest.approx((0.9, 1.0)),
        9: pytest.approx((-1.0, -0.9)),
    }
    assert view.labels() == {4: "4", 9: "9"}
    trail = view._trail_items[4].getData()
    np.testing.assert_allclose(trail[0], np.arange(10) * 0.1)
    view.set_batch(batch(1.0, Track(9, -1.0, -1.0, 1.7)))
    assert set(view.labels()) == {9}


def test_top_view_shows_the_floor_each_calibrated_camera_covers(qtbot):
    looking_down = make_pose(np.diag([1.0, -1.0, -1.0]), [2.0, 1.0, 3.0])
    calibration = NetworkCalibration(
        sensors={
            "ceiling": SensorCalibration(
                world_T_camera=tuple(map(tuple, looking_down)), intrinsics=KINECT
            ),
            "uncalibrated_intrinsics": SensorCalibration(
                world_T_camera=tuple(map(tuple, make_pose(translation=[-3, 0, 2])))
            ),
        }
    )
    view = TopView()
    qtbot.addWidget(view)
    view.set_calibration(calibration, max_depth=5.0)
    footprint = view.footprints["ceiling"]
    assert footprint.shape == (4, 2)
    np.testing.assert_allclose(footprint.mean(axis=0), [2.0, 1.0], atol=1e-9)
    assert "uncalibrated_intrinsics" not in view.footprints  # no intrinsics: no footprint
    (x0, x1), (y0, y1) = view.viewRange()
    assert x0 <= -3.0 and x1 >= 2.0  # both cameras in sight


def test_a_selected_track_stays_selected_while_it_moves(qtbot):
    table = TracksTable()
    qtbot.addWidget(table)
    table.set_batch(two_people(10.0))
    table.view.selectRow(1)
    table.set_batch(batch(10.1, Track(3, -2.0, 2.2, 1.6), Track(7, 1.3, -0.5, 1.72), seq=43))
    selected = table.view.selectionModel().selectedRows()
    assert [table.model.index(i.row(), 0).data() for i in selected] == ["7"]
    assert table.model.index(1, 1).data() == "1.30"


def test_a_negative_confidence_is_explained_where_it_is_shown(qtbot):
    table = TracksTable()
    qtbot.addWidget(table)
    person = Track(5, 0.5, 0.5, 1.7, age=9.0, confidence=-2.21, status=TrackStatus.NORMAL)
    table.set_batch(batch(3.0, person))
    column = 5
    assert table.model.index(0, column).data() == "-2.21"
    tip = table.model.index(0, column).data(Qt.ItemDataRole.ToolTipRole)
    assert "Below zero is normal" in tip and "HOG" in tip
    header = table.model.headerData(column, Qt.Orientation.Horizontal, Qt.ItemDataRole.ToolTipRole)
    assert header == tip
