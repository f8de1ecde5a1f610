"""Live network calibration: what the calibration wizard's backend says and takes.

The live calibration calibrates a running site over the bus, the GUI being one
more node; the wizard (``app/wizard``) and ``optrack calibrate live`` drive it:

* :mod:`optrack.calibration.live_session`: :class:`LiveSession`, the maths (still
  boards from the nodes' board views, the network calibrator, the solve, the
  refinement from a walk, the calibration file), without the bus;
* :mod:`optrack.runtime.calibration_live`: ``LiveCalibration``, the bus side
  (commands to the detector nodes, the site's operator, the worker thread).

This module holds what both and their users share: the phases, the
``calibration_live`` parameters and :class:`LiveState`, the snapshot the GUI
polls at ~5 Hz.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from optrack.calibration.intrinsics import IntrinsicsResult
from optrack.calibration.live_refine import RefinementReport
from optrack.calibration.overlap import BoardSuggestion
from optrack.errors import UserError
from optrack.params import Param, Schema, register
from optrack.types import Intrinsics, NetworkCalibration

__all__ = [
    "INSTRUCTIONS",
    "LIVE_PARAMS",
    "PHASES",
    "LiveCalibrationError",
    "LiveState",
    "Progress",
    "RefinementReport",
    "SensorLive",
]

#: (fraction 0..1, sentence)
Progress = Callable[[float, str], None]

#: The phases a live calibration captures for ("idle" is the state between them).
PHASES = ("intrinsics", "extrinsics", "floor", "refinement")

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
                "operator_searches",
                3,
                min=1,
                max=20,
                step=1,
                help="A simulated operator asked to go round again (a sensor still needs "
                "shared board poses) holds the board long enough for this many searches of "
                "the slowest node, at least its own hold.",
            ),
            Param(
                "min_shared_poses",
                2,
                min=1,
                max=20,
                step=1,
                help="The extrinsics page calls a sensor calibrated once it shares this many "
                "distinct board poses with calibrated sensors (one pose leaves it where that "
                "one pose put it).",
            ),
            Param(
                "shared_pose_spacing",
                0.3,
                min=0.0,
                max=5.0,
                unit="m",
                help="Two board poses a sensor shares are distinct when their centres are "
                "this far apart (or turned by shared_pose_turn_deg).",
            ),
            Param(
                "shared_pose_turn_deg",
                15.0,
                min=0.0,
                max=90.0,
                unit="deg",
                help="Two board poses a sensor shares are distinct when turned this far from "
                "each other (or shared_pose_spacing apart).",
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


INSTRUCTIONS = {
    "intrinsics": "Show the board all over the image, tilted.",
    "extrinsics": "Move the board where cameras overlap; hold it still for a second at each place.",
    "floor": "Lay the board flat on the floor where cameras see it, at one or several places.",
    "refinement": "One person walks alone through every camera's view.",
}


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
    # the board lies on the floor in the latest image (the node's depth test)
    on_floor: bool = False
    # board views this node has published in this phase (found or not), and the rate it
    # actually captures at (Hz, measured on our side): the truth for the status
    frames: int = 0
    capture_hz: float = 0.0
    # tree parent in the network (None for the root or uncalibrated)
    parent: str | None = None
    # extrinsics: distinct board poses this sensor shares with calibrated sensors, the
    # number it needs (0: no such rule), and those poses' board centres (Kx3, the frame of
    # world_T_camera)
    shared_poses: int = 0
    shared_needed: int = 0
    shared_centers: np.ndarray | None = None
    # intrinsics: the lens from this capture's views so far (None: too few yet); its
    # ``good`` says whether they pin it down, its ``advice`` where to show the board
    lens: IntrinsicsResult | None = None

    @property
    def settled(self) -> bool:
        """Calibrated on enough shared evidence (what the extrinsics page asks for)."""
        return self.calibrated and self.shared_poses >= self.shared_needed


@dataclasses.dataclass
class LiveState:
    """A snapshot of the live calibration, cheap to take: everything the wizard shows and
    decides on (it keeps no calibration of its own)."""

    phase: str  # "idle", "intrinsics", "extrinsics", "floor", "refinement"
    sensors: dict[str, SensorLive]
    covisibility: list[tuple[str, str, int]]  # (sensor a, sensor b, shared views)
    floor_views: int  # board-on-floor views accepted (all sensors)
    refinement_samples: dict[str, int]  # walker detections collected per sensor
    message: str  # one sentence for the operator (what to do now / what is wrong)
    # seconds since the phase started; instants (still boards fed to the calibrator)
    elapsed_s: float = 0.0
    instants: int = 0
    # what the site's operator does, when it has one (a simulated site), e.g. "lay_board"
    operator: str = ""
    # the results so far: the solved calibration, the refinement of it (if any) and the
    # calibration that is saved and sent (the refined one, else the solved one); the
    # intrinsics calibrated on the intrinsics page, per sensor
    solved: NetworkCalibration | None = None
    refinement: RefinementReport | None = None
    calibration: NetworkCalibration | None = None
    intrinsics_results: dict[str, IntrinsicsResult] = dataclasses.field(default_factory=dict)
    # extrinsics: where to hold the board for a camera not calibrated yet (None: no advice)
    guidance: BoardSuggestion | None = None
    # refinement: the walker's positions so far as each sensor sees them (sensor -> Nx3, in
    # the solved calibration's world), drawn while the person walks
    walk: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
