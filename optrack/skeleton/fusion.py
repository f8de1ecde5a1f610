"""One person's cloud from every sensor at one instant: the skeleton's input.

Each sensor's depth frame becomes world points (:func:`world_points`: the
geometry's backprojection, then the sensor's ``world_T_camera``), only in the
image rectangle where the person's cylinder (below) can appear
(:func:`person_roi`), without the pixels on depth edges (:func:`drop_edges`:
flying pixels, which sit in mid-air between a silhouette and what is behind
it); the frames fused at an instant are each sensor's nearest within half its
frame period (:func:`nearest_frames`). A person's points are those in a vertical cylinder
around their floor position (:func:`person_mask`): within ``radius`` of
(x, y) on the floor, above ``floor_margin`` (the floor itself) and below
their height plus ``head_margin``; a point nearer (on the floor) to another
person's position than to theirs is left to that person. The cloud is then
decimated (:func:`decimate`): one point per occupied ``voxel`` (the mean of
its points, which evens out near and far sensors' densities), then a random
subset of at most ``points``. :func:`person_cloud` does it all from frames.

The crop is geometric: walls or furniture within ``radius`` of a person are
kept; in the runtime the detector's segmentation removes them first.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import msgspec
import numba
import numpy as np

from optrack.geometry import backproject_points, invert, project, transform_points
from optrack.params import Param, Params, Schema, register
from optrack.types import Intrinsics, RGBDFrame

__all__ = [
    "FUSION_PARAMS",
    "decimate",
    "drop_edges",
    "fuse_person",
    "nearest_frames",
    "person_cloud",
    "person_mask",
    "person_points",
    "person_roi",
    "world_points",
]

FUSION_PARAMS = register(
    Schema(
        "skeleton_fusion",
        [
            Param(
                "radius",
                0.9,
                min=0.2,
                max=3.0,
                step=0.05,
                unit="m",
                help="A person's points lie within this distance of their floor position.",
            ),
            Param(
                "floor_margin",
                0.04,
                min=0.0,
                max=0.5,
                step=0.01,
                unit="m",
                help="Points lower than this are the floor, not the person.",
            ),
            Param(
                "head_margin",
                0.25,
                min=0.0,
                max=1.0,
                step=0.05,
                unit="m",
                help="Points higher than the person's height plus this are not theirs.",
            ),
            Param(
                "edge_jump",
                0.1,
                min=0.0,
                max=2.0,
                step=0.01,
                unit="m",
                help="A depth pixel that differs by more than this from a neighbour (or has an "
                "invalid one) is dropped: flying pixels between a silhouette and the "
                "background; 0 keeps every pixel.",
            ),
            Param(
                "voxel",
                0.02,
                min=0.0,
                max=0.2,
                step=0.005,
                unit="m",
                help="Decimation grid: one point (the mean) per occupied voxel; 0 keeps every "
                "point.",
            ),
            Param(
                "points",
                500,
                min=10,
                max=100000,
                step=10,
                help="At most this many points per person (a random subset of the voxels').",
            ),
            Param(
                "stride",
                1,
                min=1,
                max=8,
                step=1,
                help="Depth pixels taken every this many rows and columns.",
            ),
        ],
        help="How each person's points are gathered from every sensor for the skeleton.",
    )
)


ROI_MARGIN_PX = 4  # pixels added around a projected cylinder (distortion, rounding)

Roi = tuple[int, int, int, int]  # u0, v0, u1, v1: columns u0..u1-1, rows v0..v1-1


def drop_edges(depth_m: np.ndarray, jump: float) -> np.ndarray:
    """The depth image (metres) with 0 wherever a 4-neighbour differs by more than
    ``jump`` or is invalid (0 or NaN)."""
    depth = np.asarray(depth_m, dtype=np.float32)
    bad = ~(depth > 0)
    with np.errstate(invalid="ignore"):
        rows = ~(np.abs(depth[1:] - depth[:-1]) <= jump)
        cols = ~(np.abs(depth[:, 1:] - depth[:, :-1]) <= jump)
    bad[1:] |= rows
    bad[:-1] |= rows
    bad[:, 1:] |= cols
    bad[:, :-1] |= cols
    return np.where(bad, np.float32(0.0), depth)


def world_points(
    frame: RGBDFrame,
    world_T_camera: np.ndarray,
    stride: int = 1,
    roi: Roi | None = None,
    edge_jump: float = 0.0,
) -> np.ndarray:
    """The frame's valid depth pixels (within ``roi``, default the whole image; without
    edges, :func:`drop_edges`, when ``edge_jump`` > 0) as world points (N, 3) float32."""
    depth = frame.depth
    intrinsics = frame.intrinsics
    if roi is not None:
        u0, v0, u1, v1 = roi
        depth = depth[v0:v1, u0:u1]
        intrinsics = msgspec.structs.replace(
            intrinsics,
            cx=intrinsics.cx - u0,
            cy=intrinsics.cy - v0,
            width=u1 - u0,
            height=v1 - v0,
        )
    if depth.dtype == np.uint16:
        depth = depth * np.float32(frame.depth_scale)  # 0 (invalid) stays 0
    if edge_jump > 0.0:
        depth = drop_edges(depth, edge_jump)
    points, _ = backproject_points(depth, intrinsics, stride)
    return _to_world(world_T_camera, points)


def _to_world(world_T_camera: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``world_T_camera`` applied to camera points (N, 3), float32, by columns: the
    (N, 3) x (3, 3) product of :func:`~optrack.geometry.transform_points` goes to BLAS,
    whose threads spin on a busy machine (2 to 60 ms of CPU for 100 000 points, measured
    on a person's rectangle; this is about 1 ms)."""
    pose = np.asarray(world_T_camera, dtype=np.float32)
    points = np.asarray(points, dtype=np.float32)
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    out = np.empty((len(points), 3), dtype=np.float32)
    for i in range(3):
        out[:, i] = x * pose[i, 0] + y * pose[i, 1] + z * pose[i, 2] + pose[i, 3]
    return out


def _box_in_camera(
    world_T_camera: np.ndarray, xy: Sequence[float], height: float, params: Params
) -> np.ndarray:
    """The corners (8, 3) of the box around the person's cylinder, in the camera's frame."""
    r = float(params.radius)
    corners = np.array(
        [
            (float(xy[0]) + sx * r, float(xy[1]) + sy * r, z)
            for sx in (-1, 1)
            for sy in (-1, 1)
            for z in (float(params.floor_margin), float(height) + float(params.head_margin))
        ]
    )
    return transform_points(invert(world_T_camera), corners)


def person_roi(
    intrinsics: Intrinsics,
    shape: tuple[int, int],
    world_T_camera: np.ndarray,
    xy: Sequence[float],
    height: float,
    params: Params,
) -> Roi | None:
    """The image rectangle (of an image ``shape`` (rows, columns)) holding the person's
    cylinder: the projection of its bounding box, the whole image when the box reaches
    behind the camera, None when it falls outside the image."""
    rows, cols = shape
    camera = _box_in_camera(world_T_camera, xy, height, params)
    if np.any(camera[:, 2] <= 0.05):
        return 0, 0, cols, rows
    pixels, _ = project(camera, intrinsics)
    u0, v0 = np.floor(pixels.min(axis=0)).astype(int) - ROI_MARGIN_PX
    u1, v1 = np.ceil(pixels.max(axis=0)).astype(int) + ROI_MARGIN_PX + 1
    u0, v0, u1, v1 = max(u0, 0), max(v0, 0), min(u1, cols), min(v1, rows)
    return (int(u0), int(v0), int(u1), int(v1)) if u1 > u0 and v1 > v0 else None


def nearest_frames(
    stamps: Mapping[str, np.ndarray], t: float, periods: Mapping[str, float]
) -> dict[str, int]:
    """For each sensor, the index of its frame stamped nearest ``t`` (its stamps ascending),
    if within half its frame period; sensors with none that near are left out."""
    chosen: dict[str, int] = {}
    for sid, times in stamps.items():
        times = np.asarray(times, dtype=np.float64)
        if not len(times):
            continue
        i = int(np.searchsorted(times, t))
        candidates = [k for k in (i - 1, i) if 0 <= k < len(times)]
        best = min(candidates, key=lambda k: abs(times[k] - t))
        if abs(times[best] - t) <= 0.5 * periods[sid]:
            chosen[sid] = best
    return chosen


def _points(cloud: np.ndarray) -> np.ndarray:
    return np.asarray(cloud).reshape(-1, 3)


def person_mask(
    points: np.ndarray,
    xy: Sequence[float],
    height: float,
    params: Params,
    others: np.ndarray | Sequence[Sequence[float]] = (),
) -> np.ndarray:
    """Which of the points (N, 3) lie in the person's vertical cylinder (see the module
    docstring); ``others``: the other people's floor positions (M, 2)."""
    points = _points(points)
    dx = points[:, 0] - float(xy[0])
    dy = points[:, 1] - float(xy[1])
    near2 = dx * dx + dy * dy
    z = points[:, 2]
    mask = (
        (near2 <= float(params.radius) ** 2)
        & (z >= float(params.floor_margin))
        & (z <= float(height) + float(params.head_margin))
    )
    for ox, oy in np.asarray(others, dtype=np.float64).reshape(-1, 2):
        ex = points[:, 0] - ox
        ey = points[:, 1] - oy
        mask &= near2 <= ex * ex + ey * ey
    return mask


def decimate(points: np.ndarray, voxel: float, count: int, rng: np.random.Generator) -> np.ndarray:
    """The mean point of each occupied ``voxel`` (0: every point), then at most ``count`` of
    them at random (float64)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if voxel > 0.0 and len(points):
        cells = np.floor(points / voxel).astype(np.int64)
        cells -= cells.min(axis=0)
        span = cells.max(axis=0) + 1
        keys = (cells[:, 0] * span[1] + cells[:, 1]) * span[2] + cells[:, 2]
        _, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
        sums = [np.bincount(inverse, points[:, k], len(counts)) for k in range(3)]
        points = np.stack(sums, axis=1) / counts[:, None]
    if len(points) > count:
        points = points[rng.choice(len(points), count, replace=False)]
    return points


def fuse_person(
    clouds: Sequence[np.ndarray],
    xy: Sequence[float],
    height: float,
    params: Params,
    rng: np.random.Generator,
    others: np.ndarray | Sequence[Sequence[float]] = (),
) -> np.ndarray:
    """One person's decimated cloud (K, 3) from every sensor's world points ``clouds``."""
    parts = [c[person_mask(c, xy, height, params, others)] for c in map(_points, clouds)]
    merged = np.concatenate(parts) if parts else np.empty((0, 3))
    return decimate(merged, float(params.voxel), int(params.points), rng)


def person_cloud(
    frames: Mapping[str, RGBDFrame],
    poses: Mapping[str, np.ndarray],
    xy: Sequence[float],
    height: float,
    params: Params,
    rng: np.random.Generator,
    others: np.ndarray | Sequence[Sequence[float]] = (),
) -> np.ndarray:
    """One person's decimated cloud (K, 3) from each sensor's frame at one instant
    (``poses``: each sensor's ``world_T_camera``), backprojecting only their rectangle."""
    parts = []
    for sid, frame in frames.items():
        roi = person_roi(frame.intrinsics, frame.shape, poses[sid], xy, height, params)
        if roi is None:
            continue
        if frame.intrinsics.has_distortion or frame.depth.dtype not in (np.uint16, np.float32):
            cloud = world_points(
                frame, poses[sid], int(params.stride), roi, float(params.edge_jump)
            )
            parts.append(cloud[person_mask(cloud, xy, height, params, others)])
        else:
            parts.append(person_points(frame, poses[sid], roi, xy, height, params, others))
    merged = np.concatenate(parts) if parts else np.empty((0, 3))
    return decimate(merged, float(params.voxel), int(params.points), rng)


def person_points(
    frame: RGBDFrame,
    world_T_camera: np.ndarray,
    roi: Roi,
    xy: Sequence[float],
    height: float,
    params: Params,
    others: np.ndarray | Sequence[Sequence[float]] = (),
) -> np.ndarray:
    """The person's world points (M, 3) float32 from one frame without lens distortion
    (uint16 or float32 depth): :func:`world_points` (``params``' stride and edge jump)
    then :func:`person_mask`, in one pass over the rectangle that keeps only the
    person's points (the same points, in the same order, to the bit)."""
    u0, v0, u1, v1 = roi
    i = frame.intrinsics
    scale = frame.depth_scale if frame.depth.dtype == np.uint16 else 1.0
    pose = np.asarray(world_T_camera, dtype=np.float32)
    # A point of the cylinder lies in its box, whose depths (the camera's z) span those of
    # its corners: a pixel deeper or nearer (by 1 cm more than float32 rounds) is skipped
    # before it is placed in the world.
    depths = _box_in_camera(world_T_camera, xy, height, params)[:, 2]
    # Each bound as numpy compares it with float32 points: rounded to float32 first.
    bounds = np.array(
        [
            float(xy[0]),
            float(xy[1]),
            float(params.radius) ** 2,
            float(params.floor_margin),
            float(height) + float(params.head_margin),
            float(params.edge_jump),
            scale,
            depths.min() - 0.01,
            depths.max() + 0.01,
        ],
        dtype=np.float32,
    )
    rays = np.array([i.cx - u0, i.cy - v0, i.fx, i.fy])
    return _person_points(
        frame.depth[v0:v1, u0:u1], int(params.stride), rays, pose, bounds,
        np.asarray(others, dtype=np.float64).reshape(-1, 2),
    )  # fmt: skip


@numba.njit(cache=True, inline="always")
def _metre(depth, r, c, scale, jump):
    """One pixel in metres (float32), 0 where invalid or (jump > 0) on a depth edge."""
    rows, cols = depth.shape
    d = np.float32(depth[r, c]) * scale
    if jump <= 0.0:
        return d
    bad = not d > 0
    if r > 0:
        bad |= not abs(d - np.float32(depth[r - 1, c]) * scale) <= jump
    if r + 1 < rows:
        bad |= not abs(np.float32(depth[r + 1, c]) * scale - d) <= jump
    if c > 0:
        bad |= not abs(d - np.float32(depth[r, c - 1]) * scale) <= jump
    if c + 1 < cols:
        bad |= not abs(np.float32(depth[r, c + 1]) * scale - d) <= jump
    return np.float32(0.0) if bad else d


@numba.njit(cache=True)
def _person_points(depth, stride, rays, pose, bounds, others):
    rows, cols = depth.shape
    scale, jump, nearest, farthest = bounds[6], bounds[5], bounds[7], bounds[8]
    out = np.empty(
        (((rows + stride - 1) // stride) * ((cols + stride - 1) // stride), 3), np.float32
    )
    count = 0
    for r in range(0, rows, stride):
        for c in range(0, cols, stride):
            zf = np.float32(depth[r, c]) * scale
            if not (zf > 0 and zf >= nearest and zf <= farthest):
                continue  # no depth, or out of the person's box
            depth_m = np.float64(zf)
            x = np.float32((c - rays[0]) * depth_m / rays[2])
            y = np.float32((r - rays[1]) * depth_m / rays[3])
            wx = x * pose[0, 0] + y * pose[0, 1] + zf * pose[0, 2] + pose[0, 3]
            wy = x * pose[1, 0] + y * pose[1, 1] + zf * pose[1, 2] + pose[1, 3]
            wz = x * pose[2, 0] + y * pose[2, 1] + zf * pose[2, 2] + pose[2, 3]
            dx, dy = wx - bounds[0], wy - bounds[1]
            near2 = dx * dx + dy * dy
            keep = near2 <= bounds[2] and wz >= bounds[3] and wz <= bounds[4]
            for o in range(others.shape[0]):  # nearer another person: theirs
                ex, ey = np.float64(wx) - others[o, 0], np.float64(wy) - others[o, 1]
                keep = keep and np.float64(near2) <= ex * ex + ey * ey
            if keep and _metre(depth, r, c, scale, jump) > 0:  # not on an edge
                out[count, 0], out[count, 1], out[count, 2] = wx, wy, wz
                count += 1
    return out[:count]
