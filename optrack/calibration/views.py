"""One sensor's view of the checkerboard, and the tree of relative poses shared views give.

As synchronised views of the board arrive, each sensor's view gives the
board's pose in that camera (PnP). When two sensors see the board at once
their relative pose follows; a tree grows from the first such pair (a sensor
joins when it shares a view with a calibrated one, and moves to the parent
with the better view when one comes along). The tree seeds the network's
factor graph (:mod:`optrack.calibration.network`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping

import cv2
import numpy as np

from optrack.calibration.board import Checkerboard
from optrack.geometry import invert, make_pose
from optrack.types import Intrinsics

__all__ = ["BoardView", "CalibrationTree", "observe_board", "pinhole_residuals_px"]


@dataclasses.dataclass
class BoardView:
    """One sensor's view of the board at one instant.

    ``corners`` are the detected pixels; ``pinhole`` the same corners with the
    lens distortion removed (pixels of the ideal pinhole camera with the same
    K); ``camera_T_board`` comes from PnP, with reprojection ``rms_px``.
    ``quality`` is the board's apparent square size in pixels: bigger means a
    closer, more frontal board and a better pose.
    """

    sensor_id: str
    corners: np.ndarray
    pinhole: np.ndarray
    camera_T_board: np.ndarray
    rms_px: float
    quality: float


def observe_board(
    sensor_id: str, corners: np.ndarray, intrinsics: Intrinsics, board: Checkerboard
) -> BoardView:
    """Board pose in the camera from its corners (OpenCV IPPE, then LM refinement)."""
    corners = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
    if len(corners) != board.count:
        raise ValueError(
            f"sensor {sensor_id}: expected {board.count} corners of the {board.cols}x{board.rows} "
            f"board; got {len(corners)}."
        )
    objects = board.object_points
    K, dist = intrinsics.K, intrinsics.dist_coeffs
    ok, rvec, tvec = cv2.solvePnP(objects, corners, K, dist, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        ok, rvec, tvec = cv2.solvePnP(objects, corners, K, dist)
    rvec, tvec = cv2.solvePnPRefineLM(objects, corners, K, dist, rvec, tvec)
    projected, _ = cv2.projectPoints(objects, rvec, tvec, K, dist)
    rms = float(np.sqrt(np.mean(np.sum((projected.reshape(-1, 2) - corners) ** 2, axis=1))))
    rotation, _ = cv2.Rodrigues(rvec)
    pinhole = cv2.undistortPoints(corners.reshape(-1, 1, 2), K, dist, P=K).reshape(-1, 2)
    outline = corners[[0, board.cols - 1, board.count - 1, board.count - board.cols]]
    area = 0.5 * abs(
        float(
            np.dot(outline[:, 0], np.roll(outline[:, 1], -1))
            - np.dot(outline[:, 1], np.roll(outline[:, 0], -1))
        )
    )
    quality = math.sqrt(area / ((board.cols - 1) * (board.rows - 1)))
    return BoardView(
        sensor_id=sensor_id,
        corners=corners,
        pinhole=pinhole,
        camera_T_board=make_pose(rotation, tvec.reshape(3)),
        rms_px=rms,
        quality=quality,
    )


def pinhole_residuals_px(
    objects: np.ndarray, camera_T_board: np.ndarray, intrinsics: Intrinsics, pinhole: np.ndarray
) -> np.ndarray:
    """Distance in pixels between each board point (Nx3, board frame) projected through the
    ideal pinhole camera of ``intrinsics`` and its undistorted corner (``BoardView.pinhole``)."""
    points = objects @ camera_T_board[:3, :3].T + camera_T_board[:3, 3]
    k = intrinsics
    uv = np.stack(
        [k.fx * points[:, 0] / points[:, 2] + k.cx, k.fy * points[:, 1] / points[:, 2] + k.cy],
        axis=1,
    )
    return np.linalg.norm(uv - pinhole, axis=1)


# ----------------------------------------------------------------- the tree


class CalibrationTree:
    """Which sensor is placed relative to which (the live calibration's spanning tree).

    Each sensor but the root has a parent and the relative pose
    ``parent_T_child`` from the best shared view so far (link quality: the
    smaller of the two views' qualities).
    """

    def __init__(self) -> None:
        self.root: str | None = None
        self.parent: dict[str, str] = {}
        self.link_quality: dict[str, float] = {}
        self.parent_T_child: dict[str, np.ndarray] = {}

    def calibrated(self, sensor: str) -> bool:
        return sensor == self.root or sensor in self.parent

    @property
    def sensors(self) -> list[str]:
        return ([self.root] if self.root is not None else []) + list(self.parent)

    def _ancestors(self, sensor: str) -> set[str]:
        seen = set()
        while sensor in self.parent:
            sensor = self.parent[sensor]
            seen.add(sensor)
        return seen

    def offer(self, views: Mapping[str, BoardView], root: str | None = None) -> list[str]:
        """Use one instant's views (two or more sensors) to add or re-parent sensors.

        Returns the sensors that joined the tree.
        """
        if len(views) < 2:
            return []
        joined: list[str] = []
        if self.root is None:
            self.root = root if root in views else sorted(views)[0]
            joined.append(self.root)
        changed = True
        while changed:  # a sensor that joins can be the parent of another in the same view
            changed = False
            for child in sorted(views):
                if child == self.root:
                    continue
                best: tuple[float, str] | None = None
                for candidate in views:
                    if candidate == child or not self.calibrated(candidate):
                        continue
                    if child in self._ancestors(candidate):
                        continue  # re-parenting under a descendant would make a loop
                    quality = min(views[child].quality, views[candidate].quality)
                    if best is None or quality > best[0]:
                        best = (quality, candidate)
                if best is None:
                    continue
                quality, parent = best
                if self.calibrated(child) and quality <= self.link_quality[child]:
                    continue
                was = self.calibrated(child)
                self.parent[child] = parent
                self.link_quality[child] = quality
                self.parent_T_child[child] = views[parent].camera_T_board @ invert(
                    views[child].camera_T_board
                )
                if not was:
                    joined.append(child)
                    changed = True
        return joined

    def root_T(self, sensor: str) -> np.ndarray:
        """Pose of a sensor in the root camera's frame, chained along the tree."""
        pose = np.eye(4)
        while sensor != self.root:
            pose = self.parent_T_child[sensor] @ pose
            sensor = self.parent[sensor]
        return pose
