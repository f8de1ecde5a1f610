"""A small ray-cast renderer of a checkerboard over a floor (infrared and depth), to
write recordings whose truth is known without the full simulator."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from optrack.calibration.board import Checkerboard
from optrack.calibration.synthetic import look_at
from optrack.geometry import invert, make_pose
from optrack.recording import BoardTruth, GroundTruth, RecordingWriter, SensorInfo
from optrack.types import Intrinsics, RGBDFrame

MARGIN_SQUARES = 0.8


def render(
    board: Checkerboard,
    intrinsics: Intrinsics,
    world_T_camera: np.ndarray,
    world_T_board: np.ndarray | None,
    supersample: int = 3,
) -> tuple[np.ndarray, np.ndarray]:
    """(infrared uint8, depth metres float32) of a board (printed face, white margin) over
    the floor z = 0, seen by a pinhole camera. The board is a thin plate: its face only."""
    h, w = intrinsics.height, intrinsics.width
    n = supersample
    u = (np.arange(w * n) + 0.5) / n - 0.5
    v = (np.arange(h * n) + 0.5) / n - 0.5
    uu, vv = np.meshgrid(u, v)
    rays = np.stack(
        [
            (uu - intrinsics.cx) / intrinsics.fx,
            (vv - intrinsics.cy) / intrinsics.fy,
            np.ones_like(uu),
        ],
        axis=-1,
    )
    depth = np.full(uu.shape, np.inf)
    shade = np.zeros(uu.shape)
    # floor z = 0 in the camera frame
    rotation, origin = world_T_camera[:3, :3], world_T_camera[:3, 3]
    up = rotation.T @ np.array([0.0, 0.0, 1.0])
    denominator = rays @ up
    with np.errstate(divide="ignore", invalid="ignore"):
        t_floor = -(origin[2]) / denominator
    hit = (t_floor > 0) & np.isfinite(t_floor)
    depth[hit] = t_floor[hit]
    floor_points = (rays[hit] * t_floor[hit, None]) @ rotation.T + origin
    shade[hit] = 0.45 + 0.05 * np.sin(3 * floor_points[:, 0]) * np.cos(2 * floor_points[:, 1])
    if world_T_board is not None:
        camera_T_board = invert(world_T_camera) @ world_T_board
        normal, point = camera_T_board[:3, 2], camera_T_board[:3, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            t_board = (normal @ point) / (rays @ normal)
        local = (rays * t_board[..., None] - point) @ camera_T_board[:3, :3]
        s = board.square
        lo = -(1 + MARGIN_SQUARES) * s
        inside = (
            (t_board > 0)
            & (t_board < depth)
            & (local[..., 0] > lo)
            & (local[..., 0] < (board.cols + MARGIN_SQUARES) * s)
            & (local[..., 1] > lo)
            & (local[..., 1] < (board.rows + MARGIN_SQUARES) * s)
        )
        i = np.floor(local[..., 0] / s)
        j = np.floor(local[..., 1] / s)
        printed = (i >= -1) & (i <= board.cols - 1) & (j >= -1) & (j <= board.rows - 1)
        dark = printed & ((i + j) % 2 == 0)
        depth[inside] = t_board[inside]
        front = point @ normal > 0  # the camera is on the printed side (the face looks along -z)
        shade[inside] = np.where(dark[inside], 0.05, 0.85) if front else 0.3
    infrared = shade.reshape(h, n, w, n).mean(axis=(1, 3))
    z = depth[n // 2 :: n, n // 2 :: n]
    z = np.where(np.isfinite(z) & (z < 10.0), z, 0.0).astype(np.float32)  # a 10 m range
    return np.clip(infrared * 255, 0, 255).astype(np.uint8), z


def standing_board(board: Checkerboard, centre: np.ndarray, facing: np.ndarray) -> np.ndarray:
    """world_T_board of an upright board whose printed face looks along ``facing``."""
    n = np.asarray(facing, dtype=np.float64)
    n /= np.linalg.norm(n)
    z = -n
    x = np.cross([0.0, 0.0, 1.0], n)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    rotation = np.stack([x, y, z], axis=1)
    return make_pose(rotation, np.asarray(centre) - rotation @ board.center)


def floor_board(
    board: Checkerboard, centre_xy: tuple[float, float], yaw: float, thickness: float = 0.005
) -> np.ndarray:
    """world_T_board of a board lying face up on the floor, its face ``thickness`` above it."""
    c, s = np.cos(yaw), np.sin(yaw)
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ np.diag([1.0, -1.0, -1.0])
    return make_pose(rotation, np.array([*centre_xy, thickness]) - rotation @ board.center)


def three_cameras() -> dict[str, np.ndarray]:
    return {
        "a": look_at(np.array([-2.4, -1.6, 2.2]), np.array([0.0, 0.0, 0.7])),
        "b": look_at(np.array([2.4, -1.5, 2.3]), np.array([0.0, 0.1, 0.7])),
        "c": look_at(np.array([0.2, 2.6, 2.1]), np.array([0.0, -0.2, 0.7])),
    }


def write_board_recording(
    out: Path,
    board: Checkerboard,
    placements: list[tuple[np.ndarray, bool]],
    cameras: dict[str, np.ndarray] | None = None,
    intrinsics: Intrinsics | None = None,
    hold_frames: int = 4,
    fps: float = 4.0,
) -> dict[str, np.ndarray]:
    """A recording: every placement held still for ``hold_frames`` frames, every sensor
    synchronised; infrared and depth; ground truth with the boards. Returns the poses."""
    cameras = cameras or three_cameras()
    k = intrinsics or Intrinsics(250.0, 250.0, 159.5, 119.5, 320, 240)
    infos = [
        SensorInfo(
            id=sid,
            intrinsics=k,
            model="kinect2",
            world_T_camera=tuple(tuple(float(v) for v in row) for row in pose),
            streams=["depth", "infrared"],
        )
        for sid, pose in cameras.items()
    ]
    seq = 0
    with RecordingWriter(out, infos, ground_truth=True, extra={"board": board.as_dict()}) as writer:
        for world_T_board, on_floor in placements:
            images = {
                sid: render(board, k, pose, world_T_board, 2) for sid, pose in cameras.items()
            }
            for _ in range(hold_frames):
                t = seq / fps
                for sid, (infrared, depth) in images.items():
                    writer.write(
                        RGBDFrame(
                            depth=depth,
                            intrinsics=k,
                            sensor_id=sid,
                            timestamp=t,
                            infrared=infrared,
                            seq=seq,
                        )
                    )
                writer.write_ground_truth(
                    GroundTruth(
                        t=t,
                        boards=[
                            BoardTruth(
                                world_T_board=tuple(
                                    tuple(float(v) for v in row) for row in world_T_board
                                ),
                                cols=board.cols,
                                rows=board.rows,
                                square=board.square,
                                on_floor=on_floor,
                            )
                        ],
                    )
                )
                seq += 1
    return cameras
