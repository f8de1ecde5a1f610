"""Where a camera not calibrated yet shares a board view with a calibrated one
(optrack.calibration.overlap) and the live calibration's guidance built on it
(optrack.runtime.calibration_guidance)."""

from __future__ import annotations

import numpy as np

from optrack.calibration.board import Checkerboard
from optrack.calibration.live import LiveState, SensorLive
from optrack.calibration.overlap import (
    BoardLimits,
    SensorView,
    facing_rotations,
    square_pixels,
    suggest_board,
)
from optrack.calibration.synthetic import look_at
from optrack.geometry import invert, transform_points
from optrack.runtime.calibration_guidance import BoardGuide
from optrack.types import Intrinsics

BOARD = Checkerboard(6, 5, 0.15)
# A Kinect v2's colour camera, as its node finds the board in it.
K = Intrinsics(1060.0, 1060.0, 959.5, 539.5, 1920, 1080)


def view(position, target) -> SensorView:
    return SensorView(look_at(np.array(position), np.array(target)), K, 0.5, 4.5)


def corners_in_image(camera: SensorView, center, normal) -> bool:
    """Every inner corner of the board held at ``center`` facing ``normal`` projects into
    the camera's image, in front of it."""
    rotation = facing_rotations(np.asarray(normal, dtype=np.float64)[None])[0]
    middle = np.array([(BOARD.cols - 1) * BOARD.square / 2, (BOARD.rows - 1) * BOARD.square / 2])
    grid = np.stack(np.meshgrid(np.arange(BOARD.cols), np.arange(BOARD.rows)), -1).reshape(-1, 2)
    local = np.column_stack([grid * BOARD.square - middle, np.zeros(len(grid))])
    world = local @ rotation.T + center
    camera = transform_points(invert(camera.world_T_camera), world)
    u = K.fx * camera[:, 0] / camera[:, 2] + K.cx
    v = K.fy * camera[:, 1] / camera[:, 2] + K.cy
    return bool(
        (camera[:, 2] > 0).all() and (0 <= u).all() and (u < K.width).all() and (0 <= v).all()
    ) and bool((v < K.height).all())


def test_the_suggested_place_is_seen_whole_by_both_cameras():
    views = {
        "kinect2_0": view([-2.5, -2.0, 2.3], [0.0, 0.5, 0.9]),
        "kinect2_1": view([2.5, -2.0, 2.3], [0.0, 0.5, 0.9]),
        "kinect2_2": view([0.0, 3.0, 2.3], [0.0, 0.0, 0.9]),
    }
    suggestion = suggest_board(views, "kinect2_1", ["kinect2_0", "kinect2_2"], BOARD)
    assert suggestion.found and suggestion.sensor == "kinect2_1"
    assert len(suggestion.region) >= 4  # a floor area, not one spot
    for name in ("kinect2_1", *suggestion.partners):
        assert corners_in_image(views[name], suggestion.center, suggestion.normal), name
    x, y, height = suggestion.center
    sentence = suggestion.sentence()
    assert sentence.startswith(f"For kinect2_1: stand at about ({x:.1f}, {y:.1f})")
    assert f"{height:.1f} m high, facing kinect2_1 and {suggestion.partners[0]}" in sentence


def test_cameras_facing_each_other_share_no_held_board_and_the_sentence_says_move_one():
    views = {
        "a": view([-3.0, 0.0, 1.3], [3.0, 0.0, 1.3]),
        "b": view([3.0, 0.0, 1.3], [-3.0, 0.0, 1.3]),
    }
    suggestion = suggest_board(views, "b", ["a"], BOARD)
    assert not suggestion.found and len(suggestion.region) == 0
    assert "move or turn a camera" in suggestion.sentence()


def test_square_pixels_is_zero_outside_the_image_and_range():
    camera = view([0.0, 0.0, 1.3], [0.0, 2.0, 1.3])
    rotations = facing_rotations(np.array([[0.0, -1.0, 0.0]] * 3))
    centers = np.array([[0.0, 2.0, 1.3], [0.0, 9.0, 1.3], [5.0, 2.0, 1.3]])  # seen, far, aside
    w, h = 3.5 * BOARD.square, 3.0 * BOARD.square  # half the printed pattern (7x6 squares)
    outline = np.array([[-w, -h, 0.0], [w, -h, 0.0], [w, h, 0.0], [-w, h, 0.0]])
    sizes = square_pixels(camera, rotations, centers, outline, (7, 6), BoardLimits(0.06, 60, 7))
    assert sizes[0] > 7 and sizes[1] == 0 and sizes[2] == 0


def live(name: str, calibrated: bool) -> SensorLive:
    return SensorLive(name, 10 if calibrated else 3, None, calibrated, None, False, None, None, K)


def test_the_guide_puts_the_place_and_the_sentence_in_the_extrinsics_state():
    guide = BoardGuide(BOARD)
    state = LiveState(
        phase="extrinsics",
        sensors={"c0": live("c0", True), "c1": live("c1", False)},
        covisibility=[],
        floor_views=0,
        refinement_samples={},
        message="Show the board to c1 together with a calibrated camera (c0).",
    )
    assert guide.advise(state) == state  # no rough pose yet: the plain sentence
    guide.set_pose("c0", look_at(np.array([-2.5, -2.0, 2.3]), np.array([0.0, 0.5, 0.9])))
    guide.set_pose("c1", look_at(np.array([2.5, -2.0, 2.3]), np.array([0.0, 0.5, 0.9])))
    advised = guide.advise(state)
    assert advised.guidance is not None and advised.guidance.partners == ("c0",)
    assert advised.message == advised.guidance.sentence()
    assert advised.message.startswith("For c1: stand at about (")
    floor = LiveState(**{**state.__dict__, "phase": "floor"})
    assert guide.advise(floor) is floor  # only while cameras are calibrated


def test_the_guidance_is_drawn_in_the_calibrations_frame_until_the_floor_is_solved():
    """The solved poses are in the calibration's own frame until the floor is solved:
    the guide moves the place there through the calibrated partner's two poses."""
    from optrack.geometry import make_pose

    guide = BoardGuide(BOARD)
    rough = {
        "c0": look_at(np.array([-2.5, -2.0, 2.3]), np.array([0.0, 0.5, 0.9])),
        "c1": look_at(np.array([2.5, -2.0, 2.3]), np.array([0.0, 0.5, 0.9])),
    }
    for name, pose in rough.items():
        guide.set_pose(name, pose)
    frame_T_world = make_pose(np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]]), [1.0, 2.0, 0.5])
    c0 = live("c0", True)
    c0.world_T_camera = frame_T_world @ rough["c0"]
    state = LiveState("extrinsics", {"c0": c0, "c1": live("c1", False)}, [], 0, {}, "")
    guidance = guide.advise(state).guidance
    moved = guidance.in_frame()
    assert np.allclose(moved.center, transform_points(frame_T_world, guidance.center[None])[0])
    assert np.allclose(moved.corners, transform_points(frame_T_world, guidance.corners))
    assert moved.region.shape == (len(guidance.region), 3)
    # the board's corners sit around its centre, the printed face looking along the normal
    assert np.allclose(guidance.corners.mean(axis=0), guidance.center)
    edge = np.cross(
        guidance.corners[1] - guidance.corners[0], guidance.corners[3] - guidance.corners[0]
    )
    assert abs(abs(edge @ guidance.normal) / np.linalg.norm(edge) - 1) < 1e-9
