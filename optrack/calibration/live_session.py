"""The live calibration's maths: :class:`LiveSession` turns the detector nodes' board
views (``BoardViewMessage``) and the walker's detections (``DetectionsMessage``)
into a calibration; it knows nothing of the bus (the bus side is
:class:`optrack.runtime.calibration_live.LiveCalibration`, which owns one)::

    board views -> still boards (optrack.calibration.still: the still-board rule the
        offline session shares) -> NetworkCalibrator.add (iSAM2 live feedback)
    state()    -> LiveState snapshot for the GUI (~5 Hz)
    calibrate_intrinsics() -> one sensor's lens from its views of the intrinsics page
    solve()    -> global bundle adjustment with the floor boards (world frame on the floor)
    refine()   -> Algorithm 1 from the walker's detections (optrack.calibration.live_refine)
    calibration_file() -> the calibration as it is saved, with its CalibrationQuality

Every method may be called from any thread (one lock guards the state).
"""

from __future__ import annotations

import dataclasses
import threading
import time
from collections.abc import Sequence

import cv2
import numpy as np

from optrack.calibration.board import Checkerboard
from optrack.calibration.files import (
    BoardEntry,
    CalibrationFile,
    SensorEntry,
    new_calibration_id,
    now_iso,
)
from optrack.calibration.intrinsics import IntrinsicsResult, calibrate_intrinsics
from optrack.calibration.live import (
    INSTRUCTIONS,
    LIVE_PARAMS,
    PHASES,
    LiveCalibrationError,
    LiveState,
    Progress,
    SensorLive,
)
from optrack.calibration.live_lens import LensViews
from optrack.calibration.live_refine import (
    RefinementReport,
    board_rms_px,
    refine_walk,
    walk_trajectories,
)
from optrack.calibration.network import (
    FLOOR_KEY,
    NETWORK_PARAMS,
    CalibrationError,
    Feedback,
    NetworkCalibrator,
    NetworkResult,
)
from optrack.calibration.quality import CalibrationQuality
from optrack.calibration.session import SESSION_PARAMS
from optrack.calibration.still import StillBoard, StillBoards
from optrack.net.messages import BoardViewMessage, DetectionsMessage
from optrack.params import Params
from optrack.types import Intrinsics, NetworkCalibration, SensorCalibration, as_matrix4

__all__ = ["LEVEL_T_OPTICAL", "LiveSession"]

# A camera's optical frame (x right, y down, z ahead) seen as a level frame (x right,
# y ahead, z up): the display frame of the live poses until the floor is known.
LEVEL_T_OPTICAL = np.array(
    [[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
)

#: What the operator is told at the start of each capturing phase.


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
    lens: LensViews = dataclasses.field(default_factory=LensViews)  # intrinsics page

    def decoded(self) -> np.ndarray | None:
        """The latest preview as an RGB image (decoded once)."""
        if self.image is None and self.preview:
            bgr = cv2.imdecode(np.frombuffer(self.preview, np.uint8), cv2.IMREAD_COLOR)
            self.image = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB) if bgr is not None else None
        return self.image

    def capture_hz(self, now: float) -> float:
        recent = [t for t in self.arrivals if now - t < 5.0]
        if len(recent) > 1 and recent[-1] > recent[0]:
            return (len(recent) - 1) / (recent[-1] - recent[0])
        return 0.0


class LiveSession:
    """One live calibration of ``sensors`` with ``board`` (see the module docstring).

    ``params``: ``calibration_live`` values; ``network_params``: ``calibration_network``
    values (board thickness, ...).
    """

    def __init__(
        self,
        board: Checkerboard,
        sensors: Sequence[str],
        params: Params | None = None,
        network_params: Params | None = None,
    ) -> None:
        self.board = board
        self.sensors = list(sensors)
        self.params = params if params is not None else LIVE_PARAMS.create()
        self.network_params = (
            network_params if network_params is not None else NETWORK_PARAMS.create()
        )
        self.session_params = SESSION_PARAMS.create()
        self.lock = threading.RLock()
        self._solve_lock = threading.Lock()
        self._sensors = {sid: _Sensor() for sid in self.sensors}
        self.phase = "idle"
        self._phase_started = time.monotonic()
        self._message = (
            "Not capturing yet: the board and floor pages start when opened, the "
            "intrinsics page on Start capture."
        )
        self.intrinsics_sensor: str | None = None
        self.intrinsics_results: dict[str, IntrinsicsResult] = {}
        self.still = StillBoards(
            self.sensors,
            float(self.session_params.max_motion_px),
            float(self.params.max_still_gap_s),
        )
        self.calibrator: NetworkCalibrator | None = None
        self._poses: dict[str, np.ndarray] = {}
        self._instants = 0
        self._detections: dict[str, list[DetectionsMessage]] = {}
        self.result: NetworkResult | None = None
        self.solved: NetworkCalibration | None = None
        self.refinement: RefinementReport | None = None

    @property
    def calibration(self) -> NetworkCalibration | None:
        """The calibration that is saved and sent: the refined one, else the solved one."""
        refinement = self.refinement
        return refinement.calibration if refinement is not None else self.solved

    def say(self, sentence: str) -> None:
        """The sentence the state's message shows when no phase has advice of its own."""
        with self.lock:
            self._message = sentence

    def intrinsics_of(self, sensor: str) -> Intrinsics | None:
        """The intrinsics used for ``sensor``: calibrated on the intrinsics page, else its own."""
        result = self.intrinsics_results.get(sensor)
        return result.intrinsics if result is not None else self._sensors[sensor].intrinsics

    # ---------------------------------------------------------------- phases
    def check_phase(self, phase: str, sensor: str | None = None) -> None:
        """A LiveCalibrationError sentence unless ``phase`` (for ``sensor``) can start."""
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

    def begin(self, phase: str, sensor: str | None = None) -> None:
        """A new capture for ``phase``: this phase's views start from none."""
        with self.lock:
            self.phase = phase
            self._phase_started = time.monotonic()
            self.still.clear()
            for state in self._sensors.values():
                state.frames, state.arrivals, state.board_seen = 0, [], False
            if phase == "intrinsics":
                self.intrinsics_sensor = sensor
                self._sensors[str(sensor)].lens = LensViews()
            if phase == "refinement":
                self._detections = {}
                self._message = INSTRUCTIONS[phase]

    def node_ready(self, sensor: str, intrinsics: Intrinsics, model: str, image: str) -> None:
        """A node captures for this phase in ``image`` (``color`` or ``infrared``), whose
        ``intrinsics`` its board views are in."""
        with self.lock:
            state = self._sensors[sensor]
            state.intrinsics, state.model, state.image_kind = intrinsics, model, image

    def capturing(self) -> None:
        """Every node captures: extrinsics start a new network calibrator (the floor phase
        adds its floor views to the extrinsics' one)."""
        with self.lock:
            if self.phase == "extrinsics" or (self.phase == "floor" and self.calibrator is None):
                self._new_calibrator()
            self._message = INSTRUCTIONS[self.phase]

    def end(self, problem: str = "") -> None:
        """The capture stopped (``problem``: why a node did not stop): what was collected is
        kept and still boards waiting for a partner are fed."""
        self.flush(final=True)
        with self.lock:
            if self.phase != "idle":
                self._message = problem or "Capture stopped."
            self.phase = "idle"

    def _new_calibrator(self) -> None:
        intrinsics = {}
        for sid in self.sensors:
            k = self.intrinsics_of(sid)
            if k is not None:
                intrinsics[sid] = k
        self.calibrator = NetworkCalibrator(self.board, intrinsics, self.network_params)
        self.result = None
        self._poses = {}
        self._instants = 0

    # ------------------------------------------------------------- receiving
    def take_view(self, view: BoardViewMessage) -> None:
        """One board view of a node (found or not), of this phase."""
        with self.lock:
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
            corners = None if view.corners is None else np.asarray(view.corners, np.float64)
            if self.phase != "intrinsics":
                self.still.add(view.sensor, view.stamp, corners, view.on_floor)
                return
            if corners is None or view.sensor != self.intrinsics_sensor:
                return
            lens, size = sensor.lens, (view.intrinsics.width, view.intrinsics.height)
            if not lens.take(corners, view.intrinsics, float(self.params.intrinsics_min_motion_px)):
                return
        lens.check(self.board, size, self.lock)  # good yet? where is the board missing?

    def take_detections(self, message: DetectionsMessage) -> None:
        """One detections batch of a node (kept during the refinement phase)."""
        sid = message.batch.sensor_id
        with self.lock:
            if self.phase != "refinement" or sid not in self._sensors:
                return
            batches = self._detections.setdefault(sid, [])
            batches.append(message)
            oldest = message.batch.stamp - float(self.params.max_refinement_s)
            while batches and batches[0].batch.stamp < oldest:
                batches.pop(0)

    def flush(self, final: bool = False) -> None:
        """Feed the calibrator every still board no sensor can join any more (all of them
        when ``final``)."""
        with self.lock:
            if self.calibrator is None:
                return
            for still in self.still.ready(final):
                self._feed(still)

    def _feed(self, still: StillBoard) -> None:
        """One still board, as the offline session feeds one: the floor vote (the nodes'
        depth tests, majority), then NetworkCalibrator.add (iSAM2)."""
        assert self.calibrator is not None
        found = {s: c for s, c in still.corners.items() if s in self.calibrator.intrinsics}
        if not found:
            return
        self.calibrator.add(found, floor=still.on_floor(found))
        self._instants += 1
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

    # ----------------------------------------------------------------- state
    def state(self, operator: str = "") -> LiveState:
        """A cheap snapshot (polled at ~5 Hz by the GUI); ``operator``: what the site's
        operator does, when it has one."""
        with self.lock:
            feedback = self.calibrator.feedback() if self.calibrator is not None else None
            now = time.monotonic()
            return LiveState(
                phase=self.phase,
                sensors={sid: self._sensor_live(sid, feedback, now) for sid in self.sensors},
                covisibility=sorted(
                    (a, b, n) for (a, b), n in (feedback.covisibility.items() if feedback else [])
                ),
                floor_views=feedback.floor_views if feedback is not None else 0,
                refinement_samples=self._samples(),
                walk=self._walk(),
                message=self._advice(feedback),
                elapsed_s=now - self._phase_started if self.phase != "idle" else 0.0,
                instants=self._instants,
                operator=operator,
                solved=self.solved,
                refinement=self.refinement,
                calibration=self.calibration,
                intrinsics_results=dict(self.intrinsics_results),
            )

    def _sensor_live(self, sid: str, feedback: Feedback | None, now: float) -> SensorLive:
        st = self._sensors[sid]
        status = feedback.sensors.get(sid) if feedback is not None else None
        if self.result is not None and sid in self.result.world_T_camera:
            pose: np.ndarray | None = self.result.world_T_camera[sid]
        else:
            pose = self._poses.get(sid)
        coverage = None
        if st.lens.coverage is not None:
            counts = st.lens.coverage.counts
            coverage = np.clip(counts / float(self.params.coverage_corners), 0.0, 1.0)
        if self.phase == "intrinsics":
            views = len(st.lens.corners)
        else:
            views = status.views if status is not None else 0
        return SensorLive(
            sensor=sid,
            views=views,
            rms_px=status.rms_px if status is not None else None,
            calibrated=bool(status.calibrated) if status is not None else False,
            image=st.decoded(),
            board_seen=st.board_seen,
            coverage=coverage,
            world_T_camera=None if pose is None else pose.copy(),
            intrinsics=self.intrinsics_of(sid),
            on_floor=st.on_floor,
            frames=st.frames,
            capture_hz=st.capture_hz(now),
            parent=status.parent if status is not None else None,
            lens=st.lens.lens if self.phase == "intrinsics" else None,
        )

    def _walk(self) -> dict[str, np.ndarray]:
        """The walker's positions so far per sensor, in the solved world (refinement)."""
        if self.phase != "refinement" or self.solved is None:
            return {}
        trajectories = walk_trajectories(self.solved, self._detections)
        return {sid: trajectory.xyz for sid, trajectory in trajectories.items()}

    def _samples(self) -> dict[str, int]:
        """Detections of the walker collected per sensor (frames with someone in them that
        the refinement uses: refinement.usable_detections)."""
        from optrack.calibration.refinement import usable_detections

        return {
            sid: sum(1 for m in batches if usable_detections(m.batch.detections))
            for sid, batches in self._detections.items()
        }

    def _advice(self, feedback: Feedback | None) -> str:
        """One sentence: what to do now."""
        if self.phase == "intrinsics" and self.intrinsics_sensor in self._sensors:
            lens = self._sensors[self.intrinsics_sensor].lens.lens
            if lens is not None:
                return lens.advice(self.intrinsics_sensor)
        if self.phase == "extrinsics" and feedback is not None:
            sensors = feedback.sensors
            calibrated = sorted(s for s, f in sensors.items() if f.calibrated)
            missing = sorted(s for s, f in sensors.items() if not f.calibrated)
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
                f"Lay the board flat on the floor where cameras see it; "
                f"{feedback.floor_views} floor view(s) so far."
            )
        if self.phase == "refinement":
            seen = ", ".join(f"{s} {n}" for s, n in sorted(self._samples().items())) or "none yet"
            return f"One person walks alone through every camera's view (detections: {seen})."
        return self._message

    # ---------------------------------------------------------------- solving
    def calibrate_intrinsics(self, sensor: str, progress: Progress) -> IntrinsicsResult:
        """cv2.calibrateCamera over ``sensor``'s views collected in the intrinsics phase
        (optrack/calibration/intrinsics.py); the result's intrinsics are used for that
        sensor in the extrinsics that follow (start "extrinsics" again)."""
        with self.lock:
            st = self._sensors.get(sensor)
            if st is None:
                raise LiveCalibrationError(
                    f"sensor '{sensor}' is not one of the site's ({', '.join(self.sensors)})."
                )
            corners = list(st.lens.corners)
            size = (st.intrinsics.width, st.intrinsics.height) if st.intrinsics else (0, 0)
        progress(0.1, f"calibrating {sensor} from {len(corners)} views")
        result = calibrate_intrinsics(corners, self.board, size)
        with self.lock:
            self.intrinsics_results[sensor] = result
        progress(1.0, f"{sensor}: RMS {result.rms:.3f} px over {len(result.used)} views")
        return result

    def solve(self, progress: Progress) -> NetworkCalibration:
        """Global bundle adjustment over all views and floor boards: world frame on the
        floor (the first camera's frame when no board lay on the floor; the message says
        so). UserError when no two sensors shared a view."""
        with self._solve_lock:
            self.flush(final=True)
            with self.lock:
                calibrator = self.calibrator
                if calibrator is None:
                    raise LiveCalibrationError(
                        "no board views yet; start the extrinsics page and move the board first."
                    )
            progress(0.05, f"bundle adjustment over {len(calibrator.instants)} instants")
            with self.lock:  # the worker feeds the same calibrator
                result = calibrator.solve()
            if not result.world_T_camera:
                raise CalibrationError(
                    "no sensor could be calibrated; move the board where cameras overlap."
                )
            calibration = self._network(result)
            with self.lock:
                self.result, self.solved, self.refinement = result, calibration, None
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
        with self.lock:
            for sid, pose in result.world_T_camera.items():
                sensors[sid] = SensorCalibration(
                    world_T_camera=as_matrix4(pose),
                    intrinsics=self.intrinsics_of(sid),
                    model=self._sensors[sid].model,
                    reprojection_rms_px=result.sensors[sid].rms_px,
                )
        return NetworkCalibration(
            sensors=sensors,
            ground=(0.0, 0.0, 1.0, 0.0),
            created=now_iso(),
            notes=new_calibration_id(),
        )

    def refine(self, progress: Progress) -> RefinementReport:
        """Algorithm 1 from the walker's detections collected in the refinement phase,
        starting from the current calibration (:func:`~optrack.calibration.live_refine.
        refine_walk`: a sensor's correction is applied only while its checkerboard views
        still agree with it, ``calibration_live.refinement_board_growth``). The report's
        calibration becomes the one saved and sent."""
        with self.lock:
            base = self.calibration
            batches = {s: list(b) for s, b in self._detections.items()}
            calibrator, result = self.calibrator, self.result
        if base is None:
            raise LiveCalibrationError(
                "refinement starts from a calibration; solve the extrinsics and the floor first."
            )

        def board_rms(poses: dict[str, np.ndarray]) -> dict[str, float]:
            if calibrator is None or result is None:
                return {}
            return board_rms_px(calibrator, result, self.board, poses)

        growth = float(self.params.refinement_board_growth)
        report = refine_walk(base, batches, board_rms, growth, progress)
        with self.lock:
            self.refinement = report
            self._message = (
                f"Refined: sensors agree within {report.error_after_m * 100:.1f} cm "
                f"(before: {report.error_before_m * 100:.1f} cm)."
                if report.corrections
                else "Nothing refined: no correction from the walk was applied (sensors agree "
                f"within {report.error_before_m * 100:.1f} cm); the calibration is unchanged."
            )
            if report.refused:
                self._message += (
                    f" {', '.join(sorted(report.refused))} kept the checkerboard's pose: the "
                    "walk moved it where its board views disagree."
                )
        progress(1.0, self._message)
        return report

    # ----------------------------------------------------------------- output
    def quality(self) -> CalibrationQuality:
        """How the current calibration was made (the file's ``quality`` section)."""
        with self.lock:
            result, refinement = self.result, self.refinement
            if result is None:
                raise LiveCalibrationError("nothing to save yet; solve the calibration first.")
            return CalibrationQuality(
                reprojection_rms_px=result.rms_px,
                instants=self._instants,
                floor_views=result.floor_views,
                ground="floor" if result.world == "floor" else "none",
                refinement_error_before_m=refinement.error_before_m if refinement else None,
                refinement_error_after_m=refinement.error_after_m if refinement else None,
                refinement_refused=sorted(refinement.refused) if refinement else [],
            )

    def calibration_file(self, site: str) -> CalibrationFile:
        """The current calibration (refined if refine() ran, else solved) as the calibration
        file it is saved as; ``site``: the site's name, for its notes."""
        with self.lock:
            calibration, result, refinement = self.calibration, self.result, self.refinement
            if calibration is None or result is None:
                raise LiveCalibrationError("nothing to save yet; solve the calibration first.")
            sensors = {}
            for sid, entry in calibration.sensors.items():
                correction = refinement.corrections.get(sid) if refinement is not None else None
                sensors[sid] = SensorEntry(
                    world_T_camera=entry.world_T_camera,
                    intrinsics=entry.intrinsics,
                    model=entry.model,
                    image=self._sensors[sid].image_kind,
                    refinement=as_matrix4(correction) if correction is not None else None,
                    views=result.sensors[sid].used_views,
                    reprojection_rms_px=entry.reprojection_rms_px,
                )
            quality = self.quality()
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
            quality=quality.as_dict(),
            notes=f"live calibration of site '{site}'",
        )
