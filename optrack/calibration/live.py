"""Live network calibration over the bus: the calibration wizard's backend.

The wizard (``app/wizard``) and ``optrack calibrate live`` drive a running
site through this module; it is Qt-free and safe to call from any thread.

How it works::

    LiveCalibration.start("extrinsics")
        -> command "calibration_capture" {phase, board, rate_hz} to every detector node
           (optrack/runtime/calibration_capture.py): each node looks for the board in
           its depth camera's own image a few times per second and publishes a
           BoardViewMessage on board_views/<sensor> (tracker-time stamp, corners or
           none, on the floor or not, a small JPEG preview with the corners drawn)
        -> on a simulated site, command "operator" {action} to the site node: its
           simulated operator moves the board / shows it to the one sensor whose
           intrinsics are wanted / lays it on the floor / walks
    board views --> still instants (session.py's still-board rule per sensor; sensors
           whose still intervals overlap saw the same board pose) -->
           NetworkCalibrator.add(...) (iSAM2 live feedback)
    state()   -> LiveState snapshot for the GUI (~5 Hz)
    solve()   -> global bundle adjustment with the floor boards (world frame on the floor)
    refine()  -> Algorithm 1 from the walker's detections (DetectionsMessage)
    save() / publish()

Additions to the shared interface are marked "(added)" in the docstrings.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
import queue
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import cv2
import msgspec
import numpy as np

from optrack.calibration.board import CORNER_PARAMS, Checkerboard, CoverageMap
from optrack.calibration.files import (
    BoardEntry,
    CalibrationFile,
    SensorEntry,
    new_calibration_id,
    now_iso,
    save_calibration,
)
from optrack.calibration.intrinsics import IntrinsicsResult, calibrate_intrinsics
from optrack.calibration.network import (
    FLOOR_KEY,
    NETWORK_PARAMS,
    CalibrationError,
    NetworkCalibrator,
    NetworkResult,
    pinhole_residuals_px,
)
from optrack.calibration.refinement import (
    REFINEMENT_PARAMS,
    Trajectory,
    alignment_error,
    refine_from_trajectories,
)
from optrack.calibration.session import SESSION_PARAMS
from optrack.errors import UserError
from optrack.geometry import invert
from optrack.net.bus import Bus
from optrack.net.messages import (
    BoardViewMessage,
    CalibrationMessage,
    DetectionsMessage,
    StatusMessage,
)
from optrack.params import Param, Params, Schema, register
from optrack.runtime.node import send_command
from optrack.types import Intrinsics, NetworkCalibration, SensorCalibration

__all__ = [
    "LIVE_PARAMS",
    "PHASES",
    "LiveCalibration",
    "LiveCalibrationError",
    "LiveState",
    "Progress",
    "RefinementReport",
    "SensorLive",
]

log = logging.getLogger("optrack.calibration.live")

#: (fraction 0..1, sentence)
Progress = Callable[[float, str], None]

#: The phases :meth:`LiveCalibration.start` takes ("idle" is the state between them).
PHASES = ("intrinsics", "extrinsics", "floor", "refinement")

#: What the simulated operator does in each phase (optrack.runtime.calibration_capture).
OPERATOR_ACTION = {
    "intrinsics": "show_board",
    "extrinsics": "move_board",
    "floor": "lay_board",
    "refinement": "walk",
}

LIVE_PARAMS = register(
    Schema(
        "calibration_live",
        [
            Param(
                "discover_s",
                3.0,
                min=0.1,
                max=60.0,
                unit="s",
                help="How long to listen for the site's detector nodes when none are named.",
            ),
            Param(
                "max_still_gap_s",
                3.0,
                min=0.1,
                max=30.0,
                unit="s",
                help="Two searches of one sensor at most this far apart, whose corners moved "
                "less than calibration_session.max_motion_px, show the board held still in "
                "between.",
            ),
            Param(
                "command_timeout_s",
                10.0,
                min=0.1,
                max=60.0,
                unit="s",
                help="How long to wait for a node to answer a command.",
            ),
            Param(
                "operator_wait_s",
                120.0,
                min=1.0,
                max=600.0,
                unit="s",
                help="How long start() waits for the detector nodes to come back on the "
                "simulated operator's scene.",
            ),
            Param(
                "intrinsics_min_motion_px",
                15.0,
                min=0.0,
                max=500.0,
                unit="px",
                help="Intrinsics phase: a view is kept when its corners moved at least this "
                "(RMS) from the last kept one.",
            ),
            Param(
                "coverage_corners",
                20,
                min=1,
                max=10000,
                step=1,
                help="Corners in a coverage cell for it to show as full (intrinsics page).",
            ),
            Param(
                "max_refinement_s",
                600.0,
                min=1.0,
                max=7200.0,
                unit="s",
                help="The refinement phase keeps at most this many seconds of detections.",
            ),
            Param(
                "refinement_board_growth",
                0.25,
                min=0.0,
                max=100.0,
                help="A walk's correction of a sensor is applied only while that sensor's "
                "checkerboard views still agree with it: their reprojection RMS grows by at "
                "most this fraction; else the sensor keeps the checkerboard's pose.",
            ),
        ],
        help="The live calibration against a running site (the wizard's backend).",
    )
)


class LiveCalibrationError(UserError):
    """A live calibration step that cannot be done now."""


# A camera's optical frame (x right, y down, z ahead) seen as a level frame (x right,
# y ahead, z up): the display frame of the live poses until the floor is known.
LEVEL_T_OPTICAL = np.array(
    [[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
)


@dataclasses.dataclass
class SensorLive:
    """One sensor as the wizard shows it."""

    sensor: str
    views: int  # board views accepted for this sensor (this phase)
    rms_px: float | None  # reprojection RMS so far (None until solved once)
    calibrated: bool  # has a pose in the network tree / solution
    image: np.ndarray | None  # latest small uint8 image (HxW or HxWx3), corners drawn
    board_seen: bool  # board found in the latest image
    coverage: np.ndarray | None  # intrinsics phase: float 0..1 grid of where corners were seen
    world_T_camera: np.ndarray | None  # 4x4, current estimate (None until calibrated)
    intrinsics: Intrinsics | None
    # (added) the board lies on the floor in the latest image (the node's depth test)
    on_floor: bool = False
    # (added) board views this node has published in this phase (found or not), and the
    # rate it actually captures at (Hz, measured on our side): the truth for the status
    frames: int = 0
    capture_hz: float = 0.0
    # (added) tree parent in the network (None for the root or uncalibrated)
    parent: str | None = None


@dataclasses.dataclass
class LiveState:
    """A snapshot of the live calibration, cheap to take."""

    phase: str  # "idle", "intrinsics", "extrinsics", "floor", "refinement"
    sensors: dict[str, SensorLive]
    covisibility: list[tuple[str, str, int]]  # (sensor a, sensor b, shared views)
    floor_views: int  # board-on-floor views accepted (all sensors)
    refinement_samples: dict[str, int]  # walker detections collected per sensor
    message: str  # one sentence for the operator (what to do now / what is wrong)
    # (added) seconds since the phase started; instants (time bins with the board seen)
    elapsed_s: float = 0.0
    instants: int = 0
    # (added) the simulated operator's progress, e.g. "laying the board at place 2 of 3"
    operator: str = ""


@dataclasses.dataclass
class RefinementReport:
    """What :meth:`LiveCalibration.refine` found."""

    calibration: NetworkCalibration  # the refined calibration (not yet saved or published)
    error_before_m: float  # mean ground-plane distance between sensors' detections (Fig. 19)
    error_after_m: float
    trajectories_before: dict[str, np.ndarray]  # sensor -> Nx3 world positions
    trajectories_after: dict[str, np.ndarray]
    # (added) per-sensor 4x4 corrections applied in world x-y-z, and sensors skipped
    corrections: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    skipped: list[str] = dataclasses.field(default_factory=list)
    # (added) sensors whose walk correction was not applied, with the reprojection RMS
    # (px) their checkerboard views would have had with it; every sensor's RMS without
    # the walk's correction and with it
    refused: dict[str, float] = dataclasses.field(default_factory=dict)
    board_rms_px: dict[str, float] = dataclasses.field(default_factory=dict)
    board_rms_refined_px: dict[str, float] = dataclasses.field(default_factory=dict)


@dataclasses.dataclass
class _Instant:
    """Sensors that saw the board held still over overlapping intervals (tracker time)."""

    start: float
    end: float
    corners: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    floor_votes: dict[str, bool] = dataclasses.field(default_factory=dict)


@dataclasses.dataclass
class _Sensor:
    """What the session keeps of one sensor (guarded by the session's lock)."""

    intrinsics: Intrinsics | None = None
    model: str = ""
    image_kind: str = ""
    preview: bytes = b""
    image: np.ndarray | None = None
    board_seen: bool = False
    on_floor: bool = False
    frames: int = 0
    arrivals: list[float] = dataclasses.field(default_factory=list)
    intrinsics_corners: list[np.ndarray] = dataclasses.field(default_factory=list)
    coverage: CoverageMap | None = None
    status: StatusMessage | None = None


class LiveCalibration:
    """The wizard's calibration session against a running site (embedded or remote).

    ``bus``: an open :class:`~optrack.net.bus.Bus` of the site (the caller's; it stays
    open). ``sensors``: the detector nodes to use (default: every detector node whose
    status arrives within ``calibration_live.discover_s``). A UserError sentence when
    none is found. ``simulated`` is True when the site's ``site`` node answers the
    ``operator`` command (``optrack run`` with simulated sensors).

    Threads: bus callbacks only queue what arrives; one worker thread bins the board
    views and feeds the :class:`NetworkCalibrator`; every public method may be called
    from any thread. ``start``/``stop``/``solve``/``refine`` can take seconds (commands,
    node restarts on a simulated site, optimisation): call them off the GUI thread.
    """

    sensors: list[str]  # the site's sensors (from their detector nodes' status)
    simulated: bool  # the site has a simulated operator

    def __init__(
        self,
        bus: Bus,
        board: Checkerboard,
        *,
        sensors: Sequence[str] | None = None,
        params: Params | None = None,
        network_params: Params | None = None,
    ) -> None:
        """(added) ``params``: ``calibration_live`` values; ``network_params``:
        ``calibration_network`` values (board thickness, ...)."""
        self.bus = bus
        self.board = board
        self.params = params if params is not None else LIVE_PARAMS.create()
        self.network_params = (
            network_params if network_params is not None else NETWORK_PARAMS.create()
        )
        self.session_params = SESSION_PARAMS.create()
        self._lock = threading.RLock()
        self._solve_lock = threading.Lock()
        self._inbox: queue.SimpleQueue[tuple[str, Any]] = queue.SimpleQueue()
        self._sensors: dict[str, _Sensor] = {}
        self._statuses: dict[str, StatusMessage] = {}
        self._subscriptions: list[Any] = []
        self._closed = False
        self.phase = "idle"
        self._phase_started = time.monotonic()
        self._capturing: list[str] = []
        self._message = "Choose a page and press start."
        self._operator_acted = False
        # extrinsics / floor
        self.calibrator: NetworkCalibrator | None = None
        self._open: list[_Instant] = []  # still-board instants not yet fed
        self._last_found: dict[str, tuple[float, np.ndarray]] = {}
        self._latest: dict[str, float] = {}  # each sensor's newest view stamp
        self._newest = -math.inf
        self._poses: dict[str, np.ndarray] = {}
        self._instants = 0
        self._floor_votes = 0
        self._intrinsics_override: dict[str, Intrinsics] = {}
        self.intrinsics_sensor: str | None = None
        self.phase_wanted = ""
        # results
        self.result: NetworkResult | None = None
        self.calibration: NetworkCalibration | None = None
        self.refinement: RefinementReport | None = None
        self._detections: dict[str, list[DetectionsMessage]] = {}
        self._subscriptions.append(bus.subscribe(bus.keys.status(), StatusMessage, self._on_status))
        self.sensors = list(sensors) if sensors else self._discover()
        if not self.sensors:
            raise LiveCalibrationError(
                f"no detector node of site '{bus.keys.site}' answered within "
                f"{float(self.params.discover_s):g} s; start the site (optrack run) or check "
                "the site name and the bus settings."
            )
        for sid in self.sensors:
            self._sensors.setdefault(sid, _Sensor())
        self.simulated = self._has_operator()
        self._subscriptions.append(
            bus.subscribe(bus.keys.board_views(), BoardViewMessage, self._on_view)
        )
        self._subscriptions.append(
            bus.subscribe(bus.keys.detections(), DetectionsMessage, self._on_detections)
        )
        self._worker = threading.Thread(target=self._loop, name="live-calibration", daemon=True)
        self._worker.start()

    # ------------------------------------------------------------- discovery
    def _on_status(self, message: StatusMessage, key: str) -> None:
        with self._lock:
            self._statuses[message.node] = message
            if message.node in self._sensors:
                self._sensors[message.node].status = message

    def _discover(self) -> list[str]:
        deadline = time.monotonic() + float(self.params.discover_s)
        while time.monotonic() < deadline:
            time.sleep(0.1)
        with self._lock:
            return sorted(n for n, s in self._statuses.items() if s.role == "detector")

    def _has_operator(self) -> bool:
        try:
            send_command(self.bus, "site", "operator", {"action": "status"}, self._timeout())
        except UserError:
            return False
        return True

    def _timeout(self) -> float:
        return float(self.params.command_timeout_s)

    # ------------------------------------------------------------- receiving
    def _on_view(self, message: BoardViewMessage, key: str) -> None:
        if self.bus.keys.last_chunk(key) != message.sensor:
            raise LiveCalibrationError(
                f"a board view of '{message.sensor}' arrived on another sensor's key {key}."
            )
        self._inbox.put(("view", message))

    def _on_detections(self, message: DetectionsMessage, key: str) -> None:
        if self.phase == "refinement":
            self._inbox.put(("detections", message))

    def _loop(self) -> None:
        while not self._closed:
            try:
                kind, message = self._inbox.get(timeout=0.2)
            except queue.Empty:
                self._close_instants(final=False)
                continue
            try:
                if kind == "view":
                    self._take_view(message)
                elif kind == "detections":
                    self._take_detections(message)
                self._close_instants(final=False)
            except UserError as error:
                self._message = str(error)
            except Exception as error:  # the session must outlive one bad view
                log.exception("live calibration: a view could not be used")
                self._message = f"a board view could not be used ({type(error).__name__}: {error})."

    def _take_view(self, view: BoardViewMessage) -> None:
        with self._lock:
            sensor = self._sensors.get(view.sensor)
            if sensor is None or view.phase != self.phase:
                return
            now = time.monotonic()
            sensor.frames += 1
            sensor.arrivals = [t for t in sensor.arrivals if now - t < 5.0] + [now]
            sensor.board_seen = view.corners is not None
            sensor.on_floor = bool(view.on_floor)
            sensor.preview = view.preview_jpeg
            sensor.image = None  # decoded on demand by state()
            sensor.model = view.model or sensor.model
            sensor.image_kind = view.image
            if sensor.intrinsics is None:
                sensor.intrinsics = view.intrinsics
            if self.phase == "intrinsics":
                self._take_intrinsics_view(sensor, view)
                return
            self._still(view)

    def _take_intrinsics_view(self, sensor: _Sensor, view: BoardViewMessage) -> None:
        if view.corners is None or view.sensor != self.intrinsics_sensor:
            return
        corners = np.asarray(view.corners, dtype=np.float64)
        if sensor.intrinsics_corners:
            last = sensor.intrinsics_corners[-1]
            moved = float(np.sqrt(np.mean(np.sum((corners - last) ** 2, axis=1))))
            if moved < float(self.params.intrinsics_min_motion_px):
                return
        sensor.intrinsics_corners.append(corners)
        if sensor.coverage is None:
            k = view.intrinsics
            cells = int(CORNER_PARAMS.defaults()["coverage_cells"])
            sensor.coverage = CoverageMap(k.width, k.height, cells)
        sensor.coverage.add(corners)

    def _still(self, view: BoardViewMessage) -> None:
        """The still-board rule, live. Two consecutive searches of one sensor whose corners
        moved less than ``max_motion_px`` (and at most ``max_still_gap_s`` apart) show the
        board held still over that interval; sensors whose still intervals overlap saw the
        same board pose: one instant for the calibrator. (session.py's fixed time bins
        catch two sensors at once only when every sensor searches several frames per bin;
        live, each searches a few per second at best.)"""
        sid, stamp = view.sensor, view.stamp
        self._latest[sid] = max(self._latest.get(sid, -math.inf), stamp)
        self._newest = max(self._newest, stamp)
        if view.corners is None:
            self._last_found.pop(sid, None)
            return
        corners = np.asarray(view.corners, dtype=np.float64)
        previous = self._last_found.get(sid)
        self._last_found[sid] = (stamp, corners)
        if previous is None or not 0 < stamp - previous[0] <= float(self.params.max_still_gap_s):
            return
        moved = float(np.sqrt(np.mean(np.sum((corners - previous[1]) ** 2, axis=1))))
        max_motion = float(self.session_params.max_motion_px)
        if max_motion > 0 and moved > max_motion:
            return
        start = previous[0]
        overlapping = [i for i in self._open if i.start <= stamp and start <= i.end]
        if any(sid in i.corners for i in overlapping):
            return  # the same board pose as an instant this sensor is already in
        if overlapping:
            instant = overlapping[0]
            instant.start, instant.end = max(instant.start, start), min(instant.end, stamp)
        else:
            instant = _Instant(start, stamp)
            self._open.append(instant)
        instant.corners[sid] = corners
        if view.on_floor is not None:
            instant.floor_votes[sid] = view.on_floor

    def _close_instants(self, final: bool) -> None:
        """Feed the calibrator every instant no sensor can still join: each other sensor's
        newest search is later than the instant and its next still interval cannot start
        before it ends (or ``max_still_gap_s`` has passed)."""
        with self._lock:
            if self.calibrator is None or not self._open:
                return
            ready = []
            for instant in self._open:
                waiting = [
                    s
                    for s in self.sensors
                    if s not in instant.corners
                    and (
                        self._latest.get(s, -math.inf) <= instant.end
                        or (s in self._last_found and self._last_found[s][0] <= instant.end)
                    )
                ]
                timed_out = self._newest - instant.end > float(self.params.max_still_gap_s)
                if final or timed_out or not waiting:
                    ready.append(instant)
            for instant in sorted(ready, key=lambda i: i.end):
                self._open.remove(instant)
                self._feed(instant)

    def _feed(self, instant: _Instant) -> None:
        """One instant, as session.py feeds a time bin: the floor vote (the nodes' depth
        test, majority), then NetworkCalibrator.add (iSAM2)."""
        assert self.calibrator is not None
        found = {s: c for s, c in instant.corners.items() if s in self.calibrator.intrinsics}
        if not found:
            return
        votes = [v for s, v in instant.floor_votes.items() if s in found]
        floor = bool(votes) and sum(votes) * 2 > len(votes)
        self.calibrator.add(found, floor=floor)
        self._instants += 1
        self._floor_votes += int(floor)
        self._poses = self._current_poses()

    def _current_poses(self) -> dict[str, np.ndarray]:
        """world_T_camera of every calibrated sensor now: the live iSAM2 estimate (in the
        floor frame once a floor board is in it), else the tree's chain of PnP poses.
        Until a floor board is seen the frame is the first camera's, turned level
        (:data:`LEVEL_T_OPTICAL`: x right, y ahead, z up) so that a 3D view over a floor grid
        shows the cameras upright rather than lying on their backs."""
        c = self.calibrator
        if c is None or c.tree.root is None:
            return {}
        estimate = c.estimate
        world_T_network = LEVEL_T_OPTICAL
        if estimate is not None and estimate.exists(FLOOR_KEY):
            world_T_network = estimate.atPose3(FLOOR_KEY).matrix()
        poses = {}
        for sid in c.tree.sensors:
            key = c.graph.camera_key(sid)
            if estimate is not None and estimate.exists(key):
                poses[sid] = world_T_network @ estimate.atPose3(key).matrix()
            else:
                poses[sid] = world_T_network @ c.tree.root_T(sid)
        return poses

    def _take_detections(self, message: DetectionsMessage) -> None:
        sid = message.batch.sensor_id
        with self._lock:
            if self.phase != "refinement" or sid not in self._sensors:
                return
            batches = self._detections.setdefault(sid, [])
            batches.append(message)
            oldest = message.batch.stamp - float(self.params.max_refinement_s)
            while batches and batches[0].batch.stamp < oldest:
                batches.pop(0)

    # ---------------------------------------------------------------- phases
    def start(self, phase: str, sensor: str | None = None) -> None:
        """Ask the nodes to capture for ``phase`` (intrinsics: one ``sensor``). On a
        simulated site the simulated operator acts first (moves the board; lays it on the
        floor at its places; one person walks) and this waits until the detector nodes
        run on its scene (up to ``calibration_live.operator_wait_s``). Extrinsics and
        floor share one network calibrator (the floor phase adds floor views to it);
        starting extrinsics again starts over. Refinement collects the nodes' detections
        until :meth:`stop` or :meth:`refine`. A UserError sentence on failure (unknown
        phase or sensor, a node that refuses or does not answer)."""
        if phase not in PHASES:
            raise LiveCalibrationError(
                f"calibration phase '{phase}' is unknown; use one of {', '.join(PHASES)}."
            )
        if phase == "intrinsics" and sensor not in self.sensors:
            raise LiveCalibrationError(
                f"the intrinsics page needs one of the site's sensors "
                f"({', '.join(self.sensors)}); got {sensor!r}."
            )
        if phase != "intrinsics":
            self.board.require_asymmetric()
        self.stop()
        if self.simulated:
            self.phase_wanted = phase
            self._operator(OPERATOR_ACTION[phase], sensor)
        with self._lock:
            self.phase = phase
            self._phase_started = time.monotonic()
            self._open.clear()
            self._last_found.clear()
            self._latest.clear()
            self._newest = -math.inf
            for state in self._sensors.values():
                state.frames, state.arrivals, state.board_seen = 0, [], False
            if phase == "intrinsics":
                self.intrinsics_sensor = sensor
                target = self._sensors[str(sensor)]
                target.intrinsics_corners, target.coverage = [], None
            if phase == "refinement":
                self._detections = {}
        if phase == "refinement":
            self._message = "One person walks alone through every camera's view."
            return
        targets = [str(sensor)] if phase == "intrinsics" else list(self.sensors)
        replies = {}
        for sid in targets:
            replies[sid] = send_command(
                self.bus,
                sid,
                "calibration_start",
                {
                    "phase": phase,
                    "cols": self.board.cols,
                    "rows": self.board.rows,
                    "square": self.board.square,
                    "thickness": float(self.network_params.board_thickness),
                },
                self._timeout(),
            )
            with self._lock:
                self._capturing.append(sid)
        with self._lock:
            for sid, reply in replies.items():
                state = self._sensors[sid]
                state.intrinsics = msgspec.convert(reply["intrinsics"], Intrinsics)
                state.model = str(reply.get("model", ""))
                state.image_kind = str(reply.get("image", ""))
            if phase == "extrinsics" or (phase == "floor" and self.calibrator is None):
                self._new_calibrator()
        self._message = (
            "Show the board all over the image, tilted."
            if phase == "intrinsics"
            else "Move the board where cameras overlap; hold it still for a second at each place."
            if phase == "extrinsics"
            else "Lay the board flat on the floor where cameras see it, at one or several places."
        )

    def _new_calibrator(self) -> None:
        intrinsics = {}
        for sid in self.sensors:
            k = self._intrinsics_override.get(sid) or self._sensors[sid].intrinsics
            if k is not None:
                intrinsics[sid] = k
        self.calibrator = NetworkCalibrator(self.board, intrinsics, self.network_params)
        self.result = None
        self._poses = {}
        self._instants = self._floor_votes = 0

    def _operator(self, action: str, sensor: str | None = None) -> None:
        """Have the simulated operator act and wait for the nodes to run on its scene
        (``sensor``: the one it shows the board to, for the intrinsics)."""
        reply = send_command(
            self.bus,
            "site",
            "operator",
            {
                "action": action,
                "cols": self.board.cols,
                "rows": self.board.rows,
                "square": self.board.square,
                "pairs": action == "move_board" and self.phase_wanted == "extrinsics",
                "sensor": sensor or "",
            },
            self._timeout(),
        )
        self._operator_acted = True
        scene = str(reply.get("scene", ""))
        self._message = f"The simulated operator gets ready ({action.replace('_', ' ')})."
        deadline = time.monotonic() + float(self.params.operator_wait_s)
        while True:
            with self._lock:
                ready = [
                    sid
                    for sid in self.sensors
                    if (st := self._statuses.get(sid)) is not None
                    and scene in st.sensor
                    and st.state == "running"
                ]
                site = self._statuses.get("site")
                error = str(site.values.get("operator.error", "")) if site is not None else ""
            if len(ready) == len(self.sensors):
                return
            if error and site is not None and site.values.get("operator.scene") == scene:
                raise LiveCalibrationError(error)
            if time.monotonic() > deadline:
                missing = sorted(set(self.sensors) - set(ready))
                raise LiveCalibrationError(
                    f"the detector nodes {', '.join(missing)} did not come back on the simulated "
                    f"operator's scene within {float(self.params.operator_wait_s):g} s; check "
                    "the site's output (optrack run)."
                )
            time.sleep(0.2)

    def stop(self) -> None:
        """Stop capturing (the nodes stop looking for the board). What was collected is
        kept; views still in flight are used. The simulated operator stays in its scene
        until the next :meth:`start` or :meth:`close`."""
        with self._lock:
            capturing, self._capturing = self._capturing, []
        problems = []
        for sid in capturing:
            try:
                send_command(self.bus, sid, "calibration_stop", {}, self._timeout())
            except UserError as error:
                problems.append(str(error))
        deadline = time.monotonic() + 0.5
        while capturing and time.monotonic() < deadline and not self._inbox.empty():
            time.sleep(0.05)
        self._close_instants(final=True)
        with self._lock:
            if self.phase != "idle":
                self._message = problems[0] if problems else "Capture stopped."
            self.phase = "idle"

    # ----------------------------------------------------------------- state
    def state(self) -> LiveState:
        """A cheap snapshot (polled at ~5 Hz by the GUI)."""
        with self._lock:
            feedback = self.calibrator.feedback() if self.calibrator is not None else None
            solved = self.result
            sensors: dict[str, SensorLive] = {}
            now = time.monotonic()
            for sid in self.sensors:
                st = self._sensors[sid]
                if st.image is None and st.preview:
                    decoded = cv2.imdecode(np.frombuffer(st.preview, np.uint8), cv2.IMREAD_COLOR)
                    st.image = (
                        cv2.cvtColor(decoded, cv2.COLOR_BGR2RGB) if decoded is not None else None
                    )
                status = feedback.sensors.get(sid) if feedback is not None else None
                if solved is not None and sid in solved.world_T_camera:
                    pose: np.ndarray | None = solved.world_T_camera[sid]
                else:
                    pose = self._poses.get(sid)
                coverage = None
                if st.coverage is not None:
                    coverage = np.clip(
                        st.coverage.counts / float(self.params.coverage_corners), 0.0, 1.0
                    )
                recent = [t for t in st.arrivals if now - t < 5.0]
                views = (
                    len(st.intrinsics_corners)
                    if self.phase == "intrinsics"
                    else (status.views if status is not None else 0)
                )
                sensors[sid] = SensorLive(
                    sensor=sid,
                    views=views,
                    rms_px=status.rms_px if status is not None else None,
                    calibrated=bool(status.calibrated) if status is not None else False,
                    image=st.image,
                    board_seen=st.board_seen,
                    coverage=coverage,
                    world_T_camera=None if pose is None else pose.copy(),
                    intrinsics=self._intrinsics_override.get(sid) or st.intrinsics,
                    on_floor=st.on_floor,
                    frames=st.frames,
                    capture_hz=(len(recent) - 1) / (recent[-1] - recent[0])
                    if len(recent) > 1 and recent[-1] > recent[0]
                    else 0.0,
                    parent=status.parent if status is not None else None,
                )
            site = self._statuses.get("site")
            return LiveState(
                phase=self.phase,
                sensors=sensors,
                covisibility=sorted(
                    (a, b, n) for (a, b), n in (feedback.covisibility.items() if feedback else [])
                ),
                floor_views=feedback.floor_views if feedback is not None else 0,
                refinement_samples={
                    sid: sum(1 for m in batches if m.batch.detections)
                    for sid, batches in self._detections.items()
                },
                message=self._advice(feedback),
                elapsed_s=now - self._phase_started if self.phase != "idle" else 0.0,
                instants=self._instants,
                operator=str(site.values.get("operator", "")) if site is not None else "",
            )

    def _advice(self, feedback: Any) -> str:
        """One sentence: what to do now."""
        if self.phase == "extrinsics" and feedback is not None:
            calibrated = sorted(s for s, f in feedback.sensors.items() if f.calibrated)
            missing = sorted(s for s, f in feedback.sensors.items() if not f.calibrated)
            if not calibrated:
                return (
                    "Hold the board still where two cameras see it at once (no pair has shared "
                    "a view yet)."
                )
            if missing:
                return (
                    f"Show the board to {', '.join(missing)} together with a calibrated camera "
                    f"({', '.join(calibrated)})."
                )
            return "Every camera is calibrated; more views make it better, or go on to the floor."
        if self.phase == "floor" and feedback is not None:
            return (
                f"Lay the board flat on the floor where cameras see it; {feedback.floor_views} "
                "floor view(s) so far."
            )
        if self.phase == "refinement":
            with self._lock:
                counts = {
                    s: sum(1 for m in b if m.batch.detections) for s, b in self._detections.items()
                }
            seen = ", ".join(f"{s} {n}" for s, n in sorted(counts.items())) or "none yet"
            return f"One person walks alone through every camera's view (detections: {seen})."
        return self._message

    # ---------------------------------------------------------------- solving
    def calibrate_intrinsics(self, sensor: str, progress: Progress) -> IntrinsicsResult:
        """cv2.calibrateCamera over ``sensor``'s views collected in the intrinsics phase
        (optrack/calibration/intrinsics.py); the result's intrinsics are used for that
        sensor in the extrinsics that follow (start "extrinsics" again)."""
        with self._lock:
            st = self._sensors.get(sensor)
            if st is None:
                raise LiveCalibrationError(
                    f"sensor '{sensor}' is not one of the site's ({', '.join(self.sensors)})."
                )
            corners = list(st.intrinsics_corners)
            size = (st.intrinsics.width, st.intrinsics.height) if st.intrinsics else (0, 0)
        progress(0.1, f"calibrating {sensor} from {len(corners)} views")
        result = calibrate_intrinsics(corners, self.board, size)
        with self._lock:
            self._intrinsics_override[sensor] = result.intrinsics
        progress(1.0, f"{sensor}: RMS {result.rms:.3f} px over {len(result.used)} views")
        return result

    def solve(self, progress: Progress) -> NetworkCalibration:
        """Global bundle adjustment over all views and floor boards: world frame on the
        floor (the first camera's frame when no board lay on the floor; the message says
        so). UserError when no two sensors shared a view."""
        with self._solve_lock:
            self._close_instants(final=True)
            with self._lock:
                calibrator = self.calibrator
                if calibrator is None:
                    raise LiveCalibrationError(
                        "no board views yet; start the extrinsics page and move the board first."
                    )
            progress(0.05, f"bundle adjustment over {len(calibrator.instants)} instants")
            with self._lock:  # the worker feeds the same calibrator
                result = calibrator.solve()
            if not result.world_T_camera:
                raise CalibrationError(
                    "no sensor could be calibrated; move the board where cameras overlap."
                )
            calibration = self._network(result)
            with self._lock:
                self.result = result
                self.calibration = calibration
                self.refinement = None
                if result.world != "floor":
                    self._message = (
                        "No board lay on the floor, so the world is the camera "
                        f"{result.root}'s frame; do the floor page."
                    )
                elif result.uncalibrated:
                    self._message = f"Not calibrated: {', '.join(result.uncalibrated)}."
                else:
                    self._message = (
                        f"Calibrated {len(result.world_T_camera)} cameras, RMS "
                        f"{result.rms_px:.2f} px, {result.floor_views} floor view(s)."
                    )
            progress(1.0, self._message)
            return calibration

    def _network(self, result: NetworkResult) -> NetworkCalibration:
        sensors = {}
        with self._lock:
            for sid, pose in result.world_T_camera.items():
                st = self._sensors[sid]
                sensors[sid] = SensorCalibration(
                    world_T_camera=_matrix(pose),
                    intrinsics=self._intrinsics_override.get(sid) or st.intrinsics,
                    model=st.model,
                    reprojection_rms_px=result.sensors[sid].rms_px,
                )
        return NetworkCalibration(
            sensors=sensors,
            ground=(0.0, 0.0, 1.0, 0.0),
            created=now_iso(),
            notes=new_calibration_id(),
        )

    def refine(self, progress: Progress) -> RefinementReport:
        """Algorithm 1 (optrack/calibration/refinement.py) from the walker's per-sensor
        detections collected in the refinement phase (camera-frame centroids moved into the
        world by the solved calibration; the most confident one per frame), starting from
        the solved calibration. A sensor's correction is applied only while its checkerboard
        views still agree with it (``calibration_live.refinement_board_growth``; the report's
        ``refused`` lists the others, which keep the board's pose). The report's calibration
        becomes the one saved/published."""
        with self._lock:
            base = self.calibration
            batches = {s: list(b) for s, b in self._detections.items()}
        if base is None:
            raise LiveCalibrationError(
                "refinement starts from a calibration; solve the extrinsics and the floor first."
            )
        progress(0.05, "collecting the walker's trajectories")
        trajectories: dict[str, Trajectory] = {}
        for sid, messages in batches.items():
            if sid not in base.sensors:
                continue
            pose = base.pose(sid)
            times, points = [], []
            for m in messages:
                found = [d for d in m.batch.detections if d.camera_xyz is not None]
                if not found:
                    continue
                best = max(found, key=lambda d: d.confidence)
                times.append(m.batch.stamp)
                points.append(pose[:3, :3] @ np.asarray(best.camera_xyz) + pose[:3, 3])
            if times:
                trajectories[sid] = Trajectory(np.asarray(times), np.asarray(points))
        progress(0.2, f"Algorithm 1 over {len(trajectories)} sensors")
        p = REFINEMENT_PARAMS.create()
        result = refine_from_trajectories(trajectories, p)
        # The checkerboard's views are millimetre evidence, a walker's detections centimetre
        # evidence: a correction that its sensor's board views contradict is not applied.
        board_before = self._board_rms({s: base.pose(s) for s in result.corrections})
        board_after = self._board_rms({s: c @ base.pose(s) for s, c in result.corrections.items()})
        growth = 1.0 + float(self.params.refinement_board_growth)
        corrections, refused = {}, {}
        for sid, correction in result.corrections.items():
            if sid in board_after and board_after[sid] > board_before[sid] * growth:
                refused[sid] = board_after[sid]
            else:
                corrections[sid] = correction
        after = {
            s: tr.transformed(corrections[s]) if s in corrections else tr
            for s, tr in trajectories.items()
        }
        error_after = (
            alignment_error(
                {s: tr for s, tr in after.items() if s in result.corrections}, float(p.max_gap)
            )
            if refused
            else result.error_after_m
        )
        refined = base
        for sid, correction in corrections.items():
            refined = refined.with_pose(sid, correction @ base.pose(sid))
        refined = msgspec.structs.replace(refined, notes=new_calibration_id(), created=now_iso())
        report = RefinementReport(
            calibration=refined,
            error_before_m=result.error_before_m,
            error_after_m=error_after,
            trajectories_before={s: tr.xyz.copy() for s, tr in trajectories.items()},
            trajectories_after={s: tr.xyz.copy() for s, tr in after.items()},
            corrections={s: c.copy() for s, c in corrections.items()},
            skipped=list(result.skipped),
            refused=refused,
            board_rms_px=board_before,
            board_rms_refined_px=board_after,
        )
        with self._lock:
            self.refinement = report
            self.calibration = refined
            self._message = (
                f"Refined: sensors agree within {error_after * 100:.1f} cm "
                f"(before: {result.error_before_m * 100:.1f} cm)."
            )
            if refused:
                self._message += (
                    f" {', '.join(sorted(refused))} kept the checkerboard's pose: the walk "
                    "moved it where its board views disagree."
                )
        progress(1.0, self._message)
        return report

    def _board_rms(self, poses: dict[str, np.ndarray]) -> dict[str, float]:
        """(added) Per sensor, the reprojection RMS (px, pinhole corners) of its checkerboard
        views in the last solve with the camera at ``poses[sensor]`` and every board where
        the solve put it: how far a pose is from what the board showed that sensor."""
        with self._lock:
            calibrator, result = self.calibrator, self.result
        if calibrator is None or result is None:
            return {}
        objects = self.board.object_points
        errors: dict[str, list[np.ndarray]] = {}
        for instant in calibrator.instants:
            world_T_board = result.world_T_board.get(instant.index)
            if world_T_board is None:
                continue
            for sid in instant.added & set(poses):
                camera_T_board = invert(poses[sid]) @ world_T_board
                residual = pinhole_residuals_px(
                    objects, camera_T_board, calibrator.intrinsics[sid], instant.views[sid].pinhole
                )
                errors.setdefault(sid, []).append(residual)
        return {s: float(np.sqrt(np.mean(np.concatenate(e) ** 2))) for s, e in errors.items()}

    # ----------------------------------------------------------------- output
    def calibration_file(self) -> CalibrationFile:
        """(added) The current calibration (refined if refine() ran, else solved) as the
        calibration file it is saved as."""
        with self._lock:
            calibration, result, refinement = self.calibration, self.result, self.refinement
            if calibration is None or result is None:
                raise LiveCalibrationError("nothing to save yet; solve the calibration first.")
            sensors = {}
            for sid, entry in calibration.sensors.items():
                st = self._sensors[sid]
                correction = refinement.corrections.get(sid) if refinement is not None else None
                sensors[sid] = SensorEntry(
                    world_T_camera=entry.world_T_camera,
                    intrinsics=entry.intrinsics,
                    model=entry.model,
                    image=st.image_kind,
                    refinement=_matrix(correction) if correction is not None else None,
                    views=result.sensors[sid].used_views,
                    reprojection_rms_px=entry.reprojection_rms_px,
                )
            quality: dict[str, float | int | str | None] = {
                "reprojection_rms_px": result.rms_px,
                "instants": self._instants,
                "floor_views": result.floor_views,
                "ground": "floor" if result.world == "floor" else "none",
            }
            if refinement is not None:
                quality["refinement_error_before_m"] = refinement.error_before_m
                quality["refinement_error_after_m"] = refinement.error_after_m
                if refinement.refused:  # (added) sensors that kept the checkerboard's pose
                    quality["refinement_refused"] = ",".join(sorted(refinement.refused))
        return CalibrationFile(
            sensors=sensors,
            id=calibration.notes or new_calibration_id(),
            created=calibration.created or now_iso(),
            board=BoardEntry(
                self.board.cols,
                self.board.rows,
                self.board.square,
                float(self.network_params.board_thickness),
            ),
            world=result.world,
            ground=calibration.ground,
            quality=quality,
            notes=f"live calibration of site '{self.bus.keys.site}'",
        )

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the current calibration (refined if refine() ran, else solved) with
        optrack/calibration/files.py: atomic, the previous file kept as ``<name>.bak``."""
        save_calibration(path, self.calibration_file())
        return Path(path)

    def publish(self) -> None:
        """Send the current calibration to every node (CalibrationMessage on the
        calibration key, reliably); each stores it atomically and uses it from its next
        frame; the tracker keeps it for nodes that start later."""
        calibration = self.calibration_file().to_network()
        self.bus.publish(
            self.bus.keys.calibration, CalibrationMessage(calibration=calibration), realtime=False
        )
        with self._lock:
            self._message = (
                f"Calibration {calibration.notes} sent to the nodes of site '{self.bus.keys.site}'."
            )

    def close(self) -> None:
        """Stop any capture, send the simulated operator back to the venue (if it acted)
        and unsubscribe; the bus stays open (the caller's)."""
        if self._closed:
            return
        try:
            self.stop()
            if self.simulated and self._operator_acted and not self.bus.closed:
                send_command(self.bus, "site", "operator", {"action": "people"}, self._timeout())
        except UserError as error:
            log.warning("closing the live calibration: %s", error)
        finally:
            self._closed = True
            self._worker.join(timeout=2.0)
            for subscription in self._subscriptions:
                try:
                    subscription.undeclare()
                except Exception as error:  # the bus closed under us
                    log.debug("subscription not undeclared: %s", error)
            self._subscriptions = []


def _matrix(pose: np.ndarray) -> Any:
    return tuple(tuple(float(v) for v in row) for row in np.asarray(pose, dtype=np.float64))


def world_T_camera_errors(
    estimated: dict[str, np.ndarray], truth: dict[str, np.ndarray]
) -> dict[str, tuple[float, float]]:
    """(added) Per sensor (position error m, rotation error deg) after the best rigid
    alignment (optrack.calibration.quality); for simulated sites and tests."""
    from optrack.calibration.quality import calibration_errors

    errors = calibration_errors(estimated, truth)
    return {s: (errors.position_m[s], errors.rotation_deg[s]) for s in errors.position_m}


# ------------------------------------------------------------------------- CLI


def _progress(message: str) -> None:
    import sys

    print(message, file=sys.stderr, flush=True)


def _describe(state: LiveState) -> str:
    sensors = ", ".join(
        f"{s} {v.views} views{' calibrated' if v.calibrated else ''} ({v.capture_hz:.1f} Hz)"
        for s, v in sorted(state.sensors.items())
    )
    extra = f", {state.floor_views} floor views" if state.phase == "floor" else ""
    if state.phase == "refinement":
        extra = ", detections " + ", ".join(
            f"{s} {n}" for s, n in sorted(state.refinement_samples.items())
        )
    return f"{state.phase} {state.elapsed_s:5.1f} s: {sensors}{extra}. {state.message}"


def _run_phase(
    live: LiveCalibration, phase: str, seconds: float, done: Callable[[LiveState], bool]
) -> float:
    """Capture ``phase`` until ``done`` or ``seconds``; returns the seconds it took."""
    started = time.monotonic()
    live.start(phase)
    _progress(f"{phase}: started in {time.monotonic() - started:.1f} s. {live.state().message}")
    next_report = 0.0
    while True:
        state = live.state()
        now = time.monotonic()
        if now >= next_report:
            _progress(_describe(state))
            next_report = now + 2.0
        if done(state) or now - started >= seconds:
            break
        time.sleep(0.2)
    live.stop()
    return time.monotonic() - started


def cmd_live(args: Any) -> int:
    """``optrack calibrate live``: the calibration wizard without a window, against a
    running site: extrinsics, floor, (refinement), then save and publish."""
    import json
    import sys

    from optrack.runtime.config import load_node_config

    config = load_node_config(args.config)
    site = args.site or str(config["site"].name)
    board = Checkerboard.parse(args.board, args.square)
    board.require_asymmetric()
    timings: dict[str, float] = {}
    bus = Bus(site, "calibrate", config["bus"])
    live: LiveCalibration | None = None
    try:
        started = time.monotonic()
        live = LiveCalibration(bus, board, params=config.params.get("calibration_live"))
        timings["connect_s"] = time.monotonic() - started
        _progress(
            f"site '{site}': sensors {', '.join(live.sensors)}"
            + (" (simulated: its operator moves the board)" if live.simulated else "")
        )
        if not live.simulated:
            _progress(
                "Move the board through the space, holding it still for a second wherever two "
                "cameras see it; then lay it on the floor when asked."
            )
        min_views = int(args.min_views)

        def extrinsics_done(state: LiveState) -> bool:
            return all(v.calibrated and v.views >= min_views for v in state.sensors.values())

        timings["extrinsics_s"] = _run_phase(
            live, "extrinsics", float(args.extrinsics_seconds), extrinsics_done
        )
        if not live.simulated:
            _progress("Now lay the board flat on the floor where cameras see it.")
        timings["floor_s"] = _run_phase(
            live,
            "floor",
            float(args.floor_seconds),
            lambda state: state.floor_views >= int(args.floor_views),
        )
        started = time.monotonic()
        calibration = live.solve(lambda f, m: _progress(m))
        timings["solve_s"] = time.monotonic() - started
        report = None
        if args.refine_seconds > 0:
            if not live.simulated:
                _progress("Now one person walks alone through every camera's view.")
            timings["refinement_s"] = _run_phase(
                live, "refinement", float(args.refine_seconds), lambda state: False
            )
            started = time.monotonic()
            report = live.refine(lambda f, m: _progress(m))
            timings["refine_s"] = time.monotonic() - started
            calibration = report.calibration
        path = live.save(args.out)
        if not args.no_publish:
            live.publish()
        result = live.result
        assert result is not None
        payload: dict[str, Any] = {
            "out": str(path),
            "id": calibration.notes,
            "site": site,
            "simulated": live.simulated,
            "world": result.world,
            "rms_px": result.rms_px,
            "floor_views": result.floor_views,
            "uncalibrated": result.uncalibrated,
            "published": not args.no_publish,
            "sensors": {
                sid: {
                    "views": result.sensors[sid].used_views,
                    "rms_px": result.sensors[sid].rms_px,
                    "world_T_camera": np.asarray(entry.world_T_camera).round(6).tolist(),
                }
                for sid, entry in sorted(calibration.sensors.items())
            },
            "seconds": {k: round(v, 2) for k, v in timings.items()},
        }
        if report is not None:
            payload["refinement"] = {
                "error_before_m": report.error_before_m,
                "error_after_m": report.error_after_m,
                "skipped": report.skipped,
                "refused": report.refused,
            }
        if args.json:
            sys.stdout.write(json.dumps(payload) + "\n")
            sys.stdout.flush()
        else:
            _progress(
                f"wrote {path}: {len(calibration.sensors)} sensors, RMS {result.rms_px:.3f} px, "
                f"world: {result.world}"
                + ("" if args.no_publish else f"; sent to the nodes of site '{site}'")
            )
    finally:
        if live is not None:
            live.close()
        bus.close()
    return 0
