"""Live network calibration over the bus: the calibration wizard's backend.

The wizard (``app/wizard``) and ``optrack calibrate live`` drive a running
site through :class:`LiveCalibration`; it is Qt-free and safe to call from any
thread. The maths (still boards, the network calibrator, solving, refining,
the calibration file) is :class:`optrack.calibration.live_session.LiveSession`;
this module only talks to the site::

    LiveCalibration.start("extrinsics")
        -> the site's operator, if it has one (a simulated site; BoardOperator), sets the scene
        -> command "calibration_start" {phase, board} to every detector node
           (optrack/runtime/board_capture.py): each node looks for the board in its depth
           camera's own image a few times per second and publishes a BoardViewMessage on
           board_views/<sensor>
    board views, walker detections --> worker thread --> LiveSession
    state() / solve() / refine() / save() / publish()
"""

from __future__ import annotations

import dataclasses
import logging
import os
import queue
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import msgspec

from optrack.calibration.board import Checkerboard
from optrack.calibration.files import CalibrationFile, save_calibration
from optrack.calibration.intrinsics import IntrinsicsResult
from optrack.calibration.live import (
    LIVE_PARAMS,
    LiveCalibrationError,
    LiveState,
    Progress,
    RefinementReport,
)
from optrack.calibration.live_evidence import board_centres, shared_board_poses
from optrack.calibration.live_session import LiveSession
from optrack.calibration.network import NETWORK_PARAMS, NetworkResult
from optrack.errors import UserError
from optrack.net.bus import Bus
from optrack.net.messages import (
    BoardViewMessage,
    CalibrationMessage,
    DetectionsMessage,
    PreviewMessage,
    StatusMessage,
)
from optrack.params import Params
from optrack.runtime.calibration_guidance import BoardGuide
from optrack.runtime.calibration_operator import BoardOperator, SiteOperator
from optrack.runtime.node import send_command
from optrack.types import Intrinsics, NetworkCalibration

__all__ = ["FIND_OPERATOR", "LiveCalibration"]

log = logging.getLogger("optrack.runtime.calibration_live")

#: ``operator=`` default: the site's simulated operator when its site node has one.
FIND_OPERATOR = "site"


class LiveCalibration:
    """The wizard's calibration session against a running site (embedded or remote).

    ``bus``: an open :class:`~optrack.net.bus.Bus` of the site (the caller's; it stays
    open). ``sensors``: the detector nodes to use (default: every detector node whose
    status arrives within ``calibration_live.discover_s``). A UserError sentence when
    none is found. ``operator``: who moves the board (:class:`BoardOperator`; None: the
    site's people, as on a real site; default: the simulated operator of the site's
    ``site`` node when it answers, ``optrack run`` with simulated sensors).

    Threads: bus callbacks only queue what arrives; one worker thread hands the views
    and detections to the session; every public method may be called from any thread.
    ``start``/``stop``/``solve``/``refine`` can take seconds (commands, the operator's
    scene, optimisation): call them off the GUI thread.
    """

    sensors: list[str]  # the site's sensors (from their detector nodes' status)
    operator: BoardOperator | None  # the site's operator (a simulated site) or None

    def __init__(
        self,
        bus: Bus,
        board: Checkerboard,
        *,
        sensors: Sequence[str] | None = None,
        params: Params | None = None,
        network_params: Params | None = None,
        operator: BoardOperator | None | str = FIND_OPERATOR,
    ) -> None:
        self.bus = bus
        self.board = board
        self.params = params if params is not None else LIVE_PARAMS.create()
        network_params = network_params if network_params is not None else NETWORK_PARAMS.create()
        self._inbox: queue.SimpleQueue[tuple[str, Any]] = queue.SimpleQueue()
        self._lock = threading.Lock()
        self._statuses: dict[str, StatusMessage] = {}
        self._capturing: list[str] = []
        self._closed = False
        self._next_check = 0.0  # when _keep_going looks at the operator next
        self._subscriptions = [bus.subscribe(bus.keys.status(), StatusMessage, self._on_status)]
        self.sensors = list(sensors) if sensors else self._discover()
        if not self.sensors:
            self._unsubscribe()
            raise LiveCalibrationError(
                f"no detector node of site '{bus.keys.site}' answered within "
                f"{float(self.params.discover_s):g} s; start the site (optrack run) or check "
                "the site name and the bus settings."
            )
        self.session = LiveSession(board, self.sensors, self.params, network_params)
        if isinstance(operator, str):  # FIND_OPERATOR
            operator = SiteOperator.find(
                bus, self.sensors, self.status_of, self._timeout(), self._operator_wait()
            )
        self.operator = operator
        self._subscriptions.append(
            bus.subscribe(bus.keys.board_views(), BoardViewMessage, self._on_view)
        )
        self._subscriptions.append(
            bus.subscribe(bus.keys.detections(), DetectionsMessage, self._on_detections)
        )
        # Where to hold the board next, from the cameras' rough poses (their previews).
        self.guide = BoardGuide(board)
        self._subscriptions.append(
            bus.subscribe(bus.keys.preview(), PreviewMessage, self.guide.on_preview)
        )
        self._worker = threading.Thread(target=self._loop, name="live-calibration", daemon=True)
        self._worker.start()

    # ------------------------------------------------------------ the results
    @property
    def simulated(self) -> bool:
        """The site has an operator that moves the board itself (a simulated site)."""
        return self.operator is not None

    @property
    def phase(self) -> str:
        return self.session.phase

    @property
    def result(self) -> NetworkResult | None:
        return self.session.result

    @property
    def solved(self) -> NetworkCalibration | None:
        return self.session.solved

    @property
    def refinement(self) -> RefinementReport | None:
        return self.session.refinement

    @property
    def calibration(self) -> NetworkCalibration | None:
        return self.session.calibration

    # ------------------------------------------------------------- discovery
    def _on_status(self, message: StatusMessage, key: str) -> None:
        with self._lock:
            self._statuses[message.node] = message

    def status_of(self, node: str) -> StatusMessage | None:
        """The newest status of ``node`` (None before any arrived)."""
        with self._lock:
            return self._statuses.get(node)

    def _discover(self) -> list[str]:
        deadline = time.monotonic() + float(self.params.discover_s)
        while time.monotonic() < deadline:
            time.sleep(0.1)
        with self._lock:
            return sorted(n for n, s in self._statuses.items() if s.role == "detector")

    def _timeout(self) -> float:
        return float(self.params.command_timeout_s)

    def _operator_wait(self) -> float:
        return float(self.params.operator_wait_s)

    # ------------------------------------------------------------- receiving
    def _on_view(self, message: BoardViewMessage, key: str) -> None:
        if self.bus.keys.last_chunk(key) != message.sensor:
            raise LiveCalibrationError(
                f"a board view of '{message.sensor}' arrived on another sensor's key {key}."
            )
        self._inbox.put(("view", message))

    def _on_detections(self, message: DetectionsMessage, key: str) -> None:
        if self.session.phase == "refinement":
            self._inbox.put(("detections", message))

    def _loop(self) -> None:
        while not self._closed:
            try:
                self._keep_going()
            except UserError as error:
                self.session.say(str(error))
            try:
                kind, message = self._inbox.get(timeout=0.2)
            except queue.Empty:
                self.session.flush()
                continue
            try:
                if kind == "view":
                    self.session.take_view(message)
                elif kind == "detections":
                    self.session.take_detections(message)
                self.session.flush()
            except UserError as error:
                self.session.say(str(error))
            except Exception as error:  # the session must outlive one bad view
                log.exception("live calibration: a view could not be used")
                self.session.say(
                    f"a board view could not be used ({type(error).__name__}: {error})."
                )

    def _keep_going(self) -> None:
        """While the extrinsics still ask a sensor for shared board poses, or the
        intrinsics page's lens is not good yet (calibration_intrinsics.good_std_px), and
        the site's operator has made every placement it was asked, it goes round again,
        holding the board long enough for ``calibration_live.operator_searches`` searches
        of the slowest node (a loaded computer's nodes search an image every few seconds:
        a hold may have given one of them no still pair)."""
        operator, now = self.operator, time.monotonic()
        phase = self.session.phase
        if operator is None or phase not in ("intrinsics", "extrinsics"):
            return
        if now < self._next_check:
            return
        self._next_check = now + 1.0
        if not operator.finished():
            return
        state = self._with_evidence(self.session.state())
        sensor = self.session.intrinsics_sensor if phase == "intrinsics" else None
        if state.phase != phase:
            return
        if phase == "extrinsics" and all(v.settled for v in state.sensors.values()):
            return
        if sensor is not None and (lens := state.sensors[sensor].lens) is not None and lens.good:
            return
        hold = self._searches_hold(state)
        sentence = operator.act(phase, self.board, sensor, hold)
        self.session.say(sentence)
        log.info("the simulated operator goes round again (%s, hold %.1f s)", phase, hold)

    def _searches_hold(self, state: LiveState) -> float:
        """How long the operator holds the board for ``calibration_live.operator_searches``
        searches of the slowest node capturing now (0: no node captures)."""
        rates = [v.capture_hz for v in state.sensors.values() if v.capture_hz > 0]
        hold = float(self.params.operator_searches) / min(rates) if rates else 0.0
        return min(hold, 60.0)

    # ---------------------------------------------------------------- phases
    def start(self, phase: str, sensor: str | None = None) -> None:
        """Ask the nodes to capture for ``phase`` (intrinsics: one ``sensor``). When the
        site has an operator it acts first (moves the board; lays it on the floor at its
        places; one person walks) and this waits until the detector nodes see it (up to
        ``calibration_live.operator_wait_s``). Extrinsics and floor share one network
        calibrator (the floor phase adds floor views to it); starting extrinsics again
        starts over. Refinement collects the nodes' detections until :meth:`stop` or
        :meth:`refine`. A UserError sentence on failure (unknown phase or sensor, a node
        that refuses or does not answer)."""
        self.session.check_phase(phase, sensor)
        # The floor's places need one sensor's still view each: the board lies there long
        # enough for the searches of the slowest node as it captured until now (two
        # searches made 19-27 floor views on the default and four-sensor sites at load 20,
        # and a camera 8.5 mm off in height; three, 34-84).
        hold = self._searches_hold(self.session.state()) if phase == "floor" else 0.0
        self.stop()
        if self.operator is not None:
            self.session.say(self.operator.act(phase, self.board, sensor, hold))
            self.operator.wait()
        self.session.begin(phase, sensor)
        if phase == "refinement":
            return
        targets = [str(sensor)] if phase == "intrinsics" else list(self.sensors)
        args = {
            "phase": phase,
            "cols": self.board.cols,
            "rows": self.board.rows,
            "square": self.board.square,
            "thickness": float(self.session.network_params.board_thickness),
        }
        for sid in targets:
            reply = send_command(self.bus, sid, "calibration_start", args, self._timeout())
            with self._lock:
                self._capturing.append(sid)
            self.session.node_ready(
                sid,
                msgspec.convert(reply["intrinsics"], Intrinsics),
                str(reply.get("model", "")),
                str(reply.get("image", "")),
            )
        self.session.capturing()

    def stop(self) -> None:
        """Stop capturing (the nodes stop looking for the board). What was collected is
        kept; views still in flight are used. The operator stays in its scene until the
        next :meth:`start` or :meth:`close`."""
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
        self.session.end(problems[0] if problems else "")

    # ------------------------------------------------------- state and solving
    def state(self) -> LiveState:
        """A cheap snapshot (polled at ~5 Hz by the GUI): in the extrinsics, each sensor's
        shared board poses (:attr:`SensorLive.settled` once it has
        ``calibration_live.min_shared_poses``) and where to hold the board next."""
        state = self.session.state(self.operator.doing() if self.operator is not None else "")
        return self.guide.advise(self._with_evidence(state))

    def _with_evidence(self, state: LiveState) -> LiveState:
        """``state`` with each sensor's distinct board poses shared with calibrated ones."""
        if state.phase != "extrinsics":
            return state
        p = self.params
        with self.session.lock:
            calibrator = self.session.calibrator
            if calibrator is None:
                return state
            shared = shared_board_poses(
                calibrator, float(p.shared_pose_spacing), float(p.shared_pose_turn_deg)
            )
            centre = calibrator.board.center
        sensors = {}
        for sid, live in state.sensors.items():
            poses = shared.get(sid, [])
            centres = None
            if live.world_T_camera is not None:
                centres = board_centres(live.world_T_camera, poses, centre)
            sensors[sid] = dataclasses.replace(
                live,
                shared_poses=len(poses),
                shared_needed=int(p.min_shared_poses),
                shared_centers=centres,
            )
        return dataclasses.replace(state, sensors=sensors)

    def calibrate_intrinsics(self, sensor: str, progress: Progress) -> IntrinsicsResult:
        """One sensor's lens from its views of the intrinsics phase (LiveSession)."""
        return self.session.calibrate_intrinsics(sensor, progress)

    def solve(self, progress: Progress) -> NetworkCalibration:
        """Global bundle adjustment over all views and floor boards (LiveSession)."""
        return self.session.solve(progress)

    def refine(self, progress: Progress) -> RefinementReport:
        """Algorithm 1 from the walker's detections (LiveSession)."""
        return self.session.refine(progress)

    # ----------------------------------------------------------------- output
    def calibration_file(self) -> CalibrationFile:
        """The current calibration (refined if refine() ran, else solved) as the
        calibration file it is saved as."""
        return self.session.calibration_file(self.bus.keys.site)

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
        self.session.say(
            f"Calibration {calibration.notes} sent to the nodes of site '{self.bus.keys.site}'."
        )

    def close(self) -> None:
        """Stop any capture, send the operator back (if it acted) and unsubscribe; the bus
        stays open (the caller's)."""
        if self._closed:
            return
        try:
            self.stop()
            if self.operator is not None:
                self.operator.release()
        except UserError as error:
            log.warning("closing the live calibration: %s", error)
        finally:
            self._closed = True
            self._worker.join(timeout=2.0)
            self._unsubscribe()

    def _unsubscribe(self) -> None:
        for subscription in self._subscriptions:
            try:
                subscription.undeclare()
            except Exception as error:  # the bus closed under us
                log.debug("subscription not undeclared: %s", error)
        self._subscriptions = []
