"""Refining a network calibration from one walking person (OpenPTrack §4.3, Algorithm 1).

Every sensor detects the same person; with a perfect calibration their
trajectories coincide. Algorithm 1, as here:

1. Each sensor's detections become a cloud in x-y-time: (x, y, s * t), with
   ``time_scale`` s in metres per second (time warped into a length).
2. The average trajectory: detections are binned in time (``time_bin``) and
   every bin seen by at least ``min_sensors`` sensors gives one mean point.
3. Each sensor's cloud is registered to the average with Open3D's ICP in
   x-y-time, in ``rounds`` rounds whose maximum correspondence distance
   halves from ``max_correspondence`` (2.0 -> 1.0 -> 0.5 -> 0.25 m, as
   OpenPTrack). The ICP's pairs (detection, average point at about the same
   time and place) give the rigid x-y-z transform of that round
   (Kabsch/Umeyama, Open3D's point-to-point estimation), applied to the
   sensor's detections; the average is rebuilt after every round.
4. A final x-y-z alignment of every sensor against the average projected on
   the ground: the average's x-y on the level plane at the detections' median
   height, so that every sensor's trajectory ends level with the floor.

The result is one rigid transform per sensor, applied in world x-y-z:
``refined world_T_camera = correction @ world_T_camera``. (OpenPTrack fits
in x-y-time and applies that matrix in x-y-z; here the transform is always
estimated in x-y-z from the x-y-time correspondences.)

The alignment error (the paper's Figure 19) is the mean ground-plane
distance between two sensors' detections of the person at the same time,
each trajectory interpolated linearly in time.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import numpy as np
import open3d as o3d

from optrack.errors import UserError
from optrack.params import Param, Params, Schema, register

__all__ = [
    "REFINEMENT_PARAMS",
    "RefinementResult",
    "Trajectory",
    "alignment_error",
    "average_trajectory",
    "refine_from_trajectories",
]

REFINEMENT_PARAMS = register(
    Schema(
        "calibration_refinement",
        [
            Param(
                "time_scale",
                1.0,
                min=0.01,
                max=100.0,
                unit="m/s",
                help="Metres of the warped time axis per second (OpenPTrack: 1).",
            ),
            Param(
                "time_bin",
                0.25,
                min=0.01,
                max=5.0,
                unit="s",
                help="Detections of one time bin make one point of the average trajectory.",
            ),
            Param(
                "min_sensors",
                2,
                min=1,
                max=64,
                step=1,
                help="A time bin enters the average when this many sensors saw the person in it.",
            ),
            Param(
                "max_correspondence",
                2.0,
                min=0.01,
                max=20.0,
                unit="m",
                help="ICP's largest correspondence distance in the first round; halved each round.",
            ),
            Param("rounds", 4, min=1, max=12, step=1, help="Rounds of ICP against the average."),
            Param(
                "final_correspondence",
                0.25,
                min=0.01,
                max=5.0,
                unit="m",
                help="Correspondence distance of the final alignment against the levelled average.",
            ),
            Param(
                "icp_iterations",
                60,
                min=1,
                max=1000,
                step=1,
                help="ICP iterations per round.",
            ),
            Param(
                "min_detections",
                20,
                min=3,
                max=100000,
                step=1,
                help="A sensor with fewer detections of the person is left as it is.",
            ),
            Param(
                "keep_frame",
                True,
                help="Keep the network where the checkerboard put it on the floor plan: the "
                "corrections move the sensors relative to each other, not all together.",
            ),
        ],
        help="Refining the calibration from one walking person (Algorithm 1).",
    )
)


class RefinementError(UserError):
    """A refinement that cannot be done with the given detections."""


@dataclasses.dataclass
class Trajectory:
    """One sensor's detections of the person: times (s, N) and world positions (m, Nx3)."""

    t: np.ndarray
    xyz: np.ndarray

    def __post_init__(self) -> None:
        self.t = np.asarray(self.t, dtype=np.float64).reshape(-1)
        self.xyz = np.asarray(self.xyz, dtype=np.float64).reshape(-1, 3)
        if len(self.t) != len(self.xyz):
            raise ValueError(
                f"a trajectory needs one time per point; got {len(self.t)} and {len(self.xyz)}."
            )
        order = np.argsort(self.t, kind="stable")
        self.t, self.xyz = self.t[order], self.xyz[order]

    def transformed(self, world_T: np.ndarray) -> Trajectory:
        return Trajectory(self.t, self.xyz @ world_T[:3, :3].T + world_T[:3, 3])


@dataclasses.dataclass
class RefinementResult:
    """Per-sensor corrections (4x4, applied in world x-y-z) and the alignment errors (m)."""

    corrections: dict[str, np.ndarray]
    error_before_m: float
    error_after_m: float
    error_before_xyz_m: float
    error_after_xyz_m: float
    skipped: list[str]
    average_points: int


def average_trajectory(
    trajectories: Mapping[str, Trajectory], time_bin: float, min_sensors: int, t0: float
) -> tuple[np.ndarray, np.ndarray]:
    """(times, Nx3 positions) of the average trajectory: one point per time bin seen by at
    least ``min_sensors`` sensors (each sensor's detections in the bin averaged first, so
    a faster sensor does not weigh more)."""
    per_bin: dict[int, list[tuple[float, np.ndarray]]] = {}
    for trajectory in trajectories.values():
        bins = np.floor((trajectory.t - t0) / time_bin).astype(np.int64)
        for b in np.unique(bins):
            mask = bins == b
            per_bin.setdefault(int(b), []).append(
                (float(trajectory.t[mask].mean()), trajectory.xyz[mask].mean(axis=0))
            )
    times, points = [], []
    for b in sorted(per_bin):
        entries = per_bin[b]
        if len(entries) >= min_sensors:
            times.append(np.mean([e[0] for e in entries]))
            points.append(np.mean([e[1] for e in entries], axis=0))
    return np.asarray(times), np.asarray(points).reshape(-1, 3)


def _xyt_cloud(xyz: np.ndarray, t: np.ndarray, scale: float, t0: float) -> o3d.geometry.PointCloud:
    points = np.column_stack([xyz[:, 0], xyz[:, 1], (t - t0) * scale])
    return o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))


def _xyz_transform(source: np.ndarray, target: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """Rigid x-y-z transform taking ``source[pairs[:,0]]`` onto ``target[pairs[:,1]]``."""
    estimation = o3d.pipelines.registration.TransformationEstimationPointToPoint()
    return np.asarray(
        estimation.compute_transformation(
            o3d.geometry.PointCloud(o3d.utility.Vector3dVector(source)),
            o3d.geometry.PointCloud(o3d.utility.Vector3dVector(target)),
            o3d.utility.Vector2iVector(pairs.astype(np.int32)),
        )
    )


def _register(
    trajectory: Trajectory,
    target_t: np.ndarray,
    target_xyz: np.ndarray,
    distance: float,
    p: Params,
    t0: float,
) -> np.ndarray | None:
    """One round for one sensor: x-y-time ICP for the pairs, then the x-y-z transform."""
    scale = float(p.time_scale)
    source = _xyt_cloud(trajectory.xyz, trajectory.t, scale, t0)
    target = _xyt_cloud(target_xyz, target_t, scale, t0)
    result = o3d.pipelines.registration.registration_icp(
        source,
        target,
        distance,
        np.eye(4),
        o3d.pipelines.registration.TransformationEstimationPointToPoint(),
        o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=int(p.icp_iterations)),
    )
    pairs = np.asarray(result.correspondence_set)
    if len(pairs) < 3:
        return None
    return _xyz_transform(trajectory.xyz, target_xyz, pairs)


def _keep_frame(
    trajectories: Mapping[str, Trajectory], corrections: Mapping[str, np.ndarray]
) -> dict[str, np.ndarray]:
    """Corrections composed with the one motion G in the ground plane (x, y, yaw) that puts
    all refined detections, pooled, back where they were on the floor plan (Kabsch in x-y).
    Height and tilt stay as levelled by the final step."""
    moved = np.concatenate(
        [
            tr.xyz @ corrections[s][:3, :3].T + corrections[s][:3, 3]
            for s, tr in trajectories.items()
        ]
    )
    original = np.concatenate([tr.xyz for tr in trajectories.values()])
    moved[:, 2] = 0.0
    original = original.copy()
    original[:, 2] = 0.0
    pairs = np.repeat(np.arange(len(moved))[:, None], 2, axis=1)
    gauge = _xyz_transform(moved, original, pairs)
    return {s: gauge @ c for s, c in corrections.items()}


def refine_from_trajectories(
    trajectories: Mapping[str, Trajectory], params: Params | None = None
) -> RefinementResult:
    """Algorithm 1 over per-sensor trajectories in the world frame (see the module docstring)."""
    p = params if params is not None else REFINEMENT_PARAMS.create()
    usable = {s: tr for s, tr in trajectories.items() if len(tr.t) >= p.min_detections}
    skipped = sorted(set(trajectories) - set(usable))
    if len(usable) < 2:
        counts = ", ".join(f"{s}: {len(tr.t)}" for s, tr in sorted(trajectories.items()))
        raise RefinementError(
            f"refinement needs at least two sensors with {p.min_detections} or more detections "
            f"of the person (got {counts or 'none'}); walk through the area every sensor sees."
        )
    t0 = min(float(tr.t.min()) for tr in usable.values())
    corrections = {s: np.eye(4) for s in usable}
    current = dict(usable)
    distance = float(p.max_correspondence)
    average_t = np.zeros(0)
    for _ in range(int(p.rounds)):
        average_t, average_xyz = average_trajectory(
            current, float(p.time_bin), int(p.min_sensors), t0
        )
        if len(average_t) < 3:
            raise RefinementError(
                "the sensors never saw the person at the same time; walk where their views overlap."
            )
        for sid, trajectory in current.items():
            delta = _register(trajectory, average_t, average_xyz, distance, p, t0)
            if delta is not None:
                corrections[sid] = delta @ corrections[sid]
        current = {s: usable[s].transformed(corrections[s]) for s in usable}
        distance /= 2.0
    # Final: against the average on the level plane at the detections' median height.
    average_t, average_xyz = average_trajectory(current, float(p.time_bin), int(p.min_sensors), t0)
    level = float(np.median(np.concatenate([tr.xyz[:, 2] for tr in current.values()])))
    projected = average_xyz.copy()
    projected[:, 2] = level
    for sid, trajectory in current.items():
        delta = _register(trajectory, average_t, projected, float(p.final_correspondence), p, t0)
        if delta is not None:
            corrections[sid] = delta @ corrections[sid]
    if p.keep_frame:
        corrections = _keep_frame(usable, corrections)
    refined = {s: usable[s].transformed(corrections[s]) for s in usable}
    bin_ = float(p.time_bin)
    return RefinementResult(
        corrections=corrections,
        error_before_m=alignment_error(usable, bin_),
        error_after_m=alignment_error(refined, bin_),
        error_before_xyz_m=alignment_error(usable, bin_, planar=False),
        error_after_xyz_m=alignment_error(refined, bin_, planar=False),
        skipped=skipped,
        average_points=len(average_t),
    )


def _binned(trajectory: Trajectory, time_bin: float, t0: float) -> dict[int, np.ndarray]:
    """The mean position of a trajectory in each time bin it has detections in."""
    bins = np.floor((trajectory.t - t0) / time_bin).astype(np.int64)
    return {int(b): trajectory.xyz[bins == b].mean(axis=0) for b in np.unique(bins)}


def alignment_error(
    trajectories: Mapping[str, Trajectory], time_bin: float = 0.25, planar: bool = True
) -> float:
    """Mean distance (m) between two sensors' detections of the person at the same time
    (the paper's Figure 19): each sensor's detections are averaged per time bin, and the
    distances between every two sensors seen in the same bin are averaged (x-y only when
    ``planar``, as the tracker works on the ground plane)."""
    if not trajectories:
        return float("nan")
    t0 = min(float(tr.t.min()) for tr in trajectories.values() if len(tr.t))
    binned = [_binned(tr, time_bin, t0) for tr in trajectories.values() if len(tr.t)]
    dims = slice(0, 2) if planar else slice(0, 3)
    distances = []
    for i, a in enumerate(binned):
        for b in binned[i + 1 :]:
            for key in a.keys() & b.keys():
                distances.append(float(np.linalg.norm(a[key][dims] - b[key][dims])))
    return float(np.mean(distances)) if distances else float("nan")
