"""The factor graph of the network calibration (OpenPTrack §4.2, eq. 1-4).

One factor graph (gtsam) over every camera pose and every board pose, one
reprojection factor per observed corner (eq. 1-2)::

    e_ijk = || pi_i( camera_i_T_world * world_T_board_j * p_k ) - u_ijk ||^2 / sigma_cam^2

with a Huber loss. Boards laid on the floor are constrained to one plane
(eq. 3-4): the pose of floor board j is the plane's pose composed with a 2D
pose (x_j, y_j, theta_j), enforced by a tight factor that leaves only those
three free.

A corner factor needs two unknown poses (camera and board) and a known
point, so each one is gtsam_unstable's ``ProjectionFactorPPP``: it projects a
point through ``pose * transform`` with ``pose = board_T_network`` (the board
variable, stored inverted) and ``transform = network_T_camera``. The board's
corner coordinates are the "points", shared by all views and held by tight
priors. Observed corners are undistorted first (OpenCV's full model), so each
camera is a plain pinhole in the graph and any OpenCV distortion model works.
Intrinsics are fixed.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping

import gtsam
import gtsam_unstable
import numpy as np

from optrack.calibration.board import Checkerboard
from optrack.calibration.views import BoardView
from optrack.params import Params
from optrack.types import Intrinsics

__all__ = ["FLOOR_FLIP", "FLOOR_KEY", "FactorGraph", "Instant", "board_key"]


def _camera_key(index: int) -> int:
    return gtsam.symbol("c", index)


def board_key(index: int) -> int:
    return gtsam.symbol("b", index)


def _corner_key(index: int) -> int:
    return gtsam.symbol("l", index)


FLOOR_KEY = gtsam.symbol("f", 0)


def _numerical_jacobians(
    residual, poses: list[gtsam.Pose3], step: float = 1e-6
) -> list[np.ndarray]:
    """Central-difference Jacobians of ``residual(*poses)`` in each pose's tangent space."""
    jacobians = []
    for i, pose in enumerate(poses):
        columns = []
        for d in range(6):
            delta = np.zeros(6)
            delta[d] = step
            plus = list(poses)
            minus = list(poses)
            plus[i] = pose.retract(delta)
            minus[i] = pose.retract(-delta)
            columns.append((residual(*plus) - residual(*minus)) / (2 * step))
        jacobians.append(np.stack(columns, axis=1))
    return jacobians


# The canonical floor board: its z axis points into the floor, its face is
# ``thickness`` above it (board frame: x along rows, y along columns, z away
# from the viewer).
FLOOR_FLIP = np.diag([1.0, -1.0, -1.0])


def _floor_T_board_residual(thickness: float, anchor: bool):
    """Residual of eq. 3-4 for one floor board, given floor_T_network and board_T_network.

    ``floor_T_board`` must be a turn about the vertical and a shift in the
    floor plane: its z axis (0, 0, -1) and its height ``thickness``. For the
    anchor board (the first on the floor) the whole pose is fixed.
    """
    target = gtsam.Pose3(gtsam.Rot3(FLOOR_FLIP), np.array([0.0, 0.0, thickness]))

    def residual(floor: gtsam.Pose3, board: gtsam.Pose3) -> np.ndarray:
        floor_T_board = floor.compose(board.inverse())
        if anchor:
            return target.localCoordinates(floor_T_board)
        rotation = floor_T_board.rotation().matrix()
        return np.array(
            [rotation[0, 2], rotation[1, 2], floor_T_board.translation()[2] - thickness]
        )

    return residual


def _floor_factor(board: int, thickness: float, anchor: bool, sigma: float) -> gtsam.CustomFactor:
    residual = _floor_T_board_residual(thickness, anchor)

    def error(this: gtsam.CustomFactor, values: gtsam.Values, H: list[np.ndarray] | None):
        floor_pose = values.atPose3(FLOOR_KEY)
        board_pose = values.atPose3(board)
        if H is not None:
            H[0], H[1] = _numerical_jacobians(residual, [floor_pose, board_pose])
        return residual(floor_pose, board_pose)

    noise = gtsam.noiseModel.Isotropic.Sigma(6 if anchor else 3, sigma)
    return gtsam.CustomFactor(noise, [FLOOR_KEY, board], error)


@dataclasses.dataclass
class Instant:
    """The views of one instant; ``added``: sensors whose corners are in the graph."""

    index: int
    views: dict[str, BoardView]
    floor: bool
    added: set[str] = dataclasses.field(default_factory=set)

    @property
    def in_graph(self) -> bool:
        return bool(self.added)


class FactorGraph:
    """Builds the factors and initial values that the calibrator solves incrementally
    (iSAM2) or in batch."""

    def __init__(
        self,
        board: Checkerboard,
        intrinsics: Mapping[str, Intrinsics],
        params: Params,
    ) -> None:
        self.board = board
        self.params = params
        self.calibrations = {
            sid: gtsam.Cal3_S2(k.fx, k.fy, 0.0, k.cx, k.cy) for sid, k in intrinsics.items()
        }
        self.camera_index = {sid: i for i, sid in enumerate(sorted(intrinsics))}
        sigma = float(params.sigma_px)
        self.noise = gtsam.noiseModel.Robust.Create(
            gtsam.noiseModel.mEstimator.Huber.Create(float(params.huber_px) / sigma),
            gtsam.noiseModel.Isotropic.Sigma(2, sigma),
        )
        self.corner_noise = gtsam.noiseModel.Isotropic.Sigma(3, 1e-9)
        self.root_noise = gtsam.noiseModel.Isotropic.Sigma(6, 1e-9)

    def base(
        self, root: str, fixed: Mapping[str, np.ndarray] | None = None
    ) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
        """Corner points (fixed) and the gauge: the root camera at the network origin (and
        cameras whose ``network_T_camera`` is ``fixed`` held there)."""
        graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        for k, point in enumerate(self.board.object_points):
            graph.add(gtsam.PriorFactorPoint3(_corner_key(k), point, self.corner_noise))
            values.insert(_corner_key(k), point)
        graph.add(gtsam.PriorFactorPose3(self.camera_key(root), gtsam.Pose3(), self.root_noise))
        for sid, pose in (fixed or {}).items():
            if sid != root:
                graph.add(
                    gtsam.PriorFactorPose3(self.camera_key(sid), gtsam.Pose3(pose), self.root_noise)
                )
        return graph, values

    def camera_key(self, sensor: str) -> int:
        return _camera_key(self.camera_index[sensor])

    def instant_factors(
        self, instant: Instant, sensors: Iterable[str], *, floor: bool, anchor: bool
    ) -> gtsam.NonlinearFactorGraph:
        """One reprojection factor per corner of each of ``sensors``' views (eq. 1-2), and
        with ``floor`` the board's floor constraint (eq. 3-4)."""
        graph = gtsam.NonlinearFactorGraph()
        board = board_key(instant.index)
        for sid in sensors:
            view = instant.views[sid]
            camera_key = self.camera_key(sid)
            calibration = self.calibrations[sid]
            for k, uv in enumerate(view.pinhole):
                graph.add(
                    gtsam_unstable.ProjectionFactorPPPCal3_S2(
                        uv, self.noise, board, camera_key, _corner_key(k), calibration
                    )
                )
        if floor:
            graph.add(
                _floor_factor(
                    board,
                    float(self.params.board_thickness),
                    anchor,
                    float(self.params.floor_sigma),
                )
            )
        return graph
