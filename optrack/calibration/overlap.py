"""Where a checkerboard is seen by several cameras at once: the frustum overlap maths.

One piece of code for two users: the simulated operator's board plan
(:mod:`optrack.sim.board_plan`, which adds the venue's walls and lines of
sight) and the calibration wizard's guidance for a real operator
(:func:`suggest_board`: where to hold the board so that a camera not yet
calibrated shares a view with a calibrated one).

A board is held with its printed face looking along a ``normal``; a camera sees
it when the whole pattern is in its image (``image_margin`` from the border),
within its range, at an incidence of at most ``max_incidence_deg`` and with
squares of at least ``square_px_min`` pixels. Boards held for several cameras
face between them (the mean of the directions to them, tilted at most
``max_hold_tilt_deg``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence

import numpy as np

from optrack.calibration.board import Checkerboard
from optrack.geometry import invert, transform_points
from optrack.params import Param, Params, Schema, register
from optrack.types import Intrinsics

__all__ = [
    "GUIDANCE_PARAMS",
    "PLACEMENT_PARAMS",
    "BoardLimits",
    "BoardSuggestion",
    "SensorView",
    "facing_between",
    "facing_rotations",
    "square_pixels",
    "suggest_board",
]

#: Where a board can be held and seen: shared by the simulated operator's plan
#: (``sim_board``) and the wizard's guidance (``calibration_guidance``).
PLACEMENT_PARAMS = (
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
        "max_incidence_deg",
        60.0,
        10.0,
        85.0,
        1.0,
        "deg",
        "Largest angle between the board's normal and a sensor.",
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
        "place_spacing",
        0.6,
        0.1,
        5.0,
        0.1,
        "m",
        "A camera's further board pose is held at least this far from the ones it already "
        "shares (two places, not one twice: the extrinsics page asks each camera for "
        "calibration_live.min_shared_poses).",
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
)

GUIDANCE_PARAMS = register(
    Schema(
        "calibration_guidance",
        [
            *PLACEMENT_PARAMS,
            Param(
                "room_margin",
                1.0,
                0.0,
                10.0,
                0.5,
                "m",
                "Places are tried this far past the outermost cameras.",
            ),
            Param("min_range", 0.5, 0.0, 5.0, 0.1, "m", "Closest a board is seen."),
            Param("max_range", 4.5, 1.0, 20.0, 0.5, "m", "Furthest a board is suggested."),
        ],
        help="Where the calibration wizard suggests holding the board for a camera.",
    )
)


@dataclasses.dataclass
class SensorView:
    """What the overlap needs of a sensor: pose, intrinsics and working range."""

    world_T_camera: np.ndarray
    intrinsics: Intrinsics
    min_range: float
    max_range: float


@dataclasses.dataclass(frozen=True)
class BoardLimits:
    """When a camera sees a board well enough to find its corners."""

    image_margin: float  # fraction of the image size kept from its border
    max_incidence_deg: float
    square_px_min: float


def facing_rotations(normals: np.ndarray) -> np.ndarray:
    """Rotations (N, 3, 3) of boards whose printed face looks along ``normals`` (N, 3):
    z = -normal, x horizontal (world x for a board lying flat), y = z x x."""
    # (a zero normal, between two cameras facing each other, gives a board no camera sees)
    n = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    z = -n
    x = np.cross([0.0, 0.0, 1.0], n)
    flat = np.linalg.norm(x, axis=1) < 1e-6
    x[flat] = [1.0, 0.0, 0.0]
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=2)


def square_pixels(
    view: SensorView,
    rotations: np.ndarray,
    centers: np.ndarray,
    outline: np.ndarray,
    squares: tuple[int, int],
    limits: BoardLimits,
) -> np.ndarray:
    """For N board poses (rotations (N, 3, 3), pattern centres (N, 3)): the smallest
    square side, in pixels, with which the sensor sees the whole board (``outline``: its
    4 corners relative to the pattern's centre, board frame; ``squares``: squares along
    x and y) in its image and range and at a usable angle; 0 where it does not."""
    camera_T_world = invert(view.world_T_camera)
    world = np.einsum("nij,kj->nki", rotations, outline) + centers[:, None, :]
    camera = world @ camera_T_world[:3, :3].T + camera_T_world[:3, 3]
    z = camera[..., 2]
    k = view.intrinsics
    with np.errstate(divide="ignore", invalid="ignore"):
        u = k.fx * camera[..., 0] / z + k.cx
        v = k.fy * camera[..., 1] / z + k.cy
    mu, mv = limits.image_margin * k.width, limits.image_margin * k.height
    ok = np.all((z >= view.min_range) & (z <= view.max_range), axis=1)
    ok &= (u.min(axis=1) >= mu) & (u.max(axis=1) <= k.width - 1 - mu)
    ok &= (v.min(axis=1) >= mv) & (v.max(axis=1) <= k.height - 1 - mv)
    to_camera = view.world_T_camera[:3, 3] - centers
    cos_incidence = np.einsum("ni,ni->n", -rotations[:, :, 2], to_camera) / np.linalg.norm(
        to_camera, axis=1
    )
    ok &= cos_incidence >= math.cos(math.radians(limits.max_incidence_deg))
    sides = np.hypot(np.diff(u, axis=1, append=u[:, :1]), np.diff(v, axis=1, append=v[:, :1]))
    per_side = np.array([squares[0], squares[1]] * 2, dtype=np.float64)
    per_square = np.min(sides / per_side, axis=1)
    ok &= per_square >= limits.square_px_min
    return np.where(ok, per_square, 0.0)


def facing_between(
    views: Sequence[SensorView], centers: np.ndarray, max_tilt_deg: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The normals (N, 3) of boards at ``centers`` (N, 3) facing between ``views`` (the
    mean of the directions to them, tilted at most ``max_tilt_deg``), their horizontal
    directions (N, 2) and tilts (N, 1), radians."""
    normals = sum(
        (v.world_T_camera[:3, 3] - centers)
        / np.linalg.norm(v.world_T_camera[:3, 3] - centers, axis=1, keepdims=True)
        for v in views
    )
    flat = np.linalg.norm(normals[:, :2], axis=1, keepdims=True)
    horizontal = normals[:, :2] / np.maximum(flat, 1e-9)
    limit = math.radians(max_tilt_deg)
    tilt = np.clip(np.arctan2(normals[:, 2:], flat), -limit, limit)
    return np.concatenate([horizontal * np.cos(tilt), np.sin(tilt)], axis=1), horizontal, tilt


@dataclasses.dataclass
class BoardSuggestion:
    """Where to hold the board so that ``sensor`` shares a view with calibrated cameras.

    ``partners``: the calibrated cameras that see it there too (empty: no place found);
    ``region``: the floor points (K, 2) below every place that works; ``center`` and
    ``normal``: the best place's board centre and the direction its face looks."""

    sensor: str
    partners: tuple[str, ...]
    region: np.ndarray
    center: np.ndarray
    normal: np.ndarray
    corners: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 3)))
    #: the live calibration's frame from this one (its solved poses are in it until the
    #: floor is solved): see :meth:`in_frame`
    frame_T_world: np.ndarray | None = None
    #: (board poses the sensor shares with calibrated cameras, poses it needs): the
    #: sentence starts with them for a camera that is calibrated but needs more
    shared: tuple[int, int] | None = None

    @property
    def found(self) -> bool:
        return bool(self.partners)

    def floor_points(self) -> np.ndarray:
        """The region as 3D points on the floor (K, 3)."""
        return np.column_stack([self.region, np.zeros(len(self.region))])

    def in_frame(self) -> BoardSuggestion:
        """The same place in the live calibration's frame (``frame_T_world``): the region
        as 3D points (K, 3), the board's centre, normal and corners moved."""
        pose = np.eye(4) if self.frame_T_world is None else self.frame_T_world
        return dataclasses.replace(
            self,
            region=transform_points(pose, self.floor_points()),
            center=transform_points(pose, self.center[None])[0],
            normal=pose[:3, :3] @ self.normal,
            corners=transform_points(pose, self.corners),
            frame_T_world=None,
        )

    def sentence(self) -> str:
        """What the operator does, in one sentence."""
        if self.shared is not None:
            have, need = self.shared
            head = f"{self.sensor}: {have} of {need} shared views; "
            if not self.found:
                return head + (
                    "show it the board again together with a calibrated camera, at another "
                    "place than before (no such place was found from the cameras' poses)."
                )
            return head + self._place()
        if not self.found:
            return (
                f"No place was found where {self.sensor} and a calibrated camera both see "
                "the board whole: move or turn a camera so that their views overlap, or "
                "use a larger board."
            )
        return f"For {self.sensor}: {self._place()}"

    def _place(self) -> str:
        """Where to stand and how to hold the board (the end of the sentence)."""
        x, y, height = (float(c) for c in self.center)
        return (
            f"stand at about ({x:.1f}, {y:.1f}) with the board's centre {height:.1f} m high, "
            f"facing {' and '.join((self.sensor, *self.partners))} (the green area in the "
            "views)."
        )


def _board_outline(board: Checkerboard) -> tuple[np.ndarray, tuple[int, int]]:
    """The printed pattern's corners relative to its centre (board frame) and its squares
    along x and y (the inner corners plus one)."""
    s = board.square
    w, h = (board.cols + 1) * s, (board.rows + 1) * s
    outline = np.array(
        [[-w / 2, -h / 2, 0.0], [w / 2, -h / 2, 0.0], [w / 2, h / 2, 0.0], [-w / 2, h / 2, 0.0]]
    )
    return outline, (board.cols + 1, board.rows + 1)


def _places(views: Sequence[SensorView], params: Params) -> np.ndarray:
    """Board centres tried (M, 3): a grid around the cameras at each of the hold heights."""
    xy = np.array([v.world_T_camera[:2, 3] for v in views])
    margin, step = float(params.room_margin), float(params.grid_step)
    lo, hi = xy.min(axis=0) - margin, xy.max(axis=0) + margin
    xs = np.arange(lo[0], hi[0] + 1e-9, step)
    ys = np.arange(lo[1], hi[1] + 1e-9, step)
    grid = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
    heights = [float(h) for h in str(params.hold_heights).split(",") if h.strip()]
    places = np.concatenate([np.column_stack([grid, np.full(len(grid), h)]) for h in heights])
    cameras = np.array([v.world_T_camera[:3, 3] for v in views])
    near = np.linalg.norm(places[:, None, :] - cameras[None], axis=2).min(axis=1)
    return places[near >= float(params.min_range)]  # no board inside a camera


def suggest_board(
    views: Mapping[str, SensorView],
    sensor: str,
    calibrated: Sequence[str],
    board: Checkerboard,
    params: Params | None = None,
    avoid: np.ndarray | None = None,
) -> BoardSuggestion:
    """Where ``sensor`` (its pose a rough one: not calibrated yet) and the calibrated
    camera that sees the board sharpest with it both see the board whole, facing between
    them; ``found`` is False when no calibrated camera shares such a place. ``avoid``
    (K, 3): board centres the sensor already shares; places nearer than
    ``place_spacing`` to one of them are left out (a further pose, not the same again)."""
    params = params if params is not None else GUIDANCE_PARAMS.create()
    limits = BoardLimits(
        float(params.image_margin), float(params.max_incidence_deg), float(params.square_px_min)
    )
    outline, squares = _board_outline(board)
    target = views[sensor]
    centers = _places(list(views.values()), params)
    if avoid is not None and len(avoid):
        near = np.linalg.norm(centers[:, None, :] - np.asarray(avoid)[None], axis=2).min(axis=1)
        centers = centers[near >= float(params.place_spacing)]
    if not len(centers):
        return BoardSuggestion(sensor, (), np.zeros((0, 2)), np.zeros(3), np.zeros(3))
    best: tuple[float, str, np.ndarray, np.ndarray, np.ndarray] | None = None
    for partner in calibrated:
        pair = (target, views[partner])
        normals, _, _ = facing_between(pair, centers, float(params.max_hold_tilt_deg))
        rotations = facing_rotations(normals)
        sizes = np.stack(
            [square_pixels(v, rotations, centers, outline, squares, limits) for v in pair]
        )
        worst = sizes.min(axis=0)
        if worst.max() <= 0 or (best is not None and worst.max() <= best[0]):
            continue
        k = int(np.argmax(worst))
        best = (float(worst[k]), partner, centers[worst > 0, :2], centers[k], normals[k])
    if best is None:
        return BoardSuggestion(sensor, (), np.zeros((0, 2)), np.zeros(3), np.zeros(3))
    _, partner, region, center, normal = best
    rotation = facing_rotations(normal[None])[0]
    corners = outline @ rotation.T + center
    return BoardSuggestion(sensor, (partner,), np.unique(region, axis=0), center, normal, corners)
