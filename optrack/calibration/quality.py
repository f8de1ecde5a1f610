"""A calibration's quality: the figures it was made with, and how far it is from the truth.

:class:`CalibrationQuality` is the typed form of a calibration file's
``quality`` section as the live calibration writes it and the wizard's
review page reads it back.

Against the truth (simulated recordings, synthetic sessions): a calibration
is only defined up to the choice of world frame, so camera
poses are compared after the rigid transform that best maps the estimated
network onto the true one (rotation: the chordal mean of the per-camera
rotation offsets; translation: the camera centroids). The ground plane is
compared where the detectors use it: in each camera's frame (angle between
the normals, and the difference in the camera's height above the floor).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import msgspec
import numpy as np

from optrack.geometry import Plane, invert, make_pose, rotation_angle_deg

__all__ = ["CalibrationErrors", "CalibrationQuality", "align_networks", "calibration_errors"]


class CalibrationQuality(msgspec.Struct, kw_only=True):
    """How a calibration was made: its reprojection RMS (px) over every view, the still
    board instants and floor views it used, where its world is (``floor`` or ``none``), and
    after a walk's refinement (Algorithm 1) the sensors' disagreement on the walker before
    and after (m) and the sensors whose correction was refused (they kept the
    checkerboard's pose)."""

    reprojection_rms_px: float | None = None
    instants: int | None = None
    floor_views: int = 0
    ground: str = "none"
    refinement_error_before_m: float | None = None
    refinement_error_after_m: float | None = None
    refinement_refused: list[str] = msgspec.field(default_factory=list)

    @property
    def refined(self) -> bool:
        return self.refinement_error_after_m is not None

    def as_dict(self) -> dict[str, Any]:
        """The file's ``quality`` section: the figures that are known."""
        return {k: v for k, v in msgspec.structs.asdict(self).items() if v not in (None, [])}

    @classmethod
    def of(cls, quality: Mapping[str, Any]) -> CalibrationQuality:
        """The figures of a file's ``quality`` section (other keys, which other commands
        write, are left out)."""
        known = {f: quality[f] for f in cls.__struct_fields__ if f in quality}
        return msgspec.convert(known, cls, strict=False)


def align_networks(
    estimated: Mapping[str, np.ndarray], truth: Mapping[str, np.ndarray]
) -> np.ndarray:
    """``truth_T_estimated``: the rigid transform best mapping estimated poses onto true ones."""
    common = sorted(set(estimated) & set(truth))
    if not common:
        raise ValueError("the two networks share no sensor.")
    offsets = sum(truth[s][:3, :3] @ estimated[s][:3, :3].T for s in common)
    u, _, vt = np.linalg.svd(offsets)
    rotation = u @ np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))]) @ vt
    centre_est = np.mean([estimated[s][:3, 3] for s in common], axis=0)
    centre_true = np.mean([truth[s][:3, 3] for s in common], axis=0)
    return make_pose(rotation, centre_true - rotation @ centre_est)


@dataclasses.dataclass
class CalibrationErrors:
    """Per-sensor errors after alignment; ground errors per sensor in its own frame."""

    position_m: dict[str, float]
    rotation_deg: dict[str, float]
    ground_deg: dict[str, float]
    ground_m: dict[str, float]

    @property
    def max_position_error_m(self) -> float:
        return max(self.position_m.values())

    @property
    def max_rotation_error_deg(self) -> float:
        return max(self.rotation_deg.values())

    @property
    def ground_error_deg(self) -> float:
        return max(self.ground_deg.values())

    @property
    def ground_error_m(self) -> float:
        return max(self.ground_m.values())

    def as_dict(self) -> dict[str, object]:
        return {
            "max_position_error_m": self.max_position_error_m,
            "max_rotation_error_deg": self.max_rotation_error_deg,
            "ground_error_deg": self.ground_error_deg,
            "ground_error_m": self.ground_error_m,
            "position_error_m": dict(self.position_m),
            "rotation_error_deg": dict(self.rotation_deg),
            "ground_error_deg_by_sensor": dict(self.ground_deg),
            "ground_error_m_by_sensor": dict(self.ground_m),
        }


def calibration_errors(
    estimated: Mapping[str, np.ndarray],
    truth: Mapping[str, np.ndarray],
    estimated_ground: Plane | None = None,
    true_ground: Plane | None = None,
) -> CalibrationErrors:
    """Errors of estimated ``world_T_camera`` poses against the true ones.

    Grounds are planes in each network's world frame (default z = 0, the
    floor by convention).
    """
    estimated_ground = estimated_ground or Plane(0.0, 0.0, 1.0, 0.0)
    true_ground = true_ground or Plane(0.0, 0.0, 1.0, 0.0)
    truth_T_est = align_networks(estimated, truth)
    position, rotation, ground_deg, ground_m = {}, {}, {}, {}
    for sid in sorted(set(estimated) & set(truth)):
        aligned = truth_T_est @ estimated[sid]
        position[sid] = float(np.linalg.norm(aligned[:3, 3] - truth[sid][:3, 3]))
        rotation[sid] = rotation_angle_deg(aligned, truth[sid])
        plane_est = estimated_ground.transform(invert(estimated[sid]))
        plane_true = true_ground.transform(invert(truth[sid]))
        ground_deg[sid] = plane_est.angle_deg(plane_true)
        ground_m[sid] = abs(abs(plane_est.d) - abs(plane_true.d))  # camera height above floor
    return CalibrationErrors(position, rotation, ground_deg, ground_m)
