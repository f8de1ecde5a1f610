"""Extrinsic calibration of a camera network with a moving checkerboard (OpenPTrack §4.2).

Live part: as synchronised views of the board arrive, each sensor's view
gives the board's pose in that camera and a tree of relative poses grows from
the views two sensors share (:mod:`optrack.calibration.views`).

Global part: one factor graph over every camera pose and every board pose,
one reprojection factor per observed corner, with the boards laid on the
floor held in one plane (:mod:`optrack.calibration.factors`, eq. 1-4),
solved incrementally with iSAM2 while views arrive (the live feedback) and by
Levenberg-Marquardt over everything at the end. The first floor board fixes
the world frame: origin on the floor under its first corner, x along its
rows, z up.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Iterable, Mapping

import gtsam
import numpy as np

from optrack.calibration.board import Checkerboard
from optrack.calibration.factors import FLOOR_FLIP, FLOOR_KEY, FactorGraph, Instant, board_key
from optrack.calibration.views import (
    BoardView,
    CalibrationTree,
    observe_board,
    pinhole_residuals_px,
)
from optrack.errors import UserError
from optrack.geometry import invert, make_pose
from optrack.params import Param, Params, Schema, register
from optrack.types import Intrinsics, as_matrix4

__all__ = [
    "FLOOR_KEY",
    "NETWORK_PARAMS",
    "BoardView",
    "CalibrationError",
    "CalibrationTree",
    "Feedback",
    "Instant",
    "NetworkCalibrator",
    "NetworkResult",
    "SensorStatus",
    "observe_board",
    "pinhole_residuals_px",
]

NETWORK_PARAMS = register(
    Schema(
        "calibration_network",
        [
            Param(
                "sigma_px",
                0.5,
                min=0.01,
                max=20.0,
                unit="px",
                help="sigma_cam of eq. 1: the standard deviation of a detected corner.",
            ),
            Param(
                "huber_px",
                1.5,
                min=0.01,
                max=100.0,
                unit="px",
                help="Reprojection errors above this count linearly (Huber loss), so a bad "
                "corner cannot pull the solution.",
            ),
            Param(
                "max_pnp_rms_px",
                3.0,
                min=0.1,
                max=100.0,
                unit="px",
                help="A single view whose board pose does not reproject within this is "
                "refused (a mis-detected board).",
            ),
            Param(
                "incremental",
                True,
                help="Re-solve with iSAM2 after every accepted view (live feedback); off: "
                "only the tree until the final global solve.",
            ),
            Param(
                "relinearize_threshold",
                0.01,
                min=1e-6,
                max=1.0,
                help="iSAM2 relinearises a variable when its update exceeds this.",
            ),
            Param(
                "max_iterations",
                100,
                min=1,
                max=1000,
                step=1,
                help="Levenberg-Marquardt iterations of the final global solve.",
            ),
            Param(
                "relative_error_tol",
                1e-7,
                min=1e-12,
                max=1e-2,
                help="The final solve stops when the error improves by less than this fraction.",
            ),
            Param(
                "min_board_motion",
                0.0,
                min=0.0,
                max=1.0,
                unit="m",
                help="A view whose board has moved less than this since the last accepted view "
                "is skipped (0: keep all).",
            ),
            Param(
                "board_thickness",
                0.005,
                min=0.0,
                max=0.1,
                unit="m",
                help="Height of the board's printed face above the floor when it lies on it "
                "(a board on foam or card: measure yours).",
            ),
            Param(
                "floor_sigma",
                1e-4,
                min=1e-8,
                max=0.1,
                help="Tolerance (rad, m) of the constraint holding floor boards in one plane "
                "(eq. 3-4).",
            ),
        ],
        help="Extrinsic calibration of the camera network (checkerboard, global optimisation).",
    )
)


class CalibrationError(UserError):
    """A network calibration that cannot be completed."""


# --------------------------------------------------------------- feedback


@dataclasses.dataclass
class SensorStatus:
    """Live figures of one sensor."""

    views: int = 0  # instants in which this sensor saw the board
    used_views: int = 0  # of those, the ones in the optimisation
    rejected: int = 0  # views refused: the board's pose did not reproject (max_pnp_rms_px)
    rms_px: float | None = None  # reprojection RMS over its corners in the optimisation
    calibrated: bool = False
    parent: str | None = None

    def as_dict(self) -> dict[str, object]:
        return dataclasses.asdict(self)


@dataclasses.dataclass
class Feedback:
    """What the operator sees after each view."""

    sensors: dict[str, SensorStatus]
    covisibility: dict[tuple[str, str], int]  # instants seen by both sensors
    instants: int  # instants with the board seen by at least one sensor
    used_instants: int  # instants in the optimisation
    floor_views: int
    solve_ms: float

    @property
    def all_calibrated(self) -> bool:
        return all(s.calibrated for s in self.sensors.values())

    def as_dict(self) -> dict[str, object]:
        return {
            "sensors": {k: v.as_dict() for k, v in self.sensors.items()},
            "covisibility": [
                {"a": a, "b": b, "views": n} for (a, b), n in sorted(self.covisibility.items())
            ],
            "instants": self.instants,
            "used_instants": self.used_instants,
            "floor_views": self.floor_views,
            "solve_ms": self.solve_ms,
        }


@dataclasses.dataclass
class NetworkResult:
    """The solved network.

    ``world_T_camera`` is in the floor frame when a board lay on the floor
    (``world == "floor"``), else in the root camera's frame
    (``world == "camera:<id>"``). Sensors the board never linked to the
    others are listed in ``uncalibrated``.
    """

    world_T_camera: dict[str, np.ndarray]
    world: str
    root: str
    world_T_board: dict[int, np.ndarray]
    sensors: dict[str, SensorStatus]
    uncalibrated: list[str]
    rms_px: float
    floor_views: int
    seconds: float
    anchor: int | None = None  # the floor instant that sets the world frame

    def as_dict(self, images: Mapping[str, str] | None = None) -> dict[str, object]:
        """The world, each calibrated sensor (pose, views used, RMS and, from ``images``,
        the image its board was found in), the uncalibrated ones and the solve's figures."""
        images = images or {}
        return {
            "world": self.world,
            "sensors": {
                sid: {
                    "world_T_camera": as_matrix4(self.world_T_camera[sid]),
                    "views": self.sensors[sid].used_views,
                    "rms_px": self.sensors[sid].rms_px,
                    "image": images.get(sid, ""),
                }
                for sid in sorted(self.world_T_camera)
            },
            "uncalibrated": self.uncalibrated,
            "rms_px": self.rms_px,
            "floor_views": self.floor_views,
            "solve_seconds": self.seconds,
        }


# --------------------------------------------------------------- calibrator


class NetworkCalibrator:
    """Calibrates a network from synchronised checkerboard views, live.

    ``add({sensor: corners, ...}, floor=...)`` takes the corners every sensor
    found at one instant (pixels, board order) and returns the updated
    :class:`Feedback`; ``solve()`` runs the global optimisation and returns a
    :class:`NetworkResult`. An instant enters the optimisation once two of its
    sensors are calibrated (one, for a board on the floor); a sensor's views
    join as soon as the tree reaches it.
    """

    def __init__(
        self,
        board: Checkerboard,
        intrinsics: Mapping[str, Intrinsics],
        params: Params | None = None,
        root: str | None = None,
        fixed_poses: Mapping[str, np.ndarray] | None = None,
    ) -> None:
        """``fixed_poses``: world_T_camera of sensors to hold where they are (then only the
        boards, and the floor, are solved for)."""
        if not intrinsics:
            raise CalibrationError("network calibration needs at least one sensor.")
        board.require_asymmetric()
        self.board = board
        self.intrinsics = dict(intrinsics)
        self.params = params if params is not None else NETWORK_PARAMS.create()
        self.preferred_root = root
        self.tree = CalibrationTree()
        self.instants: list[Instant] = []
        self.status = {sid: SensorStatus() for sid in sorted(self.intrinsics)}
        self.covisibility: dict[tuple[str, str], int] = {}
        self.graph = FactorGraph(board, self.intrinsics, self.params)
        self.isam: gtsam.ISAM2 | None = None
        self.estimate: gtsam.Values | None = None
        self.floor_anchor: int | None = None
        self.last_centres: dict[str, np.ndarray] = {}
        self.solve_ms = 0.0
        self.fixed: dict[str, np.ndarray] = {}
        if fixed_poses:
            self._fix(fixed_poses)

    def _fix(self, world_T_camera: Mapping[str, np.ndarray]) -> None:
        """Seed the tree with known poses (network frame: the first one's camera)."""
        root = sorted(world_T_camera)[0]
        camera_T_world = invert(np.asarray(world_T_camera[root], dtype=np.float64))
        self.tree.root = root
        for sid, pose in world_T_camera.items():
            self.fixed[sid] = camera_T_world @ np.asarray(pose, dtype=np.float64)
            if sid != root:
                self.tree.parent[sid] = root
                self.tree.link_quality[sid] = math.inf
                self.tree.parent_T_child[sid] = self.fixed[sid]
            self.status[sid].calibrated = True

    # ---------------------------------------------------------------- input
    def add(self, corners: Mapping[str, np.ndarray | None], *, floor: bool = False) -> Feedback:
        """Feed the corners seen at one instant (None or absent: board not seen)."""
        started = time.perf_counter()
        views: dict[str, BoardView] = {}
        for sid, found in corners.items():
            if found is None:
                continue
            if sid not in self.intrinsics:
                raise CalibrationError(
                    f"sensor '{sid}' has no intrinsics in this calibration; add it or drop its views."
                )
            view = observe_board(sid, found, self.intrinsics[sid], self.board)
            if view.rms_px <= self.params.max_pnp_rms_px:
                views[sid] = view
            else:
                self.status[sid].rejected += 1
        if views and self._moved_enough(views):
            self._accept(views, floor)
        self.solve_ms = (time.perf_counter() - started) * 1000.0
        return self.feedback()

    def _moved_enough(self, views: Mapping[str, BoardView]) -> bool:
        """False when the same sensors see the board where they last did (a still board)."""
        threshold = float(self.params.min_board_motion)
        centres = {
            sid: v.camera_T_board[:3, :3] @ self.board.center + v.camera_T_board[:3, 3]
            for sid, v in views.items()
        }
        still = set(centres) == set(self.last_centres) and all(
            np.linalg.norm(centres[s] - self.last_centres[s]) < threshold for s in centres
        )
        if threshold > 0 and still:
            return False
        self.last_centres = centres
        return True

    def _accept(self, views: dict[str, BoardView], floor: bool) -> None:
        instant = Instant(len(self.instants), views, floor)
        self.instants.append(instant)
        for sid in views:
            self.status[sid].views += 1
        for a, b in iter_pairs(views):
            self.covisibility[(a, b)] = self.covisibility.get((a, b), 0) + 1
        self.tree.offer(views, self.preferred_root)
        for sid in self.tree.sensors:
            self.status[sid].calibrated = True
            self.status[sid].parent = self.tree.parent.get(sid)
        if self.params.incremental:
            self._update_incremental()

    # ----------------------------------------------------------- building
    def _addable(self, instant: Instant) -> list[str]:
        """Sensors of an instant whose corners can enter the graph now."""
        calibrated = sorted(s for s in instant.views if self.tree.calibrated(s))
        if instant.added:
            return [s for s in calibrated if s not in instant.added]
        if len(calibrated) >= 2 or (instant.floor and calibrated):
            return calibrated
        return []

    def _place_cameras(self, values: gtsam.Values | None) -> dict[str, np.ndarray]:
        """network_T_camera of every calibrated sensor: the current estimate where there is
        one, else chained from a placed ancestor along the tree."""
        placed: dict[str, np.ndarray] = {}
        for sid in self.tree.sensors:
            key = self.graph.camera_key(sid)
            if values is not None and values.exists(key):
                placed[sid] = values.atPose3(key).matrix()
        for sid in self.tree.sensors:
            chain, node = [], sid
            while node not in placed and node != self.tree.root:
                chain.append(node)
                node = self.tree.parent[node]
            pose = placed.setdefault(node, np.eye(4))  # a placed sensor, or the root
            for child in reversed(chain):
                pose = pose @ self.tree.parent_T_child[child]
                placed[child] = pose
        return placed

    def _board_initial(self, instant: Instant, cameras: Mapping[str, np.ndarray]) -> np.ndarray:
        """network_T_board from the best view of a placed camera."""
        best = max(
            (v for v in instant.views.values() if v.sensor_id in cameras),
            key=lambda v: v.quality,
        )
        return cameras[best.sensor_id] @ best.camera_T_board

    def _add_instant(
        self,
        instant: Instant,
        sensors: list[str],
        cameras: Mapping[str, np.ndarray],
        values: gtsam.Values,
        graph: gtsam.NonlinearFactorGraph,
        existing: gtsam.Values | None,
        anchor: bool,
    ) -> None:
        key = board_key(instant.index)
        new_board = not instant.added
        anchor = anchor and new_board
        if new_board:
            if existing is not None and existing.exists(key):
                board_T_network = existing.atPose3(key)
            else:
                board_T_network = gtsam.Pose3(invert(self._board_initial(instant, cameras)))
            values.insert(key, board_T_network)
            if anchor:
                self.floor_anchor = instant.index
                if existing is not None and existing.exists(FLOOR_KEY):
                    values.insert(FLOOR_KEY, existing.atPose3(FLOOR_KEY))
                else:
                    floor_T_board = make_pose(
                        FLOOR_FLIP, (0.0, 0.0, float(self.params.board_thickness))
                    )
                    values.insert(FLOOR_KEY, gtsam.Pose3(floor_T_board @ board_T_network.matrix()))
        graph.push_back(
            self.graph.instant_factors(
                instant, sensors, floor=new_board and instant.floor, anchor=anchor
            )
        )
        instant.added.update(sensors)

    def _update_incremental(self) -> None:
        if self.tree.root is None:
            return
        pending = [(i, s) for i in self.instants if (s := self._addable(i))]
        if not pending:
            return
        if self.isam is None:
            params = gtsam.ISAM2Params()
            params.setRelinearizeThreshold(float(self.params.relinearize_threshold))
            self.isam = gtsam.ISAM2(params)
            graph, values = self.graph.base(self.tree.root, self.fixed)
        else:
            graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        cameras = self._place_cameras(self.estimate)
        for sid, pose in cameras.items():
            key = self.graph.camera_key(sid)
            if self.estimate is None or not self.estimate.exists(key):
                values.insert(key, gtsam.Pose3(pose))
        for instant, sensors in pending:
            anchor = instant.floor and self.floor_anchor is None
            self._add_instant(instant, sensors, cameras, values, graph, None, anchor)
        self.isam.update(graph, values)
        self.estimate = self.isam.calculateEstimate()
        self._refresh_rms(self.estimate)

    # ------------------------------------------------------------ figures
    def _residuals(self, values: gtsam.Values) -> dict[str, np.ndarray]:
        """Pinhole reprojection errors (px) of every corner in the graph, per sensor."""
        per_sensor: dict[str, list[np.ndarray]] = {}
        objects = self.board.object_points
        cameras = {
            sid: values.atPose3(self.graph.camera_key(sid)).matrix()
            for sid in self.tree.sensors
            if values.exists(self.graph.camera_key(sid))
        }
        for instant in self.instants:
            key = board_key(instant.index)
            if not instant.added or not values.exists(key):
                continue
            board_T_network = values.atPose3(key).matrix()
            for sid in instant.added:
                camera_T_board = invert(board_T_network @ cameras[sid])
                errors = pinhole_residuals_px(
                    objects, camera_T_board, self.intrinsics[sid], instant.views[sid].pinhole
                )
                per_sensor.setdefault(sid, []).append(errors)
        return {sid: np.concatenate(errors) for sid, errors in per_sensor.items()}

    def _refresh_rms(self, values: gtsam.Values) -> None:
        residuals = self._residuals(values)
        for sid, status in self.status.items():
            errors = residuals.get(sid)
            status.used_views = sum(1 for i in self.instants if sid in i.added)
            status.rms_px = (
                float(np.sqrt(np.mean(errors**2))) if errors is not None and errors.size else None
            )

    def feedback(self) -> Feedback:
        return Feedback(
            sensors={k: dataclasses.replace(v) for k, v in self.status.items()},
            covisibility=dict(self.covisibility),
            instants=len(self.instants),
            used_instants=sum(1 for i in self.instants if i.in_graph),
            floor_views=sum(1 for i in self.instants if i.floor and i.in_graph),
            solve_ms=self.solve_ms,
        )

    # -------------------------------------------------------------- solve
    def _best_floor_instant(self) -> int | None:
        """The floor board that sets the world's origin and heading: the one seen by the most
        calibrated sensors, then the largest in their images."""
        best: tuple[int, float, int] | None = None
        for instant in self.instants:
            sensors = [s for s in instant.views if self.tree.calibrated(s)]
            if not instant.floor or not sensors:
                continue
            score = (len(sensors), sum(instant.views[s].quality for s in sensors), -instant.index)
            if best is None or score > best:
                best = score
        return None if best is None else -best[2]

    def solve(self) -> NetworkResult:
        """Global Levenberg-Marquardt over all cameras and boards (eq. 1-4), started from
        the live estimate (or the tree)."""
        started = time.perf_counter()
        if self.tree.root is None:
            seen = sorted(s for s, st in self.status.items() if st.views)
            raise CalibrationError(
                "no two sensors ever saw the board at the same time "
                f"(sensors that saw it: {', '.join(seen) or 'none'}); move the board where "
                "neighbouring cameras overlap."
            )
        existing = self.estimate
        graph, values = self.graph.base(self.tree.root, self.fixed)
        cameras = self._place_cameras(existing)
        for sid, pose in cameras.items():
            values.insert(self.graph.camera_key(sid), gtsam.Pose3(pose))
        self.floor_anchor = None
        for instant in self.instants:
            instant.added = set()
        anchor = self._best_floor_instant()
        for instant in self.instants:
            sensors = self._addable(instant)
            if sensors:
                self._add_instant(
                    instant, sensors, cameras, values, graph, existing, instant.index == anchor
                )
        lm = gtsam.LevenbergMarquardtParams()
        lm.setMaxIterations(int(self.params.max_iterations))
        lm.setRelativeErrorTol(float(self.params.relative_error_tol))
        result = gtsam.LevenbergMarquardtOptimizer(graph, values, lm).optimize()
        self.estimate = result
        self.isam = None  # the live solver would now disagree with the estimate
        self._refresh_rms(result)
        network_T = {sid: result.atPose3(self.graph.camera_key(sid)).matrix() for sid in cameras}
        if self.floor_anchor is not None:
            world_T_network = result.atPose3(FLOOR_KEY).matrix()
            world = "floor"
        else:
            world_T_network = np.eye(4)
            world = f"camera:{self.tree.root}"
        boards = {
            i.index: world_T_network @ invert(result.atPose3(board_key(i.index)).matrix())
            for i in self.instants
            if i.in_graph
        }
        residuals = self._residuals(result)
        everything = np.concatenate(list(residuals.values())) if residuals else np.zeros(0)
        return NetworkResult(
            world_T_camera={sid: world_T_network @ pose for sid, pose in network_T.items()},
            world=world,
            root=self.tree.root,
            world_T_board=boards,
            sensors={k: dataclasses.replace(v) for k, v in self.status.items()},
            uncalibrated=sorted(s for s in self.intrinsics if s not in cameras),
            rms_px=float(np.sqrt(np.mean(everything**2))) if everything.size else math.nan,
            floor_views=sum(1 for i in self.instants if i.floor and i.in_graph),
            seconds=time.perf_counter() - started,
            anchor=self.floor_anchor,
        )


def iter_pairs(names: Iterable[str]) -> Iterable[tuple[str, str]]:
    names = sorted(names)
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            yield a, b
