"""Skeletons in the window: the tracks table's skeleton column (only while skeletons come),
the 3D view's bones in the track's colour and joints coloured by confidence (OpenGL: run
under Xvfb) with the view.skeletons toggle, and the skeleton stages in the Parameters dock."""

from __future__ import annotations

import numpy as np
import pytest
from PySide6.QtCore import Qt

from app.source import node_schemas
from app.trails import track_color
from app.widgets.parameters_panel import ParametersPanel
from app.widgets.tracks_table import SKELETON_STALE_S, TracksTable
from app.widgets.world_view import BONES, confidence_color
from optrack.skeleton.joints import JOINTS
from optrack.types import Skeleton, SkeletonBatch

from .test_tracks_views import table_rows, two_people

HEIGHTS = {"head": 1.65, "neck": 1.5, "spine": 1.25, "pelvis": 0.95, "shoulder": 1.45}
HEIGHTS |= {"elbow": 1.15, "wrist": 0.9, "hip": 0.9, "knee": 0.5, "ankle": 0.1}


def standing(track_id: int, x: float, y: float, confidence: float = 1.0) -> Skeleton:
    """A standing skeleton at (x, y), arms hanging, facing x."""
    joints = {}
    for name in JOINTS:
        side, _, part = name.rpartition("_")
        across = {"left": 0.2, "right": -0.2}.get(side, 0.0)
        joints[name] = (x, y + across, HEIGHTS[part], confidence)
    return Skeleton(id=track_id, height=1.7, state="tracking", rate_hz=14.6, joints=joints)


def test_the_skeleton_column_comes_with_skeletons_and_goes_with_them(qtbot):
    table = TracksTable()
    qtbot.addWidget(table)
    table.model.set_batch(two_people(), now=100.0)
    assert table.model.columnCount() == 7  # skeletons off: the table as it always was
    table.model.set_skeletons(SkeletonBatch(stamp=10.0, skeletons=[standing(7, 1.25, -0.5)]), 100.0)
    assert table.model.columnCount() == 8
    assert table.model.headerData(7, Qt.Orientation.Horizontal, 0) == "skeleton"
    assert [row[-1] for row in table_rows(table)] == ["", "tracking 15 Hz"]  # track 3 has none
    table.model.set_batch(two_people(), now=100.0 + SKELETON_STALE_S / 2)
    assert table.model.columnCount() == 8
    table.model.set_batch(two_people(), now=100.0 + SKELETON_STALE_S * 2)
    assert table.model.columnCount() == 7  # the stage was turned off
    assert table_rows(table)[1] == ["7", "1.25", "-0.50", "1.72", "3.5", "0.91", "normal"]


def test_the_skeleton_stages_build_pages_in_the_parameters_dock(qtbot):
    schemas = node_schemas()
    assert {"skeleton_live", "skeleton", "skeleton_fusion"} <= set(schemas)
    panel = ParametersPanel()
    qtbot.addWidget(panel)
    panel.set_schemas(schemas)
    assert panel.editors["skeleton_live"]["enabled"].value() is False
    assert panel.editors["skeleton"]["particles"].value() == 2000


def test_confidence_runs_from_red_to_green():
    colors = confidence_color(np.array([0.0, 0.5, 1.0]))
    assert colors[0, :2].tolist() == [1.0, 0.0]
    assert colors[1, :2].tolist() == [1.0, 1.0]
    assert colors[2, :2].tolist() == [0.0, 1.0]


@pytest.mark.opengl
def test_skeletons_are_drawn_in_their_tracks_colour_and_toggled(qtbot):
    from .test_world_view import frame, same_hue, shown

    view = shown(qtbot)
    view.overlay.show_message("")
    before = frame(view)
    batch = SkeletonBatch(
        stamp=1.0, skeletons=[standing(2, -1.0, 0.0), standing(5, 2.0, 1.0, confidence=0.0)]
    )
    view.set_skeletons(batch)
    assert set(view.skeletons) == {2, 5}
    bones, joints = view.skeletons[2]
    assert bones.pos.shape == (2 * len(BONES), 3)
    assert len(joints.pos) == len(JOINTS)
    assert np.allclose(joints.color[:, :3], [0.0, 1.0, 0.1])  # confident: green
    assert np.allclose(view.skeletons[5][1].color[:, :3], [1.0, 0.0, 0.1])  # not: red
    after = frame(view)
    for track_id in (2, 5):
        rgb = track_color(track_id)
        assert same_hue(after, rgb).sum() > same_hue(before, rgb).sum() + 30
    view.set_show_skeletons(False)
    assert view.skeletons == {}
    view.set_show_skeletons(True)
    assert set(view.skeletons) == {2, 5}
    lost = Skeleton(id=5, height=1.7, state="lost")
    view.set_skeletons(SkeletonBatch(stamp=2.0, skeletons=[standing(2, -1.0, 0.0), lost]))
    assert set(view.skeletons) == {2}
    view.set_skeletons(SkeletonBatch(stamp=3.0))
    assert view.skeletons == {}
