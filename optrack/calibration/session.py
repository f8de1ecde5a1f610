"""A recorded checkerboard session turned into a network calibration.

Frames are taken in time bins (``view_rate_hz``); in each bin every sensor
contributes its first frame, stamped with the bin's time. The board is looked
for in the image that belongs to the depth camera: the infrared image when the
colour image is not registered to the depth (the pose that matters is the
depth camera's), else the colour image. A view counts only while the board is
held still in that sensor (corners moved less than ``max_motion_px`` since its
previous bin), so that sensors whose clocks disagree slightly still see the
same board pose: the still-board rule of :mod:`optrack.calibration.still`,
which the live calibration shares.

A board lies on the floor when the depth around it (a ring beyond its printed
border) is one surface whose median is in the board's plane (noise-tolerant:
the spread allowed follows the depth's own robust sigma) and its face looks up
in the camera (within ``floor_max_tilt_deg`` of the camera's up direction, -y).
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import heapq
import math
import os
import sys
from collections.abc import Callable, Iterator, Mapping

import numpy as np

from optrack.calibration.board import CORNER_PARAMS, Checkerboard, find_corners
from optrack.calibration.network import (
    NETWORK_PARAMS,
    BoardView,
    NetworkCalibrator,
    NetworkResult,
    observe_board,
)
from optrack.calibration.still import StillBoard, StillBoards
from optrack.errors import UserError
from optrack.geometry import transform_points
from optrack.params import Param, Params, Schema, register
from optrack.recording import Recording
from optrack.recording.format import IndexEntry, SensorInfo
from optrack.types import Intrinsics

__all__ = [
    "SESSION_PARAMS",
    "SessionResult",
    "board_from_recording",
    "board_on_floor",
    "calibrate_recording",
    "pick_image",
]

SESSION_PARAMS = register(
    Schema(
        "calibration_session",
        [
            Param(
                "view_rate_hz",
                2.0,
                min=0.1,
                max=60.0,
                unit="Hz",
                help="How many instants per second of a recording are searched for the board.",
            ),
            Param(
                "max_motion_px",
                2.0,
                min=0.0,
                max=100.0,
                unit="px",
                help="A sensor's view counts only when its corners moved less than this (RMS) "
                "since the previous instant: the board is held still (0: no check).",
            ),
            Param(
                "image",
                "auto",
                choices=("auto", "color", "infrared"),
                help="Image to find the board in: auto picks the depth camera's own image.",
            ),
            Param(
                "floor_ring_inner",
                2.5,
                min=1.0,
                max=10.0,
                unit="squares",
                help="The floor test samples depth from this far beyond the inner corners...",
            ),
            Param(
                "floor_ring_outer",
                5.0,
                min=1.5,
                max=20.0,
                unit="squares",
                help="...to this far.",
            ),
            Param(
                "floor_tolerance",
                0.03,
                min=0.001,
                max=0.5,
                unit="m",
                help="The ring's median must be this close to the board's plane (and samples "
                "this close to the median are on one surface).",
            ),
            Param(
                "floor_min_fraction",
                0.6,
                min=0.05,
                max=1.0,
                help="Share of valid ring samples that must be on one surface for a board on "
                "the floor.",
            ),
            Param(
                "floor_spread_sigmas",
                3.0,
                min=1.0,
                max=10.0,
                help="Samples within this many robust standard deviations of the ring's median "
                "are also on one surface (depth noisier than floor_tolerance: stereo far away).",
            ),
            Param(
                "floor_max_tilt_deg",
                65.0,
                min=0.0,
                max=90.0,
                unit="deg",
                help="A board on the floor faces up: within this angle of the camera's up (-y).",
            ),
        ],
        help="Reading a recorded checkerboard session for network calibration.",
    )
)


MAD_TO_SIGMA = 1.4826  # median absolute deviation to the standard deviation of a normal


class SessionError(UserError):
    """A recording that cannot be used for calibration."""


def pick_image(info: SensorInfo, choice: str = "auto") -> tuple[str, Intrinsics] | None:
    """Which image of a sensor to find the board in ("color" or "infrared") and the
    intrinsics of that image, from what the recording says of the sensor; None if none."""
    has_color = "color" in info.streams
    has_infrared = "infrared" in info.streams
    registered_color = has_color and info.color_intrinsics is None
    if choice == "infrared" or (choice == "auto" and has_infrared and not registered_color):
        return ("infrared", info.intrinsics) if has_infrared else None
    if not has_color:
        return None
    return "color", info.color_intrinsics or info.intrinsics


def board_on_floor(
    view: BoardView,
    depth_m: np.ndarray,
    intrinsics: Intrinsics,
    board: Checkerboard,
    params: Params,
    thickness: float,
) -> bool:
    """True when the board lies on a larger surface that faces up in the camera (the floor).

    ``depth_m`` must be registered to the image the board was found in
    (``intrinsics``).
    """
    camera_T_board = view.camera_T_board
    face_normal = -camera_T_board[:3, 2]  # the printed face looks along -z
    if face_normal @ np.array([0.0, -1.0, 0.0]) < math.cos(math.radians(params.floor_max_tilt_deg)):
        return False
    s = board.square
    step = 0.5
    inner, outer = float(params.floor_ring_inner), float(params.floor_ring_outer)
    grid = np.arange(-outer, max(board.cols, board.rows) - 1 + outer + 1e-9, step)
    xs, ys = np.meshgrid(grid, grid)
    x, y = xs.ravel(), ys.ravel()
    dx = np.maximum(np.maximum(-x, x - (board.cols - 1)), 0.0)
    dy = np.maximum(np.maximum(-y, y - (board.rows - 1)), 0.0)
    beyond = np.maximum(dx, dy)
    ring = (beyond >= inner) & (beyond <= outer)
    points = np.stack([x[ring] * s, y[ring] * s, np.zeros(ring.sum())], axis=1)
    camera_points = transform_points(camera_T_board, points)
    in_front = camera_points[:, 2] > 0.1
    camera_points = camera_points[in_front]
    u = intrinsics.fx * camera_points[:, 0] / camera_points[:, 2] + intrinsics.cx
    v = intrinsics.fy * camera_points[:, 1] / camera_points[:, 2] + intrinsics.cy
    height, width = depth_m.shape
    inside = (u >= 0) & (u <= width - 1) & (v >= 0) & (v <= height - 1)
    if inside.sum() < 8:
        return False
    cols, rows = np.rint(u[inside]).astype(int), np.rint(v[inside]).astype(int)
    z = depth_m[rows, cols].astype(np.float64)
    valid = np.isfinite(z) & (z > 0)
    if valid.sum() < 8:
        return False
    rays = np.stack(
        [
            (cols[valid] - intrinsics.cx) / intrinsics.fx,
            (rows[valid] - intrinsics.cy) / intrinsics.fy,
            np.ones(valid.sum()),
        ],
        axis=1,
    )
    measured = rays * z[valid, None]
    # Distance behind the face, along the board's z (into the floor): the floor is at +thickness.
    behind = (measured - camera_T_board[:3, 3]) @ camera_T_board[:3, 2]
    # One surface (most samples within a few robust sigmas of their median: noisy depth,
    # e.g. stereo at 5 m, spreads it but keeps it centred), and that surface is the
    # board's plane (its median within floor_tolerance of the floor).
    centre = float(np.median(behind))
    sigma = MAD_TO_SIGMA * float(np.median(np.abs(behind - centre)))
    spread = max(float(params.floor_tolerance), float(params.floor_spread_sigmas) * sigma)
    one_surface = np.mean(np.abs(behind - centre) < spread) >= params.floor_min_fraction
    return bool(one_surface and abs(centre - thickness) < params.floor_tolerance)


def board_from_recording(recording: Recording) -> Checkerboard | None:
    """The board a recording declares (manifest ``extra.board``, else its ground truth)."""
    extra = recording.manifest.extra.get("board") if recording.manifest.extra else None
    if isinstance(extra, dict) and {"cols", "rows", "square"} <= set(extra):
        return Checkerboard(int(extra["cols"]), int(extra["rows"]), float(extra["square"]))
    for truth in recording.ground_truth():
        for board in truth.boards:
            return Checkerboard(board.cols, board.rows, board.square)
    return None


def _bins(recording: Recording, rate: float) -> Iterator[dict[str, IndexEntry]]:
    """The first frame of every sensor in each time bin of 1/rate seconds."""

    def keyed(sid: str) -> Iterator[tuple[float, str, IndexEntry]]:
        for entry in recording.index(sid):
            yield entry.t, sid, entry

    current: dict[str, IndexEntry] = {}
    current_bin: int | None = None
    start: float | None = None
    for t, sid, entry in heapq.merge(*(keyed(s) for s in recording.sensor_ids)):
        if start is None:
            start = t
        index = int(math.floor((t - start) * rate))
        if current_bin is not None and index != current_bin:
            yield current
            current = {}
        current_bin = index
        current.setdefault(sid, entry)
    if current:
        yield current


@dataclasses.dataclass
class SessionResult:
    """A calibrated recording: the network, and what was found in it."""

    network: NetworkResult
    board: Checkerboard
    intrinsics: dict[str, Intrinsics]
    image: dict[str, str]
    instants: int
    floor_instants: int
    detections: dict[str, int]
    timeline: list[tuple[float, bool]]  # (time, on the floor) of every instant used


def _floor_after(floor: str) -> float | None:
    """``after:T`` as T; None for ``auto`` and ``none``; a SessionError for anything else."""
    if floor.startswith("after:"):
        try:
            return float(floor.split(":", 1)[1])
        except ValueError:
            raise SessionError(
                f"--floor must be auto, none or after:SECONDS; got '{floor}'."
            ) from None
    if floor not in ("auto", "none"):
        raise SessionError(f"--floor must be auto, none or after:SECONDS; got '{floor}'.")
    return None


@dataclasses.dataclass
class _BoardReader:
    """Finds the board in one sensor's frame and, for ``depth_test``, tells whether it
    lies on the floor (run on a worker thread: OpenCV releases the GIL)."""

    recording: Recording
    board: Checkerboard
    usable: dict[str, tuple[str, Intrinsics]]
    corner_params: Params
    session_params: Params
    thickness: float
    depth_test: bool

    def look(self, sid: str, entry: IndexEntry) -> tuple[np.ndarray | None, bool | None]:
        """(corners or None, on the floor or None when the depth cannot tell) of one frame."""
        kind, intrinsics = self.usable[sid]
        frame = self.recording.load(sid, entry, (kind,))
        image = frame.infrared if kind == "infrared" else frame.color
        if image is None:
            return None, None
        corners = find_corners(image, self.board, self.corner_params, infrared=kind == "infrared")
        registered = kind == "infrared" or self.recording.sensors[sid].color_intrinsics is None
        if corners is None or not registered or not self.depth_test:
            return corners, None
        view = observe_board(sid, corners, intrinsics, self.board)
        on_floor = board_on_floor(
            view, frame.depth_m(), intrinsics, self.board, self.session_params, self.thickness
        )
        return corners, on_floor


@dataclasses.dataclass
class _Tally:
    """Feeds still boards to the calibrator and counts what went in."""

    calibrator: NetworkCalibrator
    floor_after: float | None
    report: Callable[[str], None]
    detections: dict[str, int]
    start: float = 0.0
    instants: int = 0
    floor_instants: int = 0
    timeline: list[tuple[float, bool]] = dataclasses.field(default_factory=list)

    def feed(self, still: StillBoard) -> None:
        t = still.end
        if self.floor_after is not None:
            is_floor = t - self.start >= self.floor_after
        else:
            is_floor = still.on_floor()
        for sid in still.corners:
            self.detections[sid] += 1
        feedback = self.calibrator.add(still.corners, floor=is_floor)
        self.timeline.append((t, is_floor))
        self.instants += 1
        self.floor_instants += int(is_floor)
        calibrated = sum(1 for st in feedback.sensors.values() if st.calibrated)
        self.report(
            f"t={t - self.start:6.1f} s: board seen by {', '.join(sorted(still.corners))}"
            f"{' (on the floor)' if is_floor else ''}; {calibrated}/{len(feedback.sensors)} "
            "sensors calibrated"
        )


def calibrate_recording(
    recording: Recording,
    board: Checkerboard,
    *,
    floor: str = "auto",
    network_params: Params | None = None,
    session_params: Params | None = None,
    corner_params: Params | None = None,
    progress: Callable[[str], None] | None = None,
    fixed_poses: Mapping[str, np.ndarray] | None = None,
) -> SessionResult:
    """Calibrate every sensor of a recorded checkerboard session.

    ``floor``: ``auto`` (the depth test of :func:`board_on_floor`), ``none``,
    or ``after:T`` (every view from T seconds after the start lies on the floor).
    ``fixed_poses`` (world_T_camera) holds those sensors where they are.
    """
    sp = session_params if session_params is not None else SESSION_PARAMS.create()
    np_ = network_params if network_params is not None else NETWORK_PARAMS.create()
    cp = corner_params if corner_params is not None else CORNER_PARAMS.create()
    floor_after = _floor_after(floor)
    chosen = {sid: pick_image(info, str(sp.image)) for sid, info in recording.sensors.items()}
    usable = {sid: c for sid, c in chosen.items() if c is not None}
    if not usable:
        raise SessionError(
            f"no sensor of {recording.path} recorded a {sp.image} image to find the board in; "
            "record colour or infrared images."
        )
    calibrator = NetworkCalibrator(
        board,
        {sid: c[1] for sid, c in usable.items()},
        np_,
        fixed_poses={s: p for s, p in (fixed_poses or {}).items() if s in usable} or None,
    )
    reader = _BoardReader(
        recording, board, usable, cp, sp, float(np_.board_thickness), floor == "auto"
    )
    tally = _Tally(
        calibrator, floor_after, progress or (lambda message: None), dict.fromkeys(usable, 0)
    )
    grouper = StillBoards(usable, float(sp.max_motion_px))
    workers = max(1, min(len(usable), os.cpu_count() or 1))
    with concurrent.futures.ThreadPoolExecutor(workers) as pool:
        for index, bin_entries in enumerate(_bins(recording, float(sp.view_rate_hz))):
            t = min(e.t for e in bin_entries.values())
            tally.start = t if index == 0 else tally.start
            searched = sorted(sid for sid in bin_entries if sid in usable)
            looked = pool.map(reader.look, searched, [bin_entries[sid] for sid in searched])
            for sid, (corners, on_floor) in zip(searched, looked, strict=True):
                grouper.add(sid, t, corners, on_floor)
            for still in grouper.ready():
                tally.feed(still)
    for still in grouper.ready(final=True):
        tally.feed(still)
    if tally.instants == 0:
        raise SessionError(
            f"the {board.cols}x{board.rows} board was not found held still in any frame of "
            f"{recording.path}; check --board and --square, and that the board is visible and lit."
        )
    return SessionResult(
        network=calibrator.solve(),
        board=board,
        intrinsics=dict(calibrator.intrinsics),
        image={sid: c[0] for sid, c in usable.items()},
        instants=tally.instants,
        floor_instants=tally.floor_instants,
        detections=tally.detections,
        timeline=tally.timeline,
    )


def stderr_progress(message: str) -> None:
    print(message, file=sys.stderr, flush=True)
