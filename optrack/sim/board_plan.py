"""Where the operator shows the checkerboard: the placements of a calibration session.

Network calibration (OpenPTrack's procedure, Munaro et al. 2016, section 3):
the board held where one sensor, then each neighbouring pair of sensors, sees
it whole at a usable resolution, then laid on the floor at several places seen
by as many sensors as possible. Intrinsics: the board shown to one sensor at
places spread over its image, turned a different way each time.
"""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import open3d as o3d

from optrack.calibration.overlap import (
    BoardLimits,
    SensorView,
    facing_between,
    facing_rotations,
    square_pixels,
)
from optrack.geometry import invert, make_pose, transform_points
from optrack.params import Params
from optrack.sim.board import BOARD_PARAMS, PhysicalBoard
from optrack.sim.scenario import BoardSpec
from optrack.sim.venue import Venue

__all__ = [
    "INTRINSICS_CELLS",
    "INTRINSICS_HEIGHTS",
    "INTRINSICS_TURNS",
    "BoardStep",
    "SensorView",
    "board_pose_facing",
    "neighbouring_pairs",
    "plan_board_steps",
    "plan_intrinsics_steps",
]

LINE_OF_SIGHT_TFAR = 0.995  # a board corner hidden before 99.5 % of the way counts as hidden


@dataclasses.dataclass(eq=False)
class BoardStep:
    """One placement: the board's pose, where the operator stands and faces."""

    kind: str  # "hold" or "floor"
    world_T_board: np.ndarray
    operator_spot: np.ndarray
    operator_heading: float
    sensors: tuple[int, ...]
    square_px: float = 0.0  # the smallest square side the sensors see, pixels (held boards)


def board_pose_facing(center: np.ndarray, normal: np.ndarray, board: PhysicalBoard) -> np.ndarray:
    """``world_T_board`` with the printed face looking along ``normal``, x horizontal,
    and the pattern's centre at ``center``."""
    rotation = facing_rotations(np.asarray(normal, dtype=np.float64).reshape(1, 3))[0]
    return make_pose(rotation, np.asarray(center) - rotation @ board.center)


def _square_pixels(
    view: SensorView,
    rotations: np.ndarray,
    centers: np.ndarray,
    board: PhysicalBoard,
    params: Params,
    floor: bool,
) -> np.ndarray:
    """:func:`optrack.calibration.overlap.square_pixels` with the planner's limits for a
    held (or, ``floor``, a laid) board."""
    limits = BoardLimits(
        float(params.image_margin),
        float(params.floor_max_incidence_deg if floor else params.max_incidence_deg),
        float(params.floor_square_px_min if floor else params.square_px_min),
    )
    squares = (board.pattern.cols + 1, board.pattern.rows + 1)
    return square_pixels(view, rotations, centers, board.outline - board.center, squares, limits)


def _sight_points(board: PhysicalBoard) -> np.ndarray:
    """The board points whose lines of sight are checked (board frame): the outline and
    every inner corner, so a pillar in front of the middle of the pattern hides it too."""
    return np.concatenate([board.outline, board.pattern.object_points])


def _line_of_sight(
    scene: o3d.t.geometry.RaycastingScene, views: list[SensorView], points: np.ndarray
) -> bool:
    """Whether every sensor sees every point past the venue (nothing static in between)."""
    rays = [
        np.concatenate([v.world_T_camera[:3, 3], p - v.world_T_camera[:3, 3]])
        for v in views
        for p in points
    ]
    tensor = o3d.core.Tensor(np.asarray(rays, dtype=np.float32))
    return not bool(scene.test_occlusions(tensor, tnear=0.0, tfar=LINE_OF_SIGHT_TFAR).numpy().any())


def neighbouring_pairs(views: list[SensorView]) -> list[tuple[int, int]]:
    """Pairs of sensors next to each other in bearing around the room's centre."""
    if len(views) < 2:
        return []
    bearings = [math.atan2(v.world_T_camera[1, 3], v.world_T_camera[0, 3]) for v in views]
    order = [int(i) for i in np.argsort(bearings)]
    if len(views) == 2:
        return [(0, 1)]
    return [tuple(sorted((order[k], order[(k + 1) % len(order)]))) for k in range(len(order))]


def _hold_places(
    venue: Venue, params: Params, heights: tuple[float, ...] = ()
) -> tuple[np.ndarray, np.ndarray]:
    """The floor grid the operator's placements are chosen from (Nx2: every
    ``grid_step``, ``wall_clearance`` from the walls) and the board centres held over it
    (Mx3: the grid at each of ``heights``, else of ``hold_heights``)."""
    step, edge = float(params.grid_step), float(params.wall_clearance)
    xs = np.arange(-venue.half[0] + edge, venue.half[0] - edge + 1e-9, step)
    ys = np.arange(-venue.half[1] + edge, venue.half[1] - edge + 1e-9, step)
    grid = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
    if not heights:
        heights = tuple(float(h) for h in str(params.hold_heights).split(",") if h.strip())
    centers = np.concatenate([np.column_stack([grid, np.full(len(grid), h)]) for h in heights])
    return grid, centers


@dataclasses.dataclass
class _Room:
    """What every placement is checked against: the sensors, the venue's free floor and
    static scene (lines of sight), the board, the settings and the operator's size."""

    views: list[SensorView]
    venue: Venue
    scene: o3d.t.geometry.RaycastingScene
    board: PhysicalBoard
    params: Params
    body_radius: float


def plan_board_steps(
    views: list[SensorView],
    venue: Venue,
    static_scene: o3d.t.geometry.RaycastingScene,
    spec: BoardSpec,
    params: Params | None = None,
    body_radius: float = 0.25,
) -> list[BoardStep]:
    """Board placements: one per sensor, then pairs of sensors (see :func:`_pair_steps`:
    every sensor shares a view with the others wherever their views overlap), then up to
    ``spec.floor_placements`` on the floor (``spec.steps``: all of them, from the pairs
    on, or the floor only). A placement no spot satisfies is skipped.
    With ``spec.intrinsics_sensor`` set: :func:`plan_intrinsics_steps` for that sensor."""
    params = params if params is not None else BOARD_PARAMS.create()
    if spec.intrinsics_sensor >= 0:
        return plan_intrinsics_steps(
            views, spec.intrinsics_sensor, venue, static_scene, spec, params, body_radius
        )
    room = _Room(
        views, venue, static_scene, PhysicalBoard.from_spec(spec, params), params, body_radius
    )
    grid, centers = _hold_places(venue, params)
    # Held upright, facing one sensor, then between two (``spec.steps`` says which).
    steps: list[BoardStep] = []
    if spec.steps == "all":
        steps = [step for i in range(len(views)) if (step := _held_step(room, (i,), centers))]
    if spec.steps != "floor":
        steps += _pair_steps(room, centers)
    return steps + _floor_steps(room, grid, spec.floor_placements, spec.floor_per_sensor)


def _pair_steps(room: _Room, centers: np.ndarray) -> list[BoardStep]:
    """Held placements seen by two sensors at once: every neighbouring pair (by bearing)
    whose views overlap, and the pairs of a spanning tree of the sensors that see the
    board sharpest (Kruskal over every pair's best placement, largest squares first), so
    that every sensor shares a view with the others whenever some chain of overlaps joins
    it to them, whatever the layout."""
    found = {
        pair: step
        for pair in itertools.combinations(range(len(room.views)), 2)
        if (step := _held_step(room, pair, centers)) is not None
    }
    chosen = [pair for pair in neighbouring_pairs(room.views) if pair in found]
    group = list(range(len(room.views)))

    def root(i: int) -> int:
        while group[i] != i:
            i = group[i]
        return i

    for pair in chosen:
        group[root(pair[0])] = root(pair[1])
    for pair in sorted(found, key=lambda p: -found[p].square_px):
        a, b = root(pair[0]), root(pair[1])
        if a != b:
            group[a] = b
            chosen.append(pair)
    # Each pair at a second place too, ``place_spacing`` from the first (the extrinsics page
    # asks each sensor for calibration_live.min_shared_poses board poses; one pose leaves a
    # sensor where that one view put it).
    steps = []
    for pair in chosen:
        steps.append(found[pair])
        first = transform_points(found[pair].world_T_board, room.board.center[None])[0]
        far = np.linalg.norm(centers - first, axis=1) >= float(room.params.place_spacing)
        if (second := _held_step(room, pair, centers[far])) is not None:
            steps.append(second)
    return steps


def _held_step(room: _Room, subset: tuple[int, ...], centers: np.ndarray) -> BoardStep | None:
    """The best held placement among board ``centers`` (Mx3) for the sensors ``subset``:
    facing between them, seen whole by each, sharpest for the worst of them, near the
    carrying height; None when no spot satisfies them."""
    params, board = room.params, room.board
    chosen = [room.views[i] for i in subset]
    normals, horizontal, tilt = facing_between(chosen, centers, float(params.max_hold_tilt_deg))
    # The operator stands behind the board and behind its top edge, which leans back.
    lean = (board.center[1] - board.lo[1]) * np.abs(np.sin(tilt))
    spots = centers[:, :2] - (params.carry_distance + lean) * horizontal
    usable = room.venue.is_free(spots, room.body_radius + params.spot_clearance)
    rotations = facing_rotations(normals)
    sizes = np.stack([_square_pixels(v, rotations, centers, board, params, False) for v in chosen])
    score = np.minimum(sizes, params.square_px_wanted).min(axis=0) / params.square_px_wanted
    score -= params.height_preference * np.abs(centers[:, 2] - params.carry_height)
    score[~usable | (sizes.min(axis=0) <= 0)] = -np.inf
    sight = _sight_points(board)
    for best in np.argsort(-score):
        if not np.isfinite(score[best]):
            break
        pose = make_pose(rotations[best], centers[best] - rotations[best] @ board.center)
        if _line_of_sight(room.scene, chosen, transform_points(pose, sight)):
            heading = math.atan2(horizontal[best, 1], horizontal[best, 0])
            smallest = float(sizes[:, best].min())
            return BoardStep("hold", pose, spots[best], heading, subset, smallest)
    return None


def _floor_steps(room: _Room, grid: np.ndarray, count: int, per_sensor: int = 0) -> list[BoardStep]:
    """At least ``count`` placements lying on the floor (spots of ``grid``, Nx2), and more
    until every sensor that can see the floor has seen the board on it at ``per_sensor``
    of them; seen by as many sensors as possible, as sharply as possible, spread out.

    The floor's tilt in a camera comes from the boards that camera (or one near it) sees
    on the floor: a board far off, seen at a grazing angle, gives its plane to a few
    tenths of a degree, and one such board per camera tilted the floor of the default
    site enough to put a camera 6 m away 2 cm off in height. Greedy: each placement is
    worth, per sensor that sees it, its sharpness (the square size it sees, up to
    ``square_px_wanted``) over 1 + the placements that sensor already has, so the floor
    is shown to every sensor that can see it, where it sees it best."""
    params, board = room.params, room.board
    floor = grid[
        room.venue.is_free(grid, float(np.max(board.hi - board.lo)) / 2 + params.spot_clearance)
    ]
    centers = np.column_stack([floor, np.full(len(floor), float(params.thickness))])
    rotations = facing_rotations(np.tile([0.0, 0.0, 1.0], (len(floor), 1)))
    sizes = np.stack(
        [_square_pixels(v, rotations, centers, board, params, True) for v in room.views]
    )
    seen = sizes > 0
    sharp = np.minimum(sizes, float(params.square_px_wanted)) / float(params.square_px_wanted)
    placed = np.zeros(len(room.views))
    open_ = seen.any(axis=0)
    steps: list[BoardStep] = []
    while open_.any():
        if len(steps) >= count:  # then only spots a sensor still short of per_sensor sees
            short = placed < per_sensor
            open_ &= seen[short].any(axis=0)
        score = np.where(open_, (sharp / (1.0 + placed[:, None])).sum(axis=0), -np.inf)
        step = None
        for c in np.lexsort((np.arange(len(floor)), -score)):
            if not open_[c]:
                break
            open_[c] = False
            pose = make_pose(rotations[c], centers[c] - rotations[c] @ board.center)
            step = _floor_step(room, floor[c], pose, np.flatnonzero(seen[:, c]))
            if step is not None:
                open_ &= np.linalg.norm(floor - floor[c], axis=1) >= params.floor_spacing
                placed[list(step.sensors)] += 1
                steps.append(step)
                break
        if step is None:
            break
    return _nearest_next(steps)


def _nearest_next(steps: list[BoardStep]) -> list[BoardStep]:
    """The placements from the first, each next the nearest one left (a short walk)."""
    tour, left = steps[:1], steps[1:]
    while left:
        here = tour[-1].operator_spot
        tour.append(
            left.pop(int(np.argmin([np.linalg.norm(s.operator_spot - here) for s in left])))
        )
    return tour


def _floor_step(
    room: _Room, xy: np.ndarray, pose: np.ndarray, candidates: np.ndarray
) -> BoardStep | None:
    """The board lying at ``xy`` (``pose``): the ``candidates`` sensors that see it past
    the venue, and a spot beside it for the operator; None without either."""
    sight = transform_points(pose, _sight_points(room.board))
    seeing = tuple(int(k) for k in candidates if _line_of_sight(room.scene, [room.views[k]], sight))
    if not seeing:
        return None
    spot = _step_aside(
        room.venue, xy, [room.views[k] for k in seeing], room.params, room.body_radius
    )
    if spot is None:
        return None
    heading = math.atan2(xy[1] - spot[1], xy[0] - spot[0])
    return BoardStep("floor", pose, spot, heading, seeing)


#: The intrinsics plan spreads the board's centre over this many image cells a side, and
#: turns it (degrees left/right, up/down from facing the sensor) a different way each time:
#: turned far (45 degrees) and held low and high (board centre heights, m), so that the
#: views pin the lens's centre down (the intrinsics page calls a lens good by that,
#: calibration_intrinsics.good_std_px: 9 places turned at most 30 degrees, held at 1.0 to
#: 1.6 m, left it 0.5-0.8 px uncertain and up to 1.2 px off; these, 0.45-0.5 px after 12).
INTRINSICS_CELLS = 3
INTRINSICS_TURNS = (
    (0, 0),
    (45, 0),
    (-45, 0),
    (0, 30),
    (0, -30),
    (35, 25),
    (-35, -25),
    (35, -25),
    (-35, 25),
)
INTRINSICS_HEIGHTS = (0.7, 1.0, 1.3, 1.6, 1.9)


def plan_intrinsics_steps(
    views: list[SensorView],
    index: int,
    venue: Venue,
    static_scene: o3d.t.geometry.RaycastingScene,
    spec: BoardSpec,
    params: Params | None = None,
    body_radius: float = 0.25,
) -> list[BoardStep]:
    """Board placements for sensor ``index``'s intrinsics: ``spec.intrinsics_placements``
    held boards that it sees whole, their centres spread over its image (a grid of
    :data:`INTRINSICS_CELLS` cells) and each turned another way (:data:`INTRINSICS_TURNS`):
    Zhang's calibration needs the plane at several orientations (Zhang 2000, section
    3.3), and corners all over the image pin the distortion down. Each next placement is
    the least used cell and turn, nearest to where the operator stands."""
    params = params if params is not None else BOARD_PARAMS.create()
    if not 0 <= index < len(views):
        raise ValueError(f"sensor {index} is not one of the {len(views)} sensors")
    view, board = views[index], PhysicalBoard.from_spec(spec, params)
    step = float(params.grid_step)
    _, base = _hold_places(venue, params, INTRINSICS_HEIGHTS)
    to_camera = view.world_T_camera[:3, 3] - base
    heading = np.arctan2(to_camera[:, 1], to_camera[:, 0])
    elevation = np.arctan2(to_camera[:, 2], np.linalg.norm(to_camera[:, :2], axis=1))
    limit = math.radians(params.max_hold_tilt_deg)
    normals = []
    for yaw, pitch in INTRINSICS_TURNS:
        h = heading + math.radians(yaw)
        e = np.clip(elevation + math.radians(pitch), -limit, limit)
        normals.append(np.column_stack([np.cos(e) * np.cos(h), np.cos(e) * np.sin(h), np.sin(e)]))
    # every held centre once per turn, turn by turn
    centers_a = np.tile(base, (len(INTRINSICS_TURNS), 1))
    normals_a = np.concatenate(normals)
    turn = np.repeat(np.arange(len(INTRINSICS_TURNS)), len(base))
    horizontal = normals_a[:, :2] / np.maximum(
        np.linalg.norm(normals_a[:, :2], axis=1, keepdims=True), 1e-9
    )
    lean = (board.center[1] - board.lo[1]) * np.abs(normals_a[:, 2])
    spots = centers_a[:, :2] - (params.carry_distance + lean[:, None]) * horizontal
    rotations = facing_rotations(normals_a)
    size = _square_pixels(view, rotations, centers_a, board, params, False)
    ok = (size > 0) & venue.is_free(spots, body_radius + params.spot_clearance)
    camera = transform_points(invert(view.world_T_camera), centers_a)
    k = view.intrinsics
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.clip((k.fx * camera[:, 0] / camera[:, 2] + k.cx) / k.width, 0.0, 0.999)
        v = np.clip((k.fy * camera[:, 1] / camera[:, 2] + k.cy) / k.height, 0.0, 0.999)
    cell = np.where(ok, (v * INTRINSICS_CELLS).astype(int) * INTRINSICS_CELLS, 0)
    cell += np.where(ok, (u * INTRINSICS_CELLS).astype(int), 0)
    cell_uses = np.zeros(INTRINSICS_CELLS**2)
    turn_uses = np.zeros(len(INTRINSICS_TURNS))
    steps: list[BoardStep] = []
    here: np.ndarray | None = None
    open_ = ok.copy()
    while len(steps) < spec.intrinsics_placements and open_.any():
        walk = np.zeros(len(spots)) if here is None else np.linalg.norm(spots - here, axis=1)
        sharp = np.minimum(size, params.square_px_wanted) / params.square_px_wanted
        candidates = np.flatnonzero(open_)
        keys = (walk - sharp, turn_uses[turn], cell_uses[cell])
        order = candidates[np.lexsort(tuple(key[candidates] for key in keys))]
        for c in order:
            open_[c] = False
            pose = make_pose(rotations[c], centers_a[c] - rotations[c] @ board.center)
            if not _line_of_sight(
                static_scene, [view], transform_points(pose, _sight_points(board))
            ):
                continue
            bearing = math.atan2(horizontal[c, 1], horizontal[c, 0])
            steps.append(BoardStep("hold", pose, spots[c], bearing, (index,)))
            cell_uses[cell[c]] += 1
            turn_uses[turn[c]] += 1
            here = spots[c]
            # The same spot, height and turn once only.
            open_ &= ~(
                (turn == turn[c]) & (np.linalg.norm(centers_a - centers_a[c], axis=1) < step)
            )
            break
    return steps


def _step_aside(
    venue: Venue, xy: np.ndarray, views: list[SensorView], params: Params, body_radius: float
) -> np.ndarray | None:
    """Where the operator stands beside a board on the floor: away from the sensors
    that see it, on free floor."""
    away = -sum(
        (v.world_T_camera[:2, 3] - xy) / np.linalg.norm(v.world_T_camera[:2, 3] - xy) for v in views
    )
    angle0 = math.atan2(away[1], away[0]) if np.linalg.norm(away) > 1e-6 else 0.0
    for delta in np.radians([0, 45, -45, 90, -90, 135, -135, 180]):
        candidate = xy + params.step_aside * np.array(
            [math.cos(angle0 + delta), math.sin(angle0 + delta)]
        )
        if venue.is_free(candidate[None], body_radius + params.spot_clearance)[0]:
            return candidate
    return None
