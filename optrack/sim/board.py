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

__all__ = ["BOARD_PARAMS", "BoardStep", "Checkerboard", "Operator", "plan_board_steps"]

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
                9.0,
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
                50.0,
                10.0,
                85.0,
                1.0,
                "deg",
                "Largest angle between the board's normal and a sensor.",
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
            Material("board_back", (0.3, 0.3, 0.3), 0.3),
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


@dataclasses.dataclass
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


def board_pose_facing(center: np.ndarray, normal: np.ndarray, board: Checkerboard) -> np.ndarray:
    """``world_T_board`` with the printed face looking along ``normal``, x horizontal,
    and the pattern's centre at ``center``."""
    n = np.asarray(normal, dtype=np.float64)
    n /= np.linalg.norm(n)
    z = -n
    x = np.cross([0.0, 0.0, 1.0], n)
    if np.linalg.norm(x) < 1e-6:  # lying flat: any horizontal x
        x = np.array([1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    rotation = np.stack([x, y, z], axis=1)
    return make_pose(rotation, np.asarray(center) - rotation @ board.center)


def _views_board(
    view: SensorView, world_T_board: np.ndarray, board: Checkerboard, params: Params, floor: bool
) -> float:
    """Square size in pixels at which the sensor sees the whole board (0 when it does not)."""
    camera_T_world = invert(view.world_T_camera)
    outline = transform_points(camera_T_world @ world_T_board, board.outline)
    k = view.intrinsics
    if np.any(outline[:, 2] < view.min_range) or np.any(outline[:, 2] > view.max_range):
        return 0.0
    u = k.fx * outline[:, 0] / outline[:, 2] + k.cx
    v = k.fy * outline[:, 1] / outline[:, 2] + k.cy
    mu, mv = params.image_margin * k.width, params.image_margin * k.height
    if u.min() < mu or u.max() > k.width - 1 - mu or v.min() < mv or v.max() > k.height - 1 - mv:
        return 0.0
    face_normal = -world_T_board[:3, 2]
    center = world_T_board[:3, :3] @ board.center + world_T_board[:3, 3]
    to_camera = view.world_T_camera[:3, 3] - center
    distance = float(np.linalg.norm(to_camera))
    cos_incidence = float(face_normal @ to_camera) / distance
    if cos_incidence < math.cos(math.radians(params.max_incidence_deg)):
        return 0.0
    # Smallest side of the projected pattern, in squares: foreshortening included.
    sides = np.hypot(np.diff(np.append(u, u[0])), np.diff(np.append(v, v[0])))
    per_square = min(
        sides[0] / (board.cols + 1),
        sides[1] / (board.rows + 1),
        sides[2] / (board.cols + 1),
        sides[3] / (board.rows + 1),
    )
    wanted = params.floor_square_px_min if floor else params.square_px_min
    return float(per_square) if per_square >= wanted else 0.0


def _line_of_sight(
    scene: o3d.t.geometry.RaycastingScene, views: list[SensorView], points: np.ndarray
) -> bool:
    rays = []
    for view in views:
        origin = view.world_T_camera[:3, 3]
        for point in points:
            rays.append(np.concatenate([origin, point - origin]))
    tensor = o3d.core.Tensor(np.asarray(rays, dtype=np.float32))
    blocked = scene.test_occlusions(tensor, tnear=0.0, tfar=0.995).numpy()
    return not bool(blocked.any())


def plan_board_steps(
    views: list[SensorView],
    venue: Venue,
    static_scene: o3d.t.geometry.RaycastingScene,
    spec: BoardSpec,
    params: Params | None = None,
    body_radius: float = 0.25,
) -> list[BoardStep]:
    """Board placements: one per sensor, one per neighbouring pair, then ``spec.floor_placements``
    on the floor. Placements no spot satisfies are skipped."""
    params = params if params is not None else BOARD_PARAMS.create()
    board = Checkerboard(spec, params)
    step = float(params.grid_step)
    xs = np.arange(-venue.half[0] + 0.5, venue.half[0] - 0.5 + 1e-9, step)
    ys = np.arange(-venue.half[1] + 0.5, venue.half[1] - 0.5 + 1e-9, step)
    grid = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
    heights = [float(h) for h in str(params.hold_heights).split(",") if h.strip()]
    steps: list[BoardStep] = []

    # Neighbouring pairs: sensors in order of their bearing around the room centre.
    bearings = [math.atan2(v.world_T_camera[1, 3], v.world_T_camera[0, 3]) for v in views]
    order = list(np.argsort(bearings))
    subsets: list[tuple[int, ...]] = [(i,) for i in range(len(views))]
    if len(views) == 2:
        subsets.append((0, 1))
    elif len(views) > 2:
        subsets += [
            tuple(sorted((int(order[k]), int(order[(k + 1) % len(order)]))))
            for k in range(len(order))
        ]

    for subset in subsets:
        chosen = [views[i] for i in subset]
        best, best_score = None, 0.0
        for xy in grid:
            for h in heights:
                center = np.array([xy[0], xy[1], h])
                to_cameras = [v.world_T_camera[:3, 3] - center for v in chosen]
                normal = sum(t / np.linalg.norm(t) for t in to_cameras)
                horizontal = np.array([normal[0], normal[1]])
                if np.linalg.norm(horizontal) < 1e-6:
                    continue
                heading = math.atan2(horizontal[1], horizontal[0])
                spot = xy - params.carry_distance * horizontal / np.linalg.norm(horizontal)
                if not venue.is_free(spot[None], body_radius + 0.05)[0]:
                    continue
                pose = board_pose_facing(center, normal, board)
                sizes = [_views_board(v, pose, board, params, floor=False) for v in chosen]
                if min(sizes) <= 0:
                    continue
                score = min(
                    min(s, params.square_px_wanted) / params.square_px_wanted for s in sizes
                )
                score -= 0.01 * abs(h - params.carry_height)
                if score > best_score:
                    outline = transform_points(pose, board.outline)
                    if _line_of_sight(static_scene, chosen, outline):
                        best, best_score = (pose, spot, heading), score
        if best is not None:
            steps.append(BoardStep("hold", best[0], best[1], best[2], subset))

    # Floor placements: flat, seen by as many sensors as possible, spread out.
    candidates = []
    for xy in grid[:: max(1, int(round(0.5 / step)))]:
        # x along the room's y axis for sensors looking along x, and so on.
        center = np.array([xy[0], xy[1], float(params.thickness)])
        pose = board_pose_facing(center, [0.0, 0.0, 1.0], board)
        if not venue.is_free(xy[None], max(board.hi - board.lo) / 2 + 0.1)[0]:
            continue
        seeing = [
            k for k, v in enumerate(views) if _views_board(v, pose, board, params, floor=True) > 0
        ]
        if not seeing:
            continue
        outline = transform_points(pose, board.outline)
        seeing = [k for k in seeing if _line_of_sight(static_scene, [views[k]], outline)]
        if seeing:
            candidates.append((len(seeing), pose, tuple(seeing), xy))
    chosen_xy: list[np.ndarray] = []
    candidates.sort(key=lambda c: -c[0])
    for count, pose, seeing, xy in candidates:
        if len(chosen_xy) >= spec.floor_placements:
            break
        if any(np.linalg.norm(xy - other) < params.floor_spacing for other in chosen_xy):
            continue
        # Stand beside the board, away from the sensors that see it.
        away = -sum(
            (views[k].world_T_camera[:2, 3] - xy)
            / np.linalg.norm(views[k].world_T_camera[:2, 3] - xy)
            for k in seeing
        )
        angle0 = math.atan2(away[1], away[0]) if np.linalg.norm(away) > 1e-6 else 0.0
        spot = None
        for delta in np.radians([0, 45, -45, 90, -90, 135, -135, 180]):
            angle = angle0 + delta
            candidate = xy + params.step_aside * np.array([math.cos(angle), math.sin(angle)])
            if venue.is_free(candidate[None], body_radius + 0.05)[0]:
                spot = candidate
                break
        if spot is None:
            continue
        heading = math.atan2(xy[1] - spot[1], xy[0] - spot[0])
        chosen_xy.append(xy)
        steps.append(BoardStep("floor", pose, spot, heading, seeing))
    return steps


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
            if np.linalg.norm(crowd.pos[i] - step.operator_spot) < crowd.params.arrive_radius * 0.5:
                self._enter(step.kind == "floor" and "lay" or "raise", t, self.pose_now)
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
            sway = p.sway_m * np.array(
                [math.sin(3.1 * t), math.sin(2.3 * t + 1.0), math.sin(1.7 * t + 2.0)]
            )
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
        self.phase, self.phase_start, self.from_pose = (
            phase,
            t,
            None if pose is None else pose.copy(),
        )

    def _next(self, t: float) -> None:
        self.index += 1
        self._enter("walk", t, None)

    def facing(self, crowd: Crowd, i: int, t: float) -> float | None:
        if self.done:
            return None
        return self.steps[self.index].operator_heading if self.phase != "walk" else None

    def wrists(self, crowd: Crowd, i: int, t: float) -> np.ndarray | None:
        if self.pose_now is None or self.on_floor or self.phase in ("lay", "pickup"):
            return None
        mid = (self.board.lo[1] + self.board.hi[1]) / 2
        edges = np.array([[self.board.hi[0], mid, 0.0], [self.board.lo[0], mid, 0.0]])
        return transform_points(self.pose_now, edges)

    def board_pose(self) -> np.ndarray | None:
        return self.pose_now

    def planned_seconds(self, start: np.ndarray) -> float:
        """A rough duration of the whole procedure (walking plus every phase)."""
        p, total, here = self.params, 0.0, np.asarray(start)
        for step in self.steps:
            total += np.linalg.norm(step.operator_spot - here) / p.operator_speed + 1.5
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
