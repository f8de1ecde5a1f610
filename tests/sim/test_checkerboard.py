"""The calibration checkerboard: found by OpenCV where it truly is, in colour and infrared;
the operator shows it to every sensor and pair, then lays it on the floor."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from optrack.geometry import invert, project, transform_points
from optrack.sim import Simulation
from optrack.sim.board_plan import neighbouring_pairs

CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 0.001)


def _eight_bit(image: np.ndarray) -> np.ndarray:
    if image.ndim == 3:
        return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    scale = 255.0 / max(float(np.percentile(image, 99.5)), 1.0)
    return np.clip(image.astype(np.float32) * scale, 0, 255).astype(np.uint8)


def _detected_vs_true(sim: Simulation, index: int, t: float, stream: str) -> np.ndarray:
    """Distances (px) from each corner OpenCV finds to the nearest true projection."""
    state = sim.snapshot(t)
    frame = sim.frame(index, 0, state, noise=False)
    board = sim.truth(state).boards[0]
    image = _eight_bit(getattr(frame, stream))
    found, corners = cv2.findChessboardCorners(image, (board.cols, board.rows))
    assert found, f"OpenCV did not find the board in the {stream} image"
    corners = cv2.cornerSubPix(image, corners, (3, 3), (-1, -1), CRITERIA).reshape(-1, 2)
    sensor = sim.sensors[index]
    camera_T_board = invert(sensor.world_T_camera) @ np.array(board.world_T_board)
    truth, _ = project(
        transform_points(camera_T_board, sim.board.pattern.object_points), sensor.model.intrinsics
    )
    assert len(corners) == board.cols * board.rows
    return np.linalg.norm(corners[:, None, :] - truth[None], axis=2).min(axis=1)


@pytest.mark.parametrize(
    ("model", "stream"),
    [
        ("kinect2", "color"),
        ("kinect2", "infrared"),
        ("kinect1", "color"),
        ("sr4500", "infrared"),
        ("stereo", "color"),
    ],
)
def test_noise_free_board_is_found_where_it_truly_is(model, stream):
    sim = Simulation("calibration", seed=0, sensor_model=model)
    first = sim.operator.steps[0]
    assert first.kind == "hold" and first.sensors == (0,)
    # The operator starts at the first spot: after raising the board, it is held there.
    t = sim.board.params.raise_seconds + 0.5
    errors = _detected_vs_true(sim, 0, t, stream)
    assert errors.max() < 0.5


def test_board_truth_is_exact_when_held_and_when_on_the_floor():
    sim = Simulation("calibration", seed=0, sensors=3)
    steps = sim.operator.steps
    on_floor = []
    for t in np.arange(0.0, sim.seconds, 0.5):
        truth = sim.truth(sim.snapshot(t), visibility=False)
        assert len(truth.boards) == 1
        board = truth.boards[0]
        pose = np.array(board.world_T_board)
        assert (board.cols, board.rows, board.square) == (6, 5, 0.15)
        if board.on_floor:
            on_floor.append(pose)
            assert pose[2, 3] == pytest.approx(sim.board.params.thickness, abs=1e-6)
            assert pose[:3, 2] @ [0.0, 0.0, 1.0] == pytest.approx(-1.0)  # face up
    assert len({tuple(np.round(p[:2, 3], 2)) for p in on_floor}) == sum(
        s.kind == "floor" for s in steps
    )


def test_operator_shows_the_board_to_every_sensor_and_neighbouring_pair():
    sim = Simulation("calibration", seed=0, sensors=3)
    held = {s.sensors for s in sim.operator.steps if s.kind == "hold"}
    assert {(0,), (1,), (2,)} <= held
    views = [s for s in sim.operator.steps]
    pairs = set(neighbouring_pairs([_view(s) for s in sim.sensors]))
    assert pairs <= held
    floor = [s for s in views if s.kind == "floor"]
    assert len(floor) == sim.scenario.board.floor_placements
    assert sim.seconds > sum(1 for _ in views) * sim.board.params.hold_seconds


def test_a_neighbouring_pair_sees_the_same_board_at_once():
    sim = Simulation("calibration", seed=0, sensors=3)
    pair_step = next(s for s in sim.operator.steps if len(s.sensors) == 2)
    index = sim.operator.steps.index(pair_step)
    # Run until that step's hold, then check both sensors find the board.
    t = 0.0
    while not (sim.operator.index == index and sim.operator.phase == "hold"):
        t += 0.25
        sim.snapshot(t)
        assert t < sim.seconds
    t += 0.5
    errors = [
        _detected_vs_true(sim, k, t, _calibration_stream(sim.sensors[k])) for k in pair_step.sensors
    ]
    assert all(e.max() < 0.5 for e in errors)


def _calibration_stream(sensor) -> str:
    return "infrared" if "infrared" in sensor.model.streams else "color"


def test_calibration_scenario_mixes_four_models_and_the_sr4500_shares_views_and_floor():
    sim = Simulation("calibration", seed=0)
    models = [s.model.name for s in sim.sensors]
    assert len(models) == 6 and set(models) == {"kinect2", "kinect1", "stereo", "sr4500"}
    sr = models.index("sr4500")
    held = [s.sensors for s in sim.operator.steps if s.kind == "hold"]
    floor = [s.sensors for s in sim.operator.steps if s.kind == "floor"]
    pairs = [tuple(sorted(h)) for h in held if len(h) == 2 and sr in h]
    assert len(pairs) == 4 and len(set(pairs)) == 2  # both neighbours, at two places each
    assert sum(1 for f in floor if sr in f) >= 2  # the floor plane, not one board
    assert all(any(k in f for f in floor) for k in range(6))


def test_the_sr4500_finds_the_board_on_its_upsampled_infrared_image():
    from optrack.calibration.board import Checkerboard as Board
    from optrack.calibration.board import find_corners

    sim = Simulation("calibration", seed=0)
    sr = next(s.index for s in sim.sensors if s.model.name == "sr4500")
    step = next(s for s in sim.operator.steps if s.sensors == (sr,))
    index = sim.operator.steps.index(step)
    t = 0.0
    while not (sim.operator.index == index and sim.operator.phase == "hold"):
        t += 0.25
        sim.snapshot(t)
        assert t < sim.seconds
    state = sim.snapshot(t + 0.5)
    frame = sim.frame(sr, 0, state)  # with the sensor's noise
    truth = sim.truth(state).boards[0]
    corners = find_corners(
        frame.infrared, Board(truth.cols, truth.rows, truth.square), infrared=True
    )
    assert corners is not None
    sensor = sim.sensors[sr]
    camera_T_board = invert(sensor.world_T_camera) @ np.array(truth.world_T_board)
    true_px, _ = project(
        transform_points(camera_T_board, sim.board.pattern.object_points), sensor.model.intrinsics
    )
    assert np.sqrt(np.mean(np.sum((corners - true_px) ** 2, axis=1))) < 0.3


def test_the_operator_stands_still_while_holding_the_board_near_a_wall():
    sim = Simulation("calibration", seed=0)
    spots = []
    for t in np.arange(0.0, 40.0, 0.1):
        sim.snapshot(float(t))
        if sim.operator.phase == "hold":
            spots.append((sim.operator.index, sim.crowd.pos[sim.operator_index].copy()))
    by_step: dict[int, list[np.ndarray]] = {}
    for index, xy in spots:
        by_step.setdefault(index, []).append(xy)
    assert len(by_step) >= 3
    for positions in by_step.values():
        assert np.ptp(np.array(positions), axis=0).max() < 1e-9


def _view(sensor):
    from optrack.sim.board_plan import SensorView

    model = sensor.model
    return SensorView(sensor.world_T_camera, model.intrinsics, model.min_range, model.max_range)


@pytest.mark.parametrize("sensors", [3, 4, 6])
def test_the_board_is_laid_until_each_sensor_saw_the_floor_at_several_places(sensors):
    """The ground page's plan on the default venue with 3, 4 and 6 sensors (one board far
    off per camera tilted the floor by tenths of a degree): at least floor_placements
    places, then more until each sensor saw the board on the floor at floor_per_sensor of
    them, or every floor spot it sees past the venue is taken by a nearer placement (the
    places keep floor_spacing apart); where a sensor sees it sharper is chosen first."""
    import msgspec

    from optrack.calibration.overlap import facing_rotations
    from optrack.geometry import make_pose
    from optrack.sim import board_plan
    from optrack.sim.scenario import BoardSpec, load_scenario

    spec = BoardSpec(cols=6, rows=5, square=0.15, steps="floor", floor_per_sensor=3)
    scenario = msgspec.structs.replace(load_scenario("mixed"), board=spec)
    sim = Simulation(scenario, seed=0, sensors=sensors, people=0)
    steps, board, params = sim.operator.steps, sim.board, sim.board.params
    assert len(steps) >= spec.floor_placements and all(s.kind == "floor" for s in steps)
    placed = np.array([s.world_T_board[:2, 3] for s in steps])  # board frame origins
    spots = placed + (steps[0].world_T_board[:3, :3] @ board.center)[:2]
    gaps = np.linalg.norm(spots[:, None] - spots[None], axis=2) + np.eye(len(spots)) * 99
    assert gaps.min() >= params.floor_spacing - 1e-6
    grid, _ = board_plan._hold_places(sim.venue, params)
    free = sim.venue.is_free(grid, float(np.max(board.hi - board.lo)) / 2 + params.spot_clearance)
    grid = grid[free]
    centers = np.column_stack([grid, np.full(len(grid), float(params.thickness))])
    rotations = facing_rotations(np.tile([0.0, 0.0, 1.0], (len(grid), 1)))
    for k, sensor in enumerate(sim.sensors):
        seen = sum(k in s.sensors for s in steps)
        if seen >= spec.floor_per_sensor:
            continue
        view = _view(sensor)
        sizes = board_plan._square_pixels(view, rotations, centers, board, params, True)
        for c in np.flatnonzero(sizes > 0):
            pose = make_pose(rotations[c], centers[c] - rotations[c] @ board.center)
            points = transform_points(pose, board_plan._sight_points(board))
            if board_plan._line_of_sight(sim.static.scene, [view], points):
                near = np.linalg.norm(spots - grid[c], axis=1).min()
                assert near < params.floor_spacing, (sensor.id, seen, grid[c])
    if sensors == 3:  # kinect2_2 sees the floor past the partition only, far off
        assert [sum(k in s.sensors for s in steps) >= 3 for k in range(3)] == [True, True, False]
