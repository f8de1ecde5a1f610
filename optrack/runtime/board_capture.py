"""The detector node's checkerboard capture for the live calibration.

On the ``calibration_start`` command (``{phase, cols, rows, square[,
thickness, image, rate_hz]}``) the node looks for the checkerboard ``rate_hz``
times per second in the image that belongs to its depth camera
(:func:`optrack.calibration.session.pick_image`: infrared, equalised and
upsampled for a low-resolution sensor, when the colour is not registered) and
publishes one :class:`~optrack.net.messages.BoardViewMessage` per searched
frame on ``board_views/<sensor>``: the capture stamp in tracker time, the
corners or none, whether the board lies on the floor (the depth test of
:func:`optrack.calibration.session.board_on_floor`, done here where the
full-resolution depth is) and a small JPEG with the corners drawn. The
search runs in its own thread on a copy of the newest frame (OpenCV releases
the GIL); the node's loop only hands frames over. ``calibration_stop`` ends
it. The GUI never receives full frames. The live calibration that asks for
it is :class:`optrack.runtime.calibration_live.LiveCalibration`.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from typing import Any

import cv2
import msgspec
import numpy as np

from optrack.calibration.board import CORNER_PARAMS, Checkerboard, find_corners, to_gray
from optrack.errors import UserError
from optrack.net.bus import Bus
from optrack.net.clock import ClockSync
from optrack.net.messages import BoardViewMessage
from optrack.params import Param, Params, Schema, register
from optrack.recording import SensorInfo
from optrack.runtime.node import RateMeter
from optrack.types import RGBDFrame

__all__ = [
    "CAPTURE_PARAMS",
    "CAPTURE_PHASES",
    "CalibrationCapture",
    "CaptureError",
]

log = logging.getLogger("optrack.runtime.board_capture")

CAPTURE_PHASES = ("intrinsics", "extrinsics", "floor")

CAPTURE_PARAMS = register(
    Schema(
        "calibration_capture",
        [
            Param(
                "rate_hz",
                3.0,
                min=0.2,
                max=30.0,
                unit="Hz",
                help="Frames per second a detector node searches for the checkerboard during "
                "a calibration capture (one search takes 0.05-0.3 s of one core).",
            ),
            Param(
                "preview_width",
                320,
                min=64,
                max=1920,
                step=1,
                unit="px",
                help="Width of the JPEG preview with the corners drawn.",
            ),
            Param(
                "jpeg_quality",
                80,
                min=10,
                max=100,
                step=1,
                help="JPEG quality of the preview.",
            ),
            Param(
                "detect_while_capturing",
                False,
                help="Keep detecting people while searching for the board; off: the board "
                "search gets the CPU and the node publishes no detections meanwhile.",
            ),
        ],
        help="Checkerboard capture on the detector nodes for the live calibration.",
    )
)


#: Board thickness when the command does not say (calibration_network.board_thickness's
#: default; that schema's module imports gtsam, which a node loads only to capture).
DEFAULT_THICKNESS = 0.005


class CaptureError(UserError):
    """A calibration capture that cannot be done."""


def _board_from(args: dict[str, Any]) -> Checkerboard:
    try:
        return Checkerboard(int(args["cols"]), int(args["rows"]), float(args["square"]))
    except KeyError as missing:
        raise CaptureError(
            f"calibration_start needs the board's {missing.args[0]} (cols, rows, square)."
        ) from None
    except (TypeError, ValueError):
        raise CaptureError(
            "calibration_start needs cols and rows as whole numbers and square in metres; "
            f"got cols={args.get('cols')!r}, rows={args.get('rows')!r}, "
            f"square={args.get('square')!r}."
        ) from None


class CalibrationCapture:
    """A detector node's checkerboard capture (see the module docstring).

    ``offer(frame, captured)`` is called by the node's loop for every frame;
    it returns True when the node should skip detection for that frame.
    """

    def __init__(
        self,
        bus: Bus,
        info: SensorInfo,
        sync: ClockSync,
        params: Params | None = None,
        on_streams: Callable[[str], None] | None = None,
        logger: logging.Logger = log,
    ) -> None:
        self.bus = bus
        self.info = info
        self.sync = sync
        self.params = params if params is not None else CAPTURE_PARAMS.create()
        self.corner_params = CORNER_PARAMS.create()
        self.session_params: Params | None = None  # made on the first capture (imports gtsam)
        self.on_streams = on_streams
        self.log = logger
        self.phase = ""
        self.board: Checkerboard | None = None
        self.kind = ""
        self.intrinsics = info.intrinsics
        self.registered = True
        self.thickness = DEFAULT_THICKNESS
        self.rate_hz = float(self.params.rate_hz)
        self.searched = 0
        self.found = 0
        self.last_error = ""
        self._seq = 0
        self._meter = RateMeter(window_s=5.0)
        self._next_due = 0.0
        self._lock = threading.Lock()
        self._work: tuple[np.ndarray, np.ndarray | None, float, str] | None = None
        self._wake = threading.Event()
        self._closed = False
        self._busy = False
        self._idle = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="calibration-capture", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------- commands
    def register(self, add_command: Callable[[str, Callable[[dict[str, Any]], Any]], None]) -> None:
        """Register ``calibration_start`` and ``calibration_stop`` with a node."""
        add_command("calibration_start", self.command_start)
        add_command("calibration_stop", self.command_stop)

    def command_start(self, args: dict[str, Any]) -> dict[str, Any]:
        # The calibration modules import gtsam: only on a node that is asked to capture.
        from optrack.calibration.session import SESSION_PARAMS, pick_image

        if self.session_params is None:
            self.session_params = SESSION_PARAMS.create()
        phase = str(args.get("phase", "extrinsics"))
        if phase not in CAPTURE_PHASES:
            raise CaptureError(
                f"calibration phase '{phase}' is unknown; use one of {', '.join(CAPTURE_PHASES)}."
            )
        board = _board_from(args)
        if phase != "intrinsics":
            board.require_asymmetric()
        choice = pick_image(self.info, str(args.get("image", "auto")))
        if choice is None:
            raise CaptureError(
                f"sensor '{self.info.id}' has no {args.get('image', 'colour or infrared')} image "
                "to find the board in; calibrate it with a sensor that records one."
            )
        kind, intrinsics = choice
        rate = self.params.schema.validate(
            {"rate_hz": float(args.get("rate_hz", self.params.rate_hz))}
        )["rate_hz"]
        thickness = float(args.get("thickness", self.thickness))
        if not (math.isfinite(thickness) and 0 <= thickness <= 0.1):
            raise CaptureError(f"board thickness must be 0 to 0.1 m; got {thickness}.")
        if self.on_streams is not None:
            self.on_streams(kind)
        with self._lock:
            self.phase, self.board, self.kind = phase, board, kind
            self.intrinsics = intrinsics
            self.registered = kind == "infrared" or self.info.color_intrinsics is None
            self.rate_hz, self.thickness = float(rate), thickness
            self.searched = self.found = 0
            self._next_due = 0.0
        self.log.info(
            "calibration capture (%s) started: %s board on the %s image at %.1f Hz",
            phase,
            board.describe(),
            kind,
            rate,
        )
        return {
            "sensor": self.info.id,
            "phase": phase,
            "image": kind,
            "intrinsics": msgspec.to_builtins(intrinsics),
            "model": self.info.model,
            "rate_hz": float(rate),
        }

    def command_stop(self, args: dict[str, Any]) -> dict[str, Any]:
        with self._lock:
            phase, self.phase = self.phase, ""
            self._work = None
        if phase:
            self.log.info(
                "calibration capture (%s) stopped: board found in %d of %d frames searched",
                phase,
                self.found,
                self.searched,
            )
        return {"sensor": self.info.id, "searched": self.searched, "found": self.found}

    @property
    def active(self) -> bool:
        return bool(self.phase)

    def wait_ready(self, stop: threading.Event) -> None:
        """Block until the search is idle and the next frame is wanted (or ``stop``): the
        node reads (and a simulated sensor renders) only the frames the capture uses."""
        while not stop.is_set() and self.phase:
            if self._busy:
                self._idle.wait(0.05)
                continue
            delay = self._next_due - time.monotonic()
            if delay <= 0:
                return
            stop.wait(min(delay, 0.05))

    # --------------------------------------------------------------- frames
    def offer(self, frame: RGBDFrame, captured: float) -> bool:
        """Hand a frame over (node clock ``captured``); True: skip detecting on it."""
        if not self.phase:
            return False
        pause = not bool(self.params.detect_while_capturing)
        now = time.monotonic()
        if self._busy or now < self._next_due:
            return pause
        image = frame.infrared if self.kind == "infrared" else frame.color
        if image is None:
            self._note(
                f"sensor '{self.info.id}' delivered a frame without its {self.kind} image; "
                "the board cannot be searched in it."
            )
            return pause
        depth = frame.depth_m() if self.registered else None
        with self._lock:
            self._work = (np.array(image, copy=True), depth, captured, self.phase)
            self._busy = True
            self._idle.clear()
            self._next_due = now + 1.0 / self.rate_hz
        self._wake.set()
        return pause

    def _note(self, sentence: str) -> None:
        if sentence != self.last_error:
            self.log.warning("%s", sentence)
        self.last_error = sentence

    def _loop(self) -> None:
        while not self._closed:
            self._wake.wait(0.5)
            self._wake.clear()
            with self._lock:
                work, self._work = self._work, None
                board, intrinsics, kind = self.board, self.intrinsics, self.kind
            if work is None or board is None:
                self._busy = False
                self._idle.set()
                continue
            try:
                self._search(work, board, intrinsics, kind)
            except Exception as error:  # a search bug must not stop the node
                self._note(f"board search failed ({type(error).__name__}: {error})")
            finally:
                self._busy = False
                self._idle.set()

    def _search(
        self,
        work: tuple[np.ndarray, np.ndarray | None, float, str],
        board: Checkerboard,
        intrinsics: Any,
        kind: str,
    ) -> None:
        from optrack.calibration.network import observe_board
        from optrack.calibration.session import board_on_floor

        image, depth, captured, phase = work
        started = time.perf_counter()
        corners = find_corners(image, board, self.corner_params, infrared=kind == "infrared")
        on_floor: bool | None = None
        if corners is not None and depth is not None and phase != "intrinsics":
            view = observe_board(self.info.id, corners, intrinsics, board)
            on_floor = board_on_floor(
                view, depth, intrinsics, board, self.session_params, self.thickness
            )
        search_ms = (time.perf_counter() - started) * 1000.0
        preview = self._preview(image, board, corners)
        if phase != self.phase:  # stopped or restarted meanwhile
            return
        self.searched += 1
        self.found += corners is not None
        self._seq += 1
        self._meter.add()
        self.bus.publish(
            self.bus.keys.board_views(self.info.id),
            BoardViewMessage(
                sensor=self.info.id,
                stamp=self.sync.to_tracker(captured),
                phase=phase,
                seq=self._seq,
                image=kind,
                intrinsics=intrinsics,
                corners=None if corners is None else [(float(u), float(v)) for u, v in corners],
                on_floor=on_floor,
                preview_jpeg=preview,
                model=self.info.model,
                search_ms=search_ms,
            ),
        )

    def _preview(self, image: np.ndarray, board: Checkerboard, corners: np.ndarray | None) -> bytes:
        """A small JPEG of the image (grey for infrared) with the corners drawn."""
        if image.ndim == 3 and image.dtype == np.uint8:
            bgr = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
        else:
            bgr = cv2.cvtColor(to_gray(image), cv2.COLOR_GRAY2BGR)
        width = int(self.params.preview_width)
        scale = min(1.0, width / bgr.shape[1])
        if scale < 1.0:
            bgr = cv2.resize(bgr, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
        if corners is not None:
            points = ((corners + 0.5) * scale - 0.5).astype(np.float32).reshape(-1, 1, 2)
            cv2.drawChessboardCorners(bgr, board.size, points, True)
        ok, data = cv2.imencode(
            ".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, int(self.params.jpeg_quality)]
        )
        return data.tobytes() if ok else b""

    # --------------------------------------------------------------- status
    def status_values(self) -> dict[str, Any]:
        """For the node's status ``values``: the phase and the real capture rate."""
        return {
            "capture": self.phase or "off",
            "capture_hz": round(self._meter.rate(), 2),
            "capture_found": self.found,
        }

    def close(self) -> None:
        self._closed = True
        self.phase = ""
        self._wake.set()
        self._thread.join(timeout=2.0)
