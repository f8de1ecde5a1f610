"""Refining a network calibration from one walking person (OpenPTrack §4.3, Algorithm 1).

Every sensor detects the same person; with a perfect calibration their
trajectories coincide. Algorithm 1, as here:

1. Each sensor's detections become a cloud in x-y-time: (x, y, s * t), with
   ``time_scale`` s in metres per second (time warped into a length).
2. The average trajectory, sampled every ``average_step`` seconds: at each
   sample time every sensor's trajectory is interpolated linearly (across
   gaps up to ``max_gap``) and the mean taken where ``min_sensors`` sensors
   have a position. (OpenPTrack averages 0.25 s time bins; interpolating keeps
   a walking person's positions of the same instant together, where bins mix
   positions up to a bin apart: 10-25 cm at walking speed.)
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
distance between two sensors' detections of the person at the same time:
every detection against every other sensor's trajectory interpolated to its
time.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

import numpy as np
import open3d as o3d

from optrack.errors import UserError
from optrack.params import Param, Params, Schema, register
from optrack.types import as_matrix4

__all__ = [
    "REFINEMENT_PARAMS",
    "RefinementResult",
    "Trajectory",
    "alignment_error",
    "average_trajectory",
    "person_trajectories",
    "refine_from_trajectories",
    "usable_detections",
    "walker_trajectory",
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
                "average_step",
                0.05,
                min=0.005,
                max=1.0,
                unit="s",
                help="Sampling step of the average trajectory.",
            ),
            Param(
                "max_gap",
                0.5,
                min=0.01,
                max=10.0,
                unit="s",
                help="A trajectory is interpolated only between detections this close in time.",
            ),
            Param(
                "min_sensors",
                2,
                min=1,
                max=64,
                step=1,
                help="The average has a point where this many sensors saw the person.",
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
                "min_confidence",
                -1.0,
                min=-10.0,
                max=10.0,
                help="The live calibration's walk (the wizard, calibrate live) leaves out "
                "detections below this confidence: a body partly hidden or cut off by the "
                "image's border, whose centroid lies off its axis, or no person at all (in the "
                "wizard's simulated walks they put two sensors' trajectories 10-45 cm apart; "
                "without them 2-4 cm).",
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
                "dof",
                "full",
                choices=("full", "heading"),
                help="What a correction may change: full (also the camera's tilt, levelling its "
                "trajectory, as Algorithm 1) or heading (x, y, z and the turn about the "
                "vertical only: the tilt stays the checkerboard's).",
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

    def as_dict(self) -> dict[str, object]:
        """The errors, the sensors refined and skipped, and each correction."""
        return {
            "error_before_m": self.error_before_m,
            "error_after_m": self.error_after_m,
            "error_before_xyz_m": self.error_before_xyz_m,
            "error_after_xyz_m": self.error_after_xyz_m,
            "refined": sorted(self.corrections),
            "skipped": self.skipped,
            "corrections": {
                sid: {"translation_m": float(np.linalg.norm(c[:3, 3])), "matrix": as_matrix4(c)}
                for sid, c in self.corrections.items()
            },
        }


def _interpolate(trajectory: Trajectory, t: np.ndarray, max_gap: float) -> np.ndarray:
    """Positions at times ``t`` (Nx3; NaN outside the trajectory or across longer gaps)."""
    out = np.full((len(t), 3), np.nan)
    times = trajectory.t
    if len(times) == 0:
        return out
    right = np.clip(np.searchsorted(times, t, side="left"), 0, len(times) - 1)
    exact = times[right] == t
    out[exact] = trajectory.xyz[right[exact]]
    inner = ~exact & (t > times[0]) & (t < times[-1])
    hi = right[inner]
    lo = hi - 1
    gap = times[hi] - times[lo]
    w = ((t[inner] - times[lo]) / np.where(gap > 0, gap, 1.0))[:, None]
    values = (1.0 - w) * trajectory.xyz[lo] + w * trajectory.xyz[hi]
    values[gap > max_gap] = np.nan
    out[inner] = values
    return out


def average_trajectory(
    trajectories: Mapping[str, Trajectory], step: float, min_sensors: int, max_gap: float
) -> tuple[np.ndarray, np.ndarray]:
    """(times, Nx3 positions) of the average trajectory: every ``step`` seconds, the mean
    of the sensors' positions interpolated to that time, where ``min_sensors`` have one."""
    start = min(float(tr.t.min()) for tr in trajectories.values() if len(tr.t))
    stop = max(float(tr.t.max()) for tr in trajectories.values() if len(tr.t))
    times = np.arange(start, stop + step / 2, step)
    stacked = np.stack([_interpolate(tr, times, max_gap) for tr in trajectories.values()])
    seen = np.all(np.isfinite(stacked), axis=2)
    keep = seen.sum(axis=0) >= min_sensors
    with np.errstate(invalid="ignore"):
        mean = np.nanmean(stacked[:, keep], axis=0)
    return times[keep], mean.reshape(-1, 3)


def _xyt_cloud(xyz: np.ndarray, t: np.ndarray, scale: float, t0: float) -> o3d.geometry.PointCloud:
    points = np.column_stack([xyz[:, 0], xyz[:, 1], (t - t0) * scale])
    return o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))


def _heading_transform(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The rotation about the vertical and the x-y-z shift that best take ``source`` onto
    ``target`` (paired Nx3 points): Kabsch in x-y for the heading, means for the shift."""
    a, b = source[:, :2], target[:, :2]
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
    rotation = vt.T @ np.diag([1.0, np.sign(np.linalg.det(vt.T @ u.T))]) @ u.T
    out = np.eye(4)
    out[:2, :2] = rotation
    out[:2, 3] = cb - rotation @ ca
    out[2, 3] = float(np.mean(target[:, 2] - source[:, 2]))
    return out


def _xyz_transform(
    source: np.ndarray, target: np.ndarray, pairs: np.ndarray, dof: str = "full"
) -> np.ndarray:
    """Rigid x-y-z transform taking ``source[pairs[:,0]]`` onto ``target[pairs[:,1]]``: all six
    degrees of freedom (Open3D's Kabsch), or ``dof="heading"``: x, y, z and the heading."""
    if dof == "heading":
        return _heading_transform(source[pairs[:, 0]], target[pairs[:, 1]])
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
    return _xyz_transform(trajectory.xyz, target_xyz, pairs, str(p.dof))


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
            current, float(p.average_step), int(p.min_sensors), float(p.max_gap)
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
    average_t, average_xyz = average_trajectory(
        current, float(p.average_step), int(p.min_sensors), float(p.max_gap)
    )
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
    gap = float(p.max_gap)
    return RefinementResult(
        corrections=corrections,
        error_before_m=alignment_error(usable, gap),
        error_after_m=alignment_error(refined, gap),
        error_before_xyz_m=alignment_error(usable, gap, planar=False),
        error_after_xyz_m=alignment_error(refined, gap, planar=False),
        skipped=skipped,
        average_points=len(average_t),
    )


def alignment_error(
    trajectories: Mapping[str, Trajectory], max_gap: float = 0.5, planar: bool = True
) -> float:
    """Mean distance (m) between two sensors' detections of the person at the same time
    (the paper's Figure 19): every detection of every sensor against every other sensor's
    trajectory interpolated to its time (x-y only when ``planar``, as the tracker works on
    the ground plane)."""
    dims = slice(0, 2) if planar else slice(0, 3)
    distances = []
    for a, ta in trajectories.items():
        for b, tb in trajectories.items():
            if a == b:
                continue
            other = _interpolate(tb, ta.t, max_gap)
            valid = np.all(np.isfinite(other), axis=1)
            if valid.any():
                distances.append(np.linalg.norm(ta.xyz[valid, dims] - other[valid, dims], axis=1))
    if not distances:
        return float("nan")
    return float(np.mean(np.concatenate(distances)))


def usable_detections(detections: Sequence[Any], min_confidence: float | None = None) -> list[Any]:
    """The detections a refinement uses: with a camera-frame centroid (``camera_xyz``) and
    a confidence of at least ``min_confidence`` (None: calibration_refinement's
    ``min_confidence``, the live walk's floor)."""
    if min_confidence is None:
        min_confidence = float(REFINEMENT_PARAMS.defaults()["min_confidence"])
    return [d for d in detections if d.camera_xyz is not None and d.confidence >= min_confidence]


def walker_trajectory(
    frames: Iterable[tuple[float, Sequence[Any]]],
    world_T_camera: np.ndarray,
    min_confidence: float | None = -math.inf,
) -> tuple[Trajectory | None, int]:
    """One sensor's detections of the one person walking as a trajectory in the world:
    for each frame ``(time, detections)``, the most confident of its
    :func:`usable_detections` (``min_confidence``: every one by default; None: the live
    walk's floor), its camera-frame centroid moved by
    ``world_T_camera``. Returns the trajectory (None when the person was never detected)
    and how many frames had more than one person."""
    pose = np.asarray(world_T_camera, dtype=np.float64)
    times: list[float] = []
    points: list[np.ndarray] = []
    crowded = 0
    for t, detections in frames:
        found = usable_detections(detections, min_confidence)
        crowded += len(found) > 1
        if not found:
            continue
        best = max(found, key=lambda d: d.confidence)
        times.append(float(t))
        points.append(pose[:3, :3] @ np.asarray(best.camera_xyz, dtype=np.float64) + pose[:3, 3])
    if not times:
        return None, crowded
    return Trajectory(np.asarray(times), np.asarray(points)), crowded


def person_trajectories(
    recording: Any,
    calibration: Any,
    rate_hz: float,
    progress: Callable[[str], None] | None = None,
) -> tuple[dict[str, Trajectory], dict[str, int]]:
    """Each sensor's detections of the one person walking through a recording (the
    people detector run on its frames, at most ``rate_hz`` a second), in the world of
    ``calibration`` (a CalibrationFile; :func:`walker_trajectory`). Returns
    (trajectories, frames with more than one person, per sensor)."""
    try:
        from optrack.detection.params import detection_params
        from optrack.detection.pipeline import PeopleDetector
    except ImportError as error:
        raise RefinementError(
            f"the people detector is not available in this optrack ({error}); refinement needs it."
        ) from None

    trajectories: dict[str, Trajectory] = {}
    crowded: dict[str, int] = {}
    for sid in recording.sensor_ids:
        info = recording.sensors[sid]
        pose = calibration.sensors[sid].pose
        detector = PeopleDetector(detection_params(info.model), sensor_id=sid, world_T_camera=pose)

        def frames(sid: str = sid, detector: Any = detector) -> Iterable[tuple[float, Any]]:
            last = -np.inf
            for entry in recording.index(sid):
                if entry.t - last < 1.0 / rate_hz - 1e-6:
                    continue
                last = entry.t
                yield entry.t, detector.process(recording.load(sid, entry)).detections

        trajectory, many = walker_trajectory(frames(), pose)
        if many:
            crowded[sid] = many
        if trajectory is not None:
            trajectories[sid] = trajectory
        if progress:
            count = 0 if trajectory is None else len(trajectory.t)
            progress(f"{sid}: the person was detected in {count} frames")
    return trajectories, crowded
