"""Synthetic checkerboard sessions: known cameras, known boards, projected corners.

Pure geometry (no rendering): a ring of cameras around a room looks at its
centre; a board is carried through the room and now and then laid on the
floor; each camera that sees the board's face whole gets its corners,
projected with its intrinsics (distortion included) plus Gaussian noise.
Used by the calibration benchmark and the tests, where the truth is needed.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial.transform import Rotation

from optrack.calibration.board import Checkerboard
from optrack.geometry import make_pose, project, transform_points
from optrack.types import Intrinsics

__all__ = ["SyntheticSession", "look_at", "synthetic_session"]


def look_at(eye: np.ndarray, target: np.ndarray) -> np.ndarray:
    """world_T_camera of an upright OpenCV camera at ``eye`` looking at ``target``."""
    eye = np.asarray(eye, dtype=np.float64)
    z = np.asarray(target, dtype=np.float64) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return make_pose(np.stack([x, y, z], axis=1), eye)


@dataclasses.dataclass
class SyntheticSession:
    """Truth and observations of one simulated board session."""

    board: Checkerboard
    intrinsics: dict[str, Intrinsics]
    world_T_camera: dict[str, np.ndarray]
    world_T_board: list[np.ndarray]
    corners: list[dict[str, np.ndarray]]  # one {sensor: Nx2 pixels} per instant
    floor: list[bool]


def _visible(
    board: Checkerboard,
    world_T_board: np.ndarray,
    world_T_camera: np.ndarray,
    intrinsics: Intrinsics,
    max_angle_deg: float,
    margin_px: float,
) -> np.ndarray | None:
    """Projected corners when the camera sees the board's whole face, else None."""
    centre = transform_points(world_T_board, board.center[None])[0]
    to_camera = world_T_camera[:3, 3] - centre
    distance = float(np.linalg.norm(to_camera))
    facing = -world_T_board[:3, 2] @ to_camera / distance  # the face's normal is -z
    if facing < np.cos(np.radians(max_angle_deg)):
        return None
    camera_T_board = np.linalg.inv(world_T_camera) @ world_T_board
    points = transform_points(camera_T_board, board.object_points)
    if np.any(points[:, 2] < 0.3):
        return None
    pixels, _ = project(points, intrinsics)
    inside = (
        (pixels[:, 0] > margin_px)
        & (pixels[:, 0] < intrinsics.width - 1 - margin_px)
        & (pixels[:, 1] > margin_px)
        & (pixels[:, 1] < intrinsics.height - 1 - margin_px)
    )
    return pixels if inside.all() else None


def synthetic_session(
    sensors: int = 6,
    views: int = 100,
    *,
    floor_views: int = 3,
    seed: int = 0,
    noise_px: float = 0.3,
    board: Checkerboard | None = None,
    room_radius: float = 4.0,
    camera_height: float = 2.6,
    intrinsics: dict[str, Intrinsics] | None = None,
    max_angle_deg: float = 65.0,
    board_thickness: float = 0.005,
) -> SyntheticSession:
    """A session with ``views`` instants seen by two or more sensors, then
    ``floor_views`` instants with the board on the floor seen by at least one.

    Sensors are ``cam0..`` on a ring of ``room_radius`` m at ``camera_height``
    m looking at the room's centre; by default each is a 640x480 camera
    (fx = 525) with mild distortion.
    """
    rng = np.random.default_rng(seed)
    board = board if board is not None else Checkerboard(9, 6, 0.08)
    names = [f"cam{i}" for i in range(sensors)]
    if intrinsics is None:
        intrinsics = {
            name: Intrinsics(
                525.0 + 10 * i, 525.0 + 10 * i, 319.5, 239.5, 640, 480, (0.05, -0.1, 0.0, 0.0, 0.0)
            )
            for i, name in enumerate(names)
        }
    world_T_camera = _camera_ring(names, rng, room_radius, camera_height)
    session = SyntheticSession(board, intrinsics, world_T_camera, [], [], [])
    half = room_radius * 0.55

    def observe(world_T_board: np.ndarray, minimum: int) -> bool:
        seen = {}
        for name, pose in world_T_camera.items():
            pixels = _visible(board, world_T_board, pose, intrinsics[name], max_angle_deg, 5.0)
            if pixels is not None:
                seen[name] = pixels + rng.normal(0.0, noise_px, pixels.shape)
        if len(seen) < minimum:
            return False
        session.world_T_board.append(world_T_board)
        session.corners.append(seen)
        return True

    attempts = 0
    while len(session.world_T_board) < views:
        attempts += 1
        if attempts > 200 * views:
            raise RuntimeError("the synthetic room cannot produce enough shared views.")
        observe(_standing_board(rng, half, board), 2)
    placed = attempts = 0
    while placed < floor_views:
        attempts += 1
        if attempts > 1000 * max(floor_views, 1):
            raise RuntimeError("no camera of the synthetic room sees the floor.")
        placed += observe(_floor_board(rng, half, board, board_thickness), 1)
    session.floor = [False] * views + [True] * floor_views
    return session


def _camera_ring(
    names: list[str], rng: np.random.Generator, room_radius: float, camera_height: float
) -> dict[str, np.ndarray]:
    """world_T_camera of cameras spread round a ring, each looking near the room's centre."""
    world_T_camera = {}
    for i, name in enumerate(names):
        angle = 2 * np.pi * i / len(names) + rng.uniform(-0.1, 0.1)
        eye = np.array(
            [room_radius * np.cos(angle), room_radius * np.sin(angle), camera_height]
        ) + rng.uniform(-0.2, 0.2, 3)
        target = np.array([*rng.uniform(-0.5, 0.5, 2), 0.8])
        world_T_camera[name] = look_at(eye, target)
    return world_T_camera


def _standing_board(rng: np.random.Generator, half: float, board: Checkerboard) -> np.ndarray:
    """world_T_board of a board held somewhere in the room: its face (-z) looks
    horizontally (towards +y turned by a random yaw), tilted about its x axis and turned
    in its own plane."""
    centre = np.array([*rng.uniform(-half, half, 2), rng.uniform(0.6, 1.9)])
    yaw = rng.uniform(0, 2 * np.pi)
    tilt = rng.uniform(-0.5, 0.5)
    roll = rng.uniform(-0.4, 0.4)
    rotation = (
        Rotation.from_rotvec([0.0, 0.0, yaw]).as_matrix()
        @ Rotation.from_rotvec([np.pi / 2 + tilt, 0.0, 0.0]).as_matrix()
        @ Rotation.from_rotvec([0.0, 0.0, roll]).as_matrix()
    )
    return make_pose(rotation, centre - rotation @ board.center)


def _floor_board(
    rng: np.random.Generator, half: float, board: Checkerboard, thickness: float
) -> np.ndarray:
    """world_T_board of a board lying face up on the floor, turned at random."""
    rotation = Rotation.from_euler("z", rng.uniform(0, 2 * np.pi)).as_matrix() @ np.diag(
        [1.0, -1.0, -1.0]
    )
    centre = np.array([*rng.uniform(-half, half, 2), thickness])
    return make_pose(rotation, centre - rotation @ board.center)


def perturb_poses(
    world_T_camera: dict[str, np.ndarray],
    translation_m: float,
    rotation_deg: float,
    seed: int = 0,
) -> dict[str, np.ndarray]:
    """Each pose moved by ``translation_m`` and turned by ``rotation_deg`` about random
    axes through the camera (exactly those magnitudes), in the world frame."""
    rng = np.random.default_rng(seed)
    out = {}
    for sid, pose in sorted(world_T_camera.items()):
        direction = rng.normal(size=3)
        axis = rng.normal(size=3)
        turn = Rotation.from_rotvec(axis / np.linalg.norm(axis) * np.radians(rotation_deg))
        moved = pose.copy()
        moved[:3, :3] = turn.as_matrix() @ pose[:3, :3]
        moved[:3, 3] = pose[:3, 3] + direction / np.linalg.norm(direction) * translation_m
        out[sid] = moved
    return out


def synthetic_walk(
    world_T_camera: dict[str, np.ndarray],
    intrinsics: dict[str, Intrinsics],
    *,
    seconds: float = 60.0,
    fps: float = 15.0,
    seed: int = 0,
    half_size: float = 2.5,
    speed: float = 1.0,
    centroid_height: float = 0.9,
    noise_m: float = 0.02,
    surface_bias_m: float = 0.0,
    max_range: float = 6.0,
) -> tuple[np.ndarray, np.ndarray, dict[str, tuple[np.ndarray, np.ndarray]]]:
    """One person walking between random waypoints, and each sensor's detections of them.

    Returns (true times, true centroids Nx3, {sensor: (times, camera-frame centroids)}).
    A sensor detects the person when the centroid projects inside its image and is
    within ``max_range``; each detection has Gaussian noise ``noise_m`` and is pulled
    ``surface_bias_m`` towards the camera (the visible surface's centroid is nearer
    than the body's).
    """
    rng = np.random.default_rng(seed)
    times = np.arange(0.0, seconds, 1.0 / fps)
    position = rng.uniform(-half_size, half_size, 2)
    goal = rng.uniform(-half_size, half_size, 2)
    truth = []
    for t in times:
        step = goal - position
        if np.linalg.norm(step) < speed / fps:
            goal = rng.uniform(-half_size, half_size, 2)
        else:
            position = position + step / np.linalg.norm(step) * speed / fps
        bob = 0.02 * np.sin(2 * np.pi * 1.8 * t)
        truth.append([position[0], position[1], centroid_height + bob])
    truth = np.asarray(truth)
    detections = {}
    for sid, pose in world_T_camera.items():
        camera_T_world = np.linalg.inv(pose)
        points = transform_points(camera_T_world, truth).astype(np.float64)
        pixels, in_front = project(points, intrinsics[sid])
        k = intrinsics[sid]
        seen = (
            in_front
            & (points[:, 2] < max_range)
            & (pixels[:, 0] > 0)
            & (pixels[:, 0] < k.width - 1)
            & (pixels[:, 1] > 0)
            & (pixels[:, 1] < k.height - 1)
        )
        rays = points / np.linalg.norm(points, axis=1, keepdims=True)
        measured = points - surface_bias_m * rays + rng.normal(0.0, noise_m, points.shape)
        detections[sid] = (times[seen], measured[seen])
    return times, truth, detections
