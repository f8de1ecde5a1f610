"""The printed calibration checkerboard and the operator who carries it.

Board frame (as :class:`~optrack.recording.BoardTruth`): origin at the first
inner corner, x along the ``cols`` inner corners, y along the ``rows``, z
into the board, so the printed face looks along -z and a camera seeing the
face sees x to the right and y down (OpenCV's object-point convention).
Inner corner (i, j) is at (i * square, j * square, 0). The printed area
holds (cols + 1) x (rows + 1) squares, the square at (-1, -1) black, inside
a white margin.

The operator walks the board to spots chosen so that every sensor, and then
every neighbouring pair of sensors, sees the whole board at a usable
resolution, holds it still there, and finally lays it on the floor at
several places seen by as many sensors as possible (OpenPTrack's network
calibration procedure, Munaro et al. 2016, section 3).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import open3d as o3d
from scipy.spatial.transform import Rotation, Slerp

from optrack.geometry import invert, make_pose, transform_points
from optrack.params import Param, Params, Schema, register
from optrack.sim.crowd import Behaviour, Crowd
from optrack.sim.materials import Material
from optrack.sim.scenario import BoardSpec
from optrack.sim.venue import Venue
from optrack.types import Intrinsics

__all__ = [
    "BOARD_PARAMS",
    "BoardStep",
    "Checkerboard",
    "Operator",
    "SensorView",
    "board_pose_facing",
    "neighbouring_pairs",
    "plan_board_steps",
    "plan_intrinsics_steps",
]

PROGRESS = 0.1  # m: walking nearer by less than this is no progress
TREMOR = ((3.1, 0.0), (2.3, 1.0), (1.7, 2.0))  # rad/s and phase of the hand tremor per axis
BACK_ALBEDO, BACK_INFRARED = (0.3, 0.3, 0.3), 0.3  # the unprinted back and edges
TURN_SECONDS = 1.5  # planning allowance for starting, stopping and turning at a spot
LINE_OF_SIGHT_TFAR = 0.995  # a board corner hidden before 99.5 % of the way counts as hidden

BOARD_PARAMS = register(
    Schema(
        "sim_board",
        [
            Param(
                "margin_squares",
                0.8,
                0.2,
                3.0,
                0.1,
                "squares",
                "White border around the printed squares.",
            ),
            Param("thickness", 0.006, 0.001, 0.05, 0.001, "m", "Board thickness."),
            Param("white", 0.85, 0.3, 1.0, 0.01, "", "Albedo of the white squares (colour)."),
            Param("black", 0.04, 0.0, 0.3, 0.01, "", "Albedo of the black squares (colour)."),
            Param(
                "white_infrared", 0.8, 0.1, 1.0, 0.01, "", "Infrared albedo of the white squares."
            ),
            Param(
                "black_infrared",
                0.05,
                0.0,
                0.5,
                0.01,
                "",
                "Infrared albedo of the black squares (toner absorbs near infrared).",
            ),
            Param(
                "grip_depth",
                0.04,
                0.0,
                0.3,
                0.01,
                "m",
                "Hands hold the board this far behind its face.",
            ),
            Param("carry_height", 1.15, 0.5, 2.0, 0.05, "m", "Board centre height while walking."),
            Param(
                "carry_distance", 0.4, 0.2, 1.0, 0.05, "m", "Board centre in front of the operator."
            ),
            Param(
                "hold_heights",
                "1.0,1.3,1.6",
                help="Board centre heights tried at each spot, m (comma separated).",
            ),
            Param("grid_step", 0.25, 0.05, 1.0, 0.05, "m", "Spacing of the candidate spots."),
            Param(
                "square_px_min",
                7.0,
                3.0,
                50.0,
                0.5,
                "px",
                "Smallest square size (pixels) a sensor must see.",
            ),
            Param(
                "square_px_wanted",
                16.0,
                3.0,
                80.0,
                0.5,
                "px",
                "Square size (pixels) a spot aims for.",
            ),
            Param(
                "floor_square_px_min",
                6.0,
                2.0,
                50.0,
                0.5,
                "px",
                "Smallest square size seen on the floor.",
            ),
            Param(
                "max_incidence_deg",
                60.0,
                10.0,
                85.0,
                1.0,
                "deg",
                "Largest angle between the board's normal and a sensor.",
            ),
            Param(
                "floor_max_incidence_deg",
                65.0,
                10.0,
                85.0,
                1.0,
                "deg",
                "Largest angle between a board on the floor and a sensor.",
            ),
            Param(
                "max_hold_tilt_deg",
                30.0,
                0.0,
                80.0,
                1.0,
                "deg",
                "A held board's face looks at most this far above or below the horizontal "
                "(held steeper, its top edge would lean into the operator).",
            ),
            Param(
                "wall_clearance",
                0.5,
                0.0,
                3.0,
                0.05,
                "m",
                "Candidate spots keep this far from the walls.",
            ),
            Param(
                "spot_clearance",
                0.3,
                0.0,
                1.0,
                0.01,
                "m",
                "Free space around the operator's spots, beyond the body.",
            ),
            Param(
                "height_preference",
                0.01,
                0.0,
                1.0,
                0.01,
                "1/m",
                "Score lost per metre away from the carrying height.",
            ),
            Param(
                "image_margin",
                0.06,
                0.0,
                0.3,
                0.01,
                "",
                "The board keeps this fraction of the image size from its border.",
            ),
            Param(
                "floor_spacing",
                1.5,
                0.3,
                10.0,
                0.1,
                "m",
                "Minimum distance between floor placements.",
            ),
            Param(
                "step_aside",
                1.0,
                0.5,
                3.0,
                0.1,
                "m",
                "Where the operator stands beside a board on the floor.",
            ),
            Param(
                "raise_seconds",
                1.0,
                0.1,
                10.0,
                0.1,
                "s",
                "Time to turn and raise the board at a spot.",
            ),
            Param(
                "hold_seconds",
                2.5,
                0.2,
                30.0,
                0.1,
                "s",
                "Time the board is held still at each spot.",
            ),
            Param(
                "lay_seconds", 1.2, 0.1, 10.0, 0.1, "s", "Time to lay the board down or pick it up."
            ),
            Param("sway_m", 0.003, 0.0, 0.05, 0.001, "m", "Hand tremor while holding the board."),
            Param("operator_speed", 0.9, 0.2, 2.0, 0.05, "m/s", "The operator's walking speed."),
        ],
        help="The calibration checkerboard and the operator carrying it.",
    )
)


class Checkerboard:
    """Geometry and printed pattern of a checkerboard (see the module docstring)."""

    def __init__(self, spec: BoardSpec, params: Params | None = None) -> None:
        self.params = params if params is not None else BOARD_PARAMS.create()
        self.cols, self.rows, self.square = spec.cols, spec.rows, float(spec.square)
        margin = float(self.params.margin_squares)
        s = self.square
        self.lo = np.array([-(1 + margin) * s, -(1 + margin) * s])
        self.hi = np.array([(self.cols + margin) * s, (self.rows + margin) * s])
        self.center = np.array([(self.cols - 1) * s / 2, (self.rows - 1) * s / 2, 0.0])
        size = np.append(self.hi - self.lo, float(self.params.thickness))
        box = o3d.geometry.TriangleMesh.create_box(*size)
        self.vertices = np.asarray(box.vertices) + np.append(self.lo, 0.0)
        self.triangles = np.asarray(box.triangles)
        front = np.all(np.abs(self.vertices[self.triangles][:, :, 2]) < 1e-9, axis=1)
        self.triangle_front = front  # the printed face (z = 0)
        p = self.params
        self.materials = [
            Material("board_face", (p.white,) * 3, p.white_infrared, checker=True),
            Material("board_back", BACK_ALBEDO, BACK_INFRARED),
        ]

    @property
    def corners(self) -> np.ndarray:
        """The inner corners in the board frame, (cols * rows, 3), row by row."""
        i, j = np.meshgrid(np.arange(self.cols), np.arange(self.rows))
        return np.stack([i.ravel() * self.square, j.ravel() * self.square, np.zeros(i.size)], 1)

    @property
    def outline(self) -> np.ndarray:
        """The four outer corners of the printed squares, board frame, (4, 3)."""
        s = self.square
        x0, y0, x1, y1 = -s, -s, self.cols * s, self.rows * s
        return np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]], dtype=np.float64)

    def reflectance(self, board_xy: np.ndarray, footprint: np.ndarray) -> np.ndarray:
        """Fraction of white (0 black .. 1 white) seen by pixels at board points (N, 2)
        whose footprint on the board is ``footprint`` metres wide.

        The pattern is box-filtered over the footprint analytically (the filtered
        checkerboard of I. Quilez, iquilezles.org/articles/checkerfiltering), so that
        corners render with sub-pixel accuracy instead of staircases.
        """
        u = board_xy[:, 0] / self.square
        v = board_xy[:, 1] / self.square
        w = np.clip(footprint / self.square, 1e-3, 2.0)

        def square_wave(x: np.ndarray) -> np.ndarray:
            def tri(y: np.ndarray) -> np.ndarray:
                return np.abs(np.mod(y * 0.5, 1.0) - 0.5)

            return 2.0 * (tri(x - 0.5 * w) - tri(x + 0.5 * w)) / w

        value = 0.5 - 0.5 * square_wave(u) * square_wave(v)
        printed = (u >= -1.0) & (u <= self.cols) & (v >= -1.0) & (v <= self.rows)
        return np.where(printed, value, 1.0).astype(np.float32)


@dataclasses.dataclass(eq=False)
class BoardStep:
    """One placement: the board's pose, where the operator stands and faces."""

    kind: str  # "hold" or "floor"
    world_T_board: np.ndarray
    operator_spot: np.ndarray
    operator_heading: float
    sensors: tuple[int, ...]


@dataclasses.dataclass
class SensorView:
    """What the planner needs of a sensor: pose, intrinsics and working range."""

    world_T_camera: np.ndarray
    intrinsics: Intrinsics
    min_range: float
    max_range: float


def _facing_rotations(normals: np.ndarray) -> np.ndarray:
    """Rotations (N, 3, 3) of boards whose printed face looks along ``normals`` (N, 3):
    z = -normal, x horizontal (world x for a board lying flat), y = z x x."""
    n = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    z = -n
    x = np.cross([0.0, 0.0, 1.0], n)
    flat = np.linalg.norm(x, axis=1) < 1e-6
    x[flat] = [1.0, 0.0, 0.0]
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=2)


def board_pose_facing(center: np.ndarray, normal: np.ndarray, board: Checkerboard) -> np.ndarray:
    """``world_T_board`` with the printed face looking along ``normal``, x horizontal,
    and the pattern's centre at ``center``."""
    rotation = _facing_rotations(np.asarray(normal, dtype=np.float64).reshape(1, 3))[0]
    return make_pose(rotation, np.asarray(center) - rotation @ board.center)


def _square_pixels(
    view: SensorView,
    rotations: np.ndarray,
    centers: np.ndarray,
    board: Checkerboard,
    params: Params,
    floor: bool,
) -> np.ndarray:
    """For N candidate board poses (rotations (N, 3, 3), pattern centres (N, 3)): the
    smallest square side, in pixels, with which the sensor sees the whole pattern in
    its image and range and at a usable angle; 0 where it does not."""
    camera_T_world = invert(view.world_T_camera)
    local = board.outline - board.center  # (4, 3)
    world = np.einsum("nij,kj->nki", rotations, local) + centers[:, None, :]
    camera = world @ camera_T_world[:3, :3].T + camera_T_world[:3, 3]
    z = camera[..., 2]
    k = view.intrinsics
    with np.errstate(divide="ignore", invalid="ignore"):
        u = k.fx * camera[..., 0] / z + k.cx
        v = k.fy * camera[..., 1] / z + k.cy
    mu, mv = params.image_margin * k.width, params.image_margin * k.height
    ok = np.all((z >= view.min_range) & (z <= view.max_range), axis=1)
    ok &= (u.min(axis=1) >= mu) & (u.max(axis=1) <= k.width - 1 - mu)
    ok &= (v.min(axis=1) >= mv) & (v.max(axis=1) <= k.height - 1 - mv)
    to_camera = view.world_T_camera[:3, 3] - centers
    cos_incidence = np.einsum("ni,ni->n", -rotations[:, :, 2], to_camera) / np.linalg.norm(
        to_camera, axis=1
    )
    limit = params.floor_max_incidence_deg if floor else params.max_incidence_deg
    ok &= cos_incidence >= math.cos(math.radians(limit))
    sides = np.hypot(np.diff(u, axis=1, append=u[:, :1]), np.diff(v, axis=1, append=v[:, :1]))
    squares = np.array([board.cols + 1, board.rows + 1] * 2, dtype=np.float64)
    per_square = np.min(sides / squares, axis=1)
    wanted = params.floor_square_px_min if floor else params.square_px_min
    ok &= per_square >= wanted
    return np.where(ok, per_square, 0.0)


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


def _hold_places(venue: Venue, params: Params) -> tuple[np.ndarray, np.ndarray]:
    """The floor grid the operator's placements are chosen from (Nx2: every
    ``grid_step``, ``wall_clearance`` from the walls) and the board centres held over it
    (Mx3: the grid at each of ``hold_heights``)."""
    step, edge = float(params.grid_step), float(params.wall_clearance)
    xs = np.arange(-venue.half[0] + edge, venue.half[0] - edge + 1e-9, step)
    ys = np.arange(-venue.half[1] + edge, venue.half[1] - edge + 1e-9, step)
    grid = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
    heights = [float(h) for h in str(params.hold_heights).split(",") if h.strip()]
    centers = np.concatenate([np.column_stack([grid, np.full(len(grid), h)]) for h in heights])
    return grid, centers


def plan_board_steps(
    views: list[SensorView],
    venue: Venue,
    static_scene: o3d.t.geometry.RaycastingScene,
    spec: BoardSpec,
    params: Params | None = None,
    body_radius: float = 0.25,
) -> list[BoardStep]:
    """Board placements: one per sensor, one per neighbouring pair, then up to
    ``spec.floor_placements`` on the floor. A placement no spot satisfies is skipped.
    With ``spec.intrinsics_sensor`` set: :func:`plan_intrinsics_steps` for that sensor."""
    params = params if params is not None else BOARD_PARAMS.create()
    if spec.intrinsics_sensor >= 0:
        return plan_intrinsics_steps(
            views, spec.intrinsics_sensor, venue, static_scene, spec, params, body_radius
        )
    board = Checkerboard(spec, params)
    grid, centers = _hold_places(venue, params)
    steps: list[BoardStep] = []

    # Held upright, facing one sensor or between two.
    subsets: list[tuple[int, ...]] = [(i,) for i in range(len(views))] + neighbouring_pairs(views)
    for subset in subsets:
        chosen = [views[i] for i in subset]
        normals = sum(
            (v.world_T_camera[:3, 3] - centers)
            / np.linalg.norm(v.world_T_camera[:3, 3] - centers, axis=1, keepdims=True)
            for v in chosen
        )
        flat = np.linalg.norm(normals[:, :2], axis=1, keepdims=True)
        horizontal = normals[:, :2] / np.maximum(flat, 1e-9)
        tilt = np.clip(
            np.arctan2(normals[:, 2:], flat),
            -math.radians(params.max_hold_tilt_deg),
            math.radians(params.max_hold_tilt_deg),
        )
        normals = np.concatenate([horizontal * np.cos(tilt), np.sin(tilt)], axis=1)
        # The operator stands behind the board and behind its top edge, which leans back.
        lean = (board.center[1] - board.lo[1]) * np.abs(np.sin(tilt))
        spots = centers[:, :2] - (params.carry_distance + lean) * horizontal
        usable = venue.is_free(spots, body_radius + params.spot_clearance)
        rotations = _facing_rotations(normals)
        sizes = np.stack(
            [_square_pixels(v, rotations, centers, board, params, False) for v in chosen]
        )
        score = np.minimum(sizes, params.square_px_wanted).min(axis=0) / params.square_px_wanted
        score -= params.height_preference * np.abs(centers[:, 2] - params.carry_height)
        score[~usable | (sizes.min(axis=0) <= 0)] = -np.inf
        for best in np.argsort(-score):
            if not np.isfinite(score[best]):
                break
            pose = make_pose(rotations[best], centers[best] - rotations[best] @ board.center)
            if _line_of_sight(static_scene, chosen, transform_points(pose, board.outline)):
                heading = math.atan2(horizontal[best, 1], horizontal[best, 0])
                steps.append(BoardStep("hold", pose, spots[best], heading, subset))
                break

    # Lying on the floor, seen by as many sensors as possible, spread out.
    floor = grid[
        venue.is_free(grid, float(np.max(board.hi - board.lo)) / 2 + params.spot_clearance)
    ]
    centers = np.column_stack([floor, np.full(len(floor), float(params.thickness))])
    rotations = _facing_rotations(np.tile([0.0, 0.0, 1.0], (len(floor), 1)))
    seen = np.stack([_square_pixels(v, rotations, centers, board, params, True) > 0 for v in views])
    # Greedy: each placement is worth 1 / (1 + placements it already has) per sensor that
    # sees it, so the floor is shown to every sensor that can see it, not only to the
    # best-placed ones (the low-resolution ones see the floor only near them).
    placed = np.zeros(len(views))
    open_ = seen.any(axis=0)
    held = len(steps)
    while len(steps) - held < spec.floor_placements and open_.any():
        found = False
        score = np.where(open_, (seen / (1.0 + placed[:, None])).sum(axis=0), -np.inf)
        for c in np.lexsort((np.arange(len(floor)), -score)):
            if not open_[c]:
                break
            open_[c] = False
            xy = floor[c]
            pose = make_pose(rotations[c], centers[c] - rotations[c] @ board.center)
            outline = transform_points(pose, board.outline)
            seeing = tuple(
                int(k)
                for k in np.flatnonzero(seen[:, c])
                if _line_of_sight(static_scene, [views[k]], outline)
            )
            if not seeing:
                continue
            spot = _step_aside(venue, xy, [views[k] for k in seeing], params, body_radius)
            if spot is None:
                continue
            open_ &= np.linalg.norm(floor - xy, axis=1) >= params.floor_spacing
            placed[list(seeing)] += 1
            heading = math.atan2(xy[1] - spot[1], xy[0] - spot[0])
            steps.append(BoardStep("floor", pose, spot, heading, seeing))
            found = True
            break
        if not found:
            break
    return steps


#: The intrinsics plan spreads the board's centre over this many image cells a side, and
#: turns it (degrees left/right, up/down from facing the sensor) a different way each time.
INTRINSICS_CELLS = 3
INTRINSICS_TURNS = ((0, 0), (30, 0), (-30, 0), (0, 20), (0, -20), (25, 15), (-25, -15), (25, -15))


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
    view, board = views[index], Checkerboard(spec, params)
    step = float(params.grid_step)
    _, base = _hold_places(venue, params)
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
    rotations = _facing_rotations(normals_a)
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
            if not _line_of_sight(static_scene, [view], transform_points(pose, board.outline)):
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


class Operator(Behaviour):
    """The person carrying the board through its :class:`BoardStep` placements."""

    def __init__(self, steps: list[BoardStep], board: Checkerboard, start: np.ndarray) -> None:
        self.steps = steps
        self.board = board
        self.params = board.params
        self.start_point = np.asarray(start, dtype=np.float64)
        self.index = 0
        self.phase = "walk"
        self.phase_start = 0.0
        self.from_pose: np.ndarray | None = None
        self.pose_now: np.ndarray | None = None
        self.on_floor = False
        self.best, self.best_t = math.inf, 0.0

    def start(self, crowd: Crowd, i: int) -> np.ndarray:
        return self.start_point.copy()

    @property
    def done(self) -> bool:
        return self.index >= len(self.steps)

    def _carry_pose(self, crowd: Crowd, i: int) -> np.ndarray:
        heading = crowd.heading[i]
        forward = np.array([math.cos(heading), math.sin(heading), 0.0])
        center = (
            np.append(crowd.pos[i], self.params.carry_height) + self.params.carry_distance * forward
        )
        return board_pose_facing(center, forward, self.board)

    def goal(self, crowd: Crowd, i: int, t: float) -> tuple[np.ndarray | None, float]:
        p = self.params
        speed = float(p.operator_speed)
        if self.done:
            self.pose_now = self._carry_pose(crowd, i) if not self.on_floor else self.pose_now
            return None, 0.0
        step = self.steps[self.index]
        elapsed = t - self.phase_start
        if self.phase == "walk":
            self.pose_now = self._carry_pose(crowd, i)
            distance = float(np.linalg.norm(crowd.pos[i] - step.operator_spot))
            if distance < self.best - PROGRESS:
                self.best, self.best_t = distance, t
            stuck = t - self.best_t > crowd.params.stuck_seconds
            if distance < crowd.params.arrive_radius or stuck:
                self._enter("lay" if step.kind == "floor" else "raise", t, self.pose_now)
                return None, 0.0
            return step.operator_spot, speed
        if self.phase in ("raise", "lay"):
            duration = p.raise_seconds if self.phase == "raise" else p.lay_seconds
            self.pose_now = _interpolate(
                self.from_pose, step.world_T_board, min(elapsed / duration, 1.0)
            )
            if elapsed >= duration:
                self.on_floor = step.kind == "floor"
                self._enter("hold", t, step.world_T_board)
            return None, 0.0
        if self.phase == "hold":
            sway = p.sway_m * np.array([math.sin(rate * t + phase) for rate, phase in TREMOR])
            self.pose_now = step.world_T_board.copy()
            if not self.on_floor:
                self.pose_now[:3, 3] += sway
            if elapsed >= p.hold_seconds:
                if step.kind == "floor":
                    self._enter("pickup", t, step.world_T_board)
                else:
                    self._next(t)
            return None, 0.0
        if self.phase == "pickup":
            self.on_floor = False
            target = self._carry_pose(crowd, i)
            self.pose_now = _interpolate(self.from_pose, target, min(elapsed / p.lay_seconds, 1.0))
            if elapsed >= p.lay_seconds:
                self._next(t)
            return None, 0.0
        return None, 0.0

    def _enter(self, phase: str, t: float, pose: np.ndarray | None) -> None:
        self.best, self.best_t = math.inf, t
        self.phase, self.phase_start, self.from_pose = (
            phase,
            t,
            None if pose is None else pose.copy(),
        )

    def _next(self, t: float) -> None:
        self.index += 1
        self._enter("walk", t, None)

    def anchored(self, crowd: Crowd, i: int, t: float) -> bool:
        """Standing firm while raising, holding, laying or picking up the board."""
        return not self.done and self.phase != "walk"

    def facing(self, crowd: Crowd, i: int, t: float) -> float | None:
        if self.done:
            return None
        return self.steps[self.index].operator_heading if self.phase != "walk" else None

    def wrists(self, crowd: Crowd, i: int, t: float) -> np.ndarray | None:
        if self.pose_now is None or self.on_floor or self.phase in ("lay", "pickup"):
            return None
        # Hands grip the side edges from behind the board, clear of the printed face.
        mid = (self.board.lo[1] + self.board.hi[1]) / 2
        behind = float(self.params.thickness + self.params.grip_depth)
        edges = np.array([[self.board.hi[0], mid, behind], [self.board.lo[0], mid, behind]])
        return transform_points(self.pose_now, edges)

    def board_pose(self, crowd: Crowd, i: int) -> np.ndarray:
        """``world_T_board`` now (in the operator's hands before the first step)."""
        if self.pose_now is None:
            self.pose_now = self._carry_pose(crowd, i)
        return self.pose_now

    def planned_seconds(self, start: np.ndarray) -> float:
        """A rough duration of the whole procedure (walking plus every phase)."""
        p, total, here = self.params, 0.0, np.asarray(start)
        for step in self.steps:
            total += np.linalg.norm(step.operator_spot - here) / p.operator_speed + TURN_SECONDS
            here = step.operator_spot
            total += p.hold_seconds + (
                p.raise_seconds if step.kind == "hold" else 2 * p.lay_seconds
            )
        return float(total)


def _interpolate(a: np.ndarray | None, b: np.ndarray, s: float) -> np.ndarray:
    if a is None:
        return b.copy()
    s = float(np.clip(s, 0.0, 1.0))
    slerp = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([a[:3, :3], b[:3, :3]])))
    return make_pose(slerp([s])[0], (1 - s) * a[:3, 3] + s * b[:3, 3])
