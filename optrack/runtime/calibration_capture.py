"""Calibration capture on the nodes, and the simulated operator of a simulated site.

Node side (:class:`CalibrationCapture`, one per detector node). On the
``calibration_start`` command (``{phase, cols, rows, square[, thickness,
image, rate_hz]}``) the node looks for the checkerboard ``rate_hz`` times per
second in the image that belongs to its depth camera
(:func:`optrack.calibration.session.pick_image`: infrared, equalised and
upsampled for a low-resolution sensor, when the colour is not registered) and
publishes one :class:`~optrack.net.messages.BoardViewMessage` per searched
frame on ``board_views/<sensor>``: the capture stamp in tracker time, the
corners or none, whether the board lies on the floor (the depth test of
:func:`optrack.calibration.session.board_on_floor`, done here where the
full-resolution depth is) and a small JPEG with the corners drawn. The
search runs in its own thread on a copy of the newest frame (OpenCV releases
the GIL); the node's loop only hands frames over. ``calibration_stop`` ends
it. The GUI never receives full frames.

Site side (:class:`SimulatedOperator`, in ``optrack run`` when every sensor
is simulated). The ``operator`` command of the ``site`` node, ``{action:
move_board | show_board | lay_board | walk | people | status}``, restarts the
detector nodes on live simulated sensors of a scene made from the site's own
scenario (same venue, same sensors, so the same true poses) with the operator
doing what the calibration wizard asks: carrying the board to places where
each sensor and each neighbouring pair sees it (``move_board``), showing it
to one ``sensor`` all over its image, turned many ways (``show_board``, the
intrinsics page), laying it on the floor at ``floor_places`` places
(``lay_board``), or one person walking through every view (``walk``);
``people`` goes back to the site's own sensors (the venue). The scenes are rendered live, so the nodes run at the
rate ray casting allows (a few frames per second on 2 cores; their status
shows it): enough for the capture, which needs a few per second.
"""

from __future__ import annotations

import logging
import math
import threading
import time
import urllib.parse
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import msgspec
import numpy as np
import yaml

from optrack.calibration.board import CORNER_PARAMS, Checkerboard, find_corners, to_gray
from optrack.errors import UserError
from optrack.net.bus import Bus
from optrack.net.clock import ClockSync
from optrack.net.messages import BoardViewMessage, CommandReply, CommandRequest
from optrack.params import Param, Params, Schema, register
from optrack.recording import SensorInfo
from optrack.runtime.node import RateMeter
from optrack.sensors.base import Sensor
from optrack.types import RGBDFrame

__all__ = [
    "CAPTURE_PARAMS",
    "CAPTURE_PHASES",
    "OPERATOR_ACTIONS",
    "OPERATOR_PARAMS",
    "CalibrationCapture",
    "CaptureError",
    "SceneSwitch",
    "SimulatedOperator",
]

log = logging.getLogger("optrack.runtime.calibration_capture")

CAPTURE_PHASES = ("intrinsics", "extrinsics", "floor")
OPERATOR_ACTIONS = ("move_board", "show_board", "lay_board", "walk", "people", "status")

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

OPERATOR_PARAMS = register(
    Schema(
        "sim_operator",
        [
            Param(
                "lead_s",
                3.0,
                min=0.0,
                max=60.0,
                unit="s",
                help="The operator's scene starts this long after the command, while the "
                "detector nodes build it.",
            ),
            Param(
                "floor_places",
                3,
                min=1,
                max=10,
                step=1,
                help="Places the simulated operator lays the board at (the ground page).",
            ),
            Param(
                "walk_margin",
                1.2,
                min=0.3,
                max=5.0,
                unit="m",
                help="The simulated walker's route keeps this far from the walls.",
            ),
            Param(
                "scene_seconds",
                900.0,
                min=10.0,
                max=3600.0,
                unit="s",
                help="Length of an operator scene; the simulated sensors end after it.",
            ),
            Param(
                "hold_s",
                5.0,
                min=0.5,
                max=60.0,
                unit="s",
                help="The simulated operator holds the board still this long at each place "
                "(a few searches of every node must fall in it; slow computers need longer).",
            ),
            Param(
                "intrinsics_places",
                9,
                min=1,
                max=40,
                step=1,
                help="Places the simulated operator shows the board at for one sensor's "
                "intrinsics (show_board), each turned another way.",
            ),
            Param(
                "intrinsics_hold_s",
                1.5,
                min=0.2,
                max=60.0,
                unit="s",
                help="The simulated operator holds the board this long at each intrinsics "
                "place (one still view is kept per place; the board needs no partner).",
            ),
            Param(
                "command_timeout_s",
                10.0,
                min=0.1,
                max=60.0,
                unit="s",
                help="How long the operator waits for a detector node to take its scene.",
            ),
            Param(
                "skip_step_s",
                0.1,
                min=0.01,
                max=1.0,
                unit="s",
                help="Time step used to find when the operator starts for the floor "
                "(lay_board skips the held placements).",
            ),
        ],
        help="The simulated operator of a simulated site (calibration wizard).",
    )
)


#: Board thickness when the command does not say (calibration_network.board_thickness's
#: default; that schema's module imports gtsam, which a node loads only to capture).
DEFAULT_THICKNESS = 0.005


class CaptureError(UserError):
    """A calibration capture or operator action that cannot be done."""


# ====================================================================== node side


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


class SceneSwitch:
    """The node side of the simulated operator: ``sim_scene {uri}`` makes the detector
    node read its sensor of a simulated scene (a ``sim://`` URI with this node's sensor
    id) from its next frame, without restarting; ``{uri: ""}`` goes back to the node's
    own sensor (a replayed venue resumes where its clock is)."""

    def __init__(self, own: Sensor, logger: logging.Logger = log) -> None:
        self.own = own
        self.current = own
        self.log = logger
        self._pending: str | None = None
        self._lock = threading.Lock()

    def register(self, add_command: Callable[[str, Callable[[dict[str, Any]], Any]], None]) -> None:
        add_command("sim_scene", self.command)

    def command(self, args: dict[str, Any]) -> dict[str, Any]:
        uri = str(args.get("uri", ""))
        sensor_id = self.own.info.id
        if uri:
            parsed = urllib.parse.urlsplit(uri)
            options = dict(urllib.parse.parse_qsl(parsed.query))
            if parsed.scheme != "sim" or options.get("id") != sensor_id:
                raise CaptureError(
                    f"a simulated operator's scene must be a sim:// URI with id={sensor_id} "
                    f"for this node; got '{uri}'."
                )
        with self._lock:
            self._pending = uri
        return {"sensor": sensor_id, "uri": uri}

    def take(self, report: Callable[[str], None]) -> Sensor | None:
        """The sensor to read from now on, when it changed (called between frames)."""
        with self._lock:
            uri, self._pending = self._pending, None
        if uri is None:
            return None
        if not uri:
            sensor = self.own
        else:
            from optrack.sim.sensor import SimulatedSensor

            try:
                sensor = SimulatedSensor.from_uri(uri)
            except UserError as error:
                report(f"the simulated operator's scene cannot be used: {error}")
                return None
        if self.current is not self.own:
            self.current.close()
        self.current = sensor
        self.log.info("reading %s", sensor.info.uri or sensor.info.id)
        return sensor


# ====================================================================== site side


#: sim:// options of the site's sensors that the operator's scenes keep.
_KEPT_OPTIONS = ("seed", "sensors", "model", "noise")


def _route(half: np.ndarray, margin: float) -> list[tuple[float, float]]:
    """A walk around and across the room (refinement.yaml's, scaled to the venue)."""
    x, y = float(half[0] - margin), float(half[1] - margin)
    points = [(-x, -y), (x, -y), (x, y), (0.0, 0.0), (-x, y), (-x, -y), (x, y), (-x, y)]
    return [(round(a, 3), round(b, 3)) for a, b in points]


class SimulatedOperator:
    """The ``operator`` command of a simulated site (see the module docstring).

    ``sensors`` lists the detector nodes as (name, scenario index) and ``uris`` their
    own sensor URIs (what ``people`` goes back to); ``switch(uris)`` asks the site to
    restart its detector nodes on new URIs (in the same order).
    """

    def __init__(
        self,
        scenario: str,
        seed: int,
        sensors: list[tuple[str, int]],
        uris: list[str],
        run_dir: Path,
        params: Params | None = None,
        logger: logging.Logger = log,
        options: dict[str, str] | None = None,
    ) -> None:
        """``options``: the site's sim:// options that the scenes keep (sensors, model,
        noise)."""
        from optrack.sim.scenario import load_scenario

        self.base = load_scenario(scenario)
        self.scenario = scenario
        self.seed = seed
        self.sensors = sensors
        self.uris = list(uris)
        self.run_dir = Path(run_dir)
        self.bus: Bus | None = None
        self.params = params if params is not None else OPERATOR_PARAMS.create()
        self.log = logger
        self.action = "people"
        self.scene = ""
        self.options = dict(options or {})
        self.count = 0
        self.error = ""
        self._lock = threading.Lock()

    def status_values(self) -> dict[str, str]:
        """For the site status: what the operator does, its scene, what went wrong."""
        return {"operator": self.action, "operator.scene": self.scene, "operator.error": self.error}

    @classmethod
    def for_site(
        cls,
        site_params: Params,
        uris: list[str],
        names: list[str],
        run_dir: Path,
    ) -> SimulatedOperator | None:
        """The site's simulated operator, or None when a sensor is not simulated."""
        if not str(site_params.sensors).strip():  # the embedded venue
            from optrack.sim.world import Simulation

            venue = Simulation(str(site_params.scenario), seed=int(site_params.seed), people=0)
            ids = {sensor.id: k for k, sensor in enumerate(venue.sensors)}
            if any(name not in ids for name in names):
                return None
            indices = [ids[name] for name in names]
            return cls(
                str(site_params.scenario),
                int(site_params.seed),
                list(zip(names, indices, strict=True)),
                uris,
                run_dir,
            )
        scenarios, kept, indices = set(), set(), []
        for uri in uris:
            parsed = urllib.parse.urlsplit(uri)
            if parsed.scheme != "sim":
                return None
            target = (parsed.netloc + parsed.path).rstrip("/")
            if not parsed.netloc and parsed.path.startswith("/"):
                target = parsed.path.rstrip("/")
            scenario, _, number = target.rpartition("/")
            if not number.isdigit():
                return None
            options = dict(urllib.parse.parse_qsl(parsed.query))
            scenarios.add(scenario)
            kept.add(tuple(sorted((k, v) for k, v in options.items() if k in _KEPT_OPTIONS)))
            indices.append(int(number))
        if len(scenarios) != 1 or len(kept) != 1:
            return None
        options = dict(kept.pop())
        try:
            seed = int(options.pop("seed", "0"))
        except ValueError:
            return None
        return cls(
            scenarios.pop(),
            seed,
            list(zip(names, indices, strict=True)),
            uris,
            run_dir,
            options=options,
        )

    # -------------------------------------------------------------- commands
    def serve(self, bus: Bus) -> None:
        """Answer ``operator`` commands on ``command/site``."""

        def answer(request: CommandRequest) -> CommandReply:
            if request.action != "operator":
                return CommandReply(
                    node="site",
                    action=request.action,
                    ok=False,
                    sentence=f"node 'site' has no command '{request.action}' (it has: operator).",
                )
            try:
                result = self.command(dict(request.args))
            except UserError as error:
                return CommandReply(node="site", action="operator", ok=False, sentence=str(error))
            return CommandReply(node="site", action="operator", ok=True, result=result)

        self.bus = bus
        bus.serve(bus.keys.command("site"), CommandRequest, answer)

    def command(self, args: dict[str, Any]) -> dict[str, Any]:
        """``{action, cols, rows, square, places, pairs, sensor}`` -> ``{action, scene}``;
        the nodes restart on the scene in the background (their status ``sensor`` names
        the scene; a scene that cannot be made is ``operator.error`` in the site status).
        ``pairs`` (move_board): skip the placements facing one sensor (the extrinsics need
        pairs). ``sensor`` (show_board): the detector node whose intrinsics are wanted."""
        action = str(args.get("action", ""))
        if action not in OPERATOR_ACTIONS:
            raise CaptureError(
                f"the simulated operator cannot '{action}'; ask one of "
                f"{', '.join(OPERATOR_ACTIONS)}."
            )
        if action == "status":
            return {"action": self.action, "scene": self.scene, "actions": list(OPERATOR_ACTIONS)}
        board = None
        shown = -1
        if action == "show_board":
            names = {name: index for name, index in self.sensors}
            shown = names.get(str(args.get("sensor", "")), -1)
            if shown < 0:
                raise CaptureError(
                    f"the simulated operator shows the board to one of the site's sensors "
                    f"({', '.join(names)}); got {args.get('sensor')!r}."
                )
        if action in ("move_board", "show_board", "lay_board"):
            board = _board_from({"cols": 6, "rows": 5, "square": 0.15, **args})
            board.require_asymmetric()
        places = int(args.get("places", self.params.floor_places))
        if action == "lay_board" and not 1 <= places <= 10:
            raise CaptureError(f"the operator lays the board at 1 to 10 places; got {places}.")
        pairs = bool(args.get("pairs", False))
        with self._lock:
            self.count += 1
            scene = "" if action == "people" else f"operator-{self.count}-{action}"
            self.action, self.scene, self.error = action, scene, ""
        threading.Thread(
            target=self._prepare, args=(action, scene, board, places, pairs, shown), daemon=True
        ).start()
        return {"action": action, "scene": scene}

    def _prepare(
        self,
        action: str,
        scene: str,
        board: Checkerboard | None,
        places: int,
        pairs: bool,
        shown: int = -1,
    ) -> None:
        try:
            uris = (
                [""] * len(self.sensors)
                if action == "people"
                else self._scene_uris(action, scene, board, places, pairs, shown)
            )
            with self._lock:
                if self.scene != scene:  # a newer command came meanwhile
                    return
            self._switch(uris)
        except Exception as error:
            sentence = (
                str(error) if isinstance(error, UserError) else f"{type(error).__name__}: {error}"
            )
            self.log.error("the simulated operator could not prepare '%s': %s", action, sentence)
            with self._lock:
                if self.scene == scene:
                    self.error = sentence
            return
        self.log.info("simulated operator: %s", action)

    def _switch(self, uris: list[str]) -> None:
        """Each detector node reads its sensor of the scene from its next frame ("": its
        own sensor again). Every node is asked even when one does not answer."""
        from optrack.runtime.node import send_command

        assert self.bus is not None
        problems = []
        for (name, _), uri in zip(self.sensors, uris, strict=True):
            try:
                send_command(
                    self.bus, name, "sim_scene", {"uri": uri}, float(self.params.command_timeout_s)
                )
            except UserError as error:
                problems.append(str(error))
        if problems:
            raise CaptureError(problems[0])

    def _scene_uris(
        self,
        action: str,
        scene: str,
        board: Checkerboard | None,
        places: int,
        pairs: bool,
        shown: int = -1,
    ) -> list[str]:
        from optrack.sim.scenario import BoardSpec, PeopleSpec
        from optrack.sim.venue import Venue

        p = self.params
        if action == "walk":
            half = Venue(self.base.venue).half
            people = PeopleSpec(count=1, routes=[_route(half, float(p.walk_margin))])
            spec = None
        else:
            assert board is not None
            people = PeopleSpec(count=0)
            spec = BoardSpec(
                cols=board.cols,
                rows=board.rows,
                square=board.square,
                floor_placements=places if action == "lay_board" else 0,
                intrinsics_sensor=shown,
                intrinsics_placements=int(p.intrinsics_places),
            )
        derived = msgspec.structs.replace(
            self.base,
            description=f"{self.base.description} (simulated operator: {action})",
            seconds=float(p.scene_seconds),
            people=people,
            board=spec,
        )
        data = msgspec.to_builtins(derived)
        data.pop("name", None)
        path = self.run_dir / f"{scene}.yaml"
        path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
        skip = 0.0
        if action == "lay_board":
            skip = self._skip_to(path, lambda step: step.kind == "floor")
        elif action == "move_board" and pairs:
            skip = self._skip_to(path, lambda step: len(step.sensors) > 1)
        start = time.time() + float(p.lead_s) - skip
        extra = "".join(f"&{k}={urllib.parse.quote(v)}" for k, v in sorted(self.options.items()))
        if spec is not None:
            hold = float(p.intrinsics_hold_s if action == "show_board" else p.hold_s)
            extra += f"&hold={hold:g}"
        return [
            f"sim://{path}/{index}?seed={self.seed}{extra}&start={start:.3f}&id={name}"
            for name, index in self.sensors
        ]

    def _skip_to(self, path: Path, wanted: Callable[[Any], bool]) -> float:
        """Simulated seconds until the operator heads for the first placement ``wanted``
        (the placements before it are skipped: the held ones for the floor, those facing
        one sensor for the extrinsics)."""
        from optrack.sim.board import BOARD_PARAMS
        from optrack.sim.world import Simulation

        sensors = self.options.get("sensors")
        sim = Simulation(
            str(path),
            seed=self.seed,
            sensors=int(sensors) if sensors else None,
            sensor_model=self.options.get("model") or None,
            params={"sim_board": BOARD_PARAMS.create({"hold_seconds": float(self.params.hold_s)})},
        )
        operator = sim.operator
        if operator is None:
            return 0.0
        first = next((k for k, step in enumerate(operator.steps) if wanted(step)), None)
        if first is None:
            raise CaptureError(
                "the simulated operator found no place for the board that the sensors see "
                "(together, or on the floor); use a larger board or check the sensors' views."
            )
        t, step = 0.0, float(self.params.skip_step_s)
        while operator.index < first and t < sim.seconds:
            t += step
            sim.crowd.advance(t)
        return t
