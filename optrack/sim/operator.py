"""The simulated operator of a simulated site: the person the calibration wizard talks
to when no one is there.

On a site whose sensors are all simulated (the embedded venue, or ``sim://``
URIs of one scenario; ``optrack run``), the ``site`` node answers the
``operator`` command, ``{action: move_board | show_board | lay_board | walk |
people | status, cols, rows, square, pairs, sensor}``
(:class:`SimulatedOperator`): it writes a scene made from the site's own
scenario (same venue, same sensors, so the same true poses) with an operator
doing what the calibration wizard asks: carrying the board to places where
each sensor and each neighbouring pair sees it (``move_board``), showing it to
one ``sensor`` all over its image, turned many ways (``show_board``, the
intrinsics page), laying it on the floor at ``floor_places`` places at least,
and more until each sensor that can see the floor saw it at ``floor_per_sensor``
(``lay_board``), or one person walking through every view (``walk``);
``people`` goes back to the site's own sensors (the venue). The board is the
command's, else the site scenario's; a scene without a board to carry is
refused. Each detector node then reads its sensor of that scene from its next
frame (command ``sim_scene``, answered by the node's :class:`SceneSwitch`).
The scenes are rendered live, so the nodes run at the rate ray casting allows
(a few frames per second on 2 cores; their status shows it): enough for the
board capture, which needs a few per second. The site status says what the
operator does (``values.operator``, ``operator.scene``, ``operator.error``).

The live calibration sees the operator only through its small interface
(``optrack.runtime.calibration_operator.BoardOperator``); a real site has none.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
import urllib.parse
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
import yaml

from optrack.calibration.board import Checkerboard
from optrack.errors import UserError
from optrack.io.files import atomic_write_text
from optrack.net.bus import Bus
from optrack.net.messages import CommandReply, CommandRequest
from optrack.params import Param, Params, Schema, register
from optrack.sensors.base import Sensor

__all__ = [
    "OPERATOR_ACTIONS",
    "OPERATOR_PARAMS",
    "OperatorError",
    "SceneSwitch",
    "SimulatedOperator",
]

log = logging.getLogger("optrack.sim.operator")

OPERATOR_ACTIONS = ("move_board", "show_board", "lay_board", "walk", "people", "status")

#: Sends one command to a node and returns its result, or raises a UserError sentence:
#: ``(bus, node, action, args, timeout_s)`` (optrack.runtime.node.send_command).
SendCommand = Callable[[Bus, str, str, Mapping[str, Any], float], dict[str, Any]]

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
                help="Places the simulated operator lays the board at (the ground page), at least.",
            ),
            Param(
                "floor_per_sensor",
                3,
                min=0,
                max=10,
                step=1,
                help="The simulated operator lays the board at more places until every "
                "sensor that can see the floor has seen it at this many (a camera that saw "
                "the board on the floor once, far off, can tilt the whole floor).",
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
                "floor_hold_s",
                2.5,
                min=0.5,
                max=60.0,
                unit="s",
                help="The simulated operator leaves the board lying still this long at each "
                "floor place (one sensor's still view is enough there; the wizard asks "
                "for longer where the nodes search their images slowly).",
            ),
            Param(
                "intrinsics_places",
                22,
                min=1,
                max=40,
                step=1,
                help="Places the simulated operator shows the board at for one sensor's "
                "intrinsics (show_board), each turned another way, all over the sensor's "
                "image (the intrinsics page calls the lens good after 12-19 of them; while it "
                "does not, the operator goes round again).",
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
        ],
        help="The simulated operator of a simulated site (calibration wizard).",
    )
)


class OperatorError(UserError):
    """An operator action that cannot be done."""


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
                raise OperatorError(
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


#: sim:// options of the site's sensors that the operator's scenes keep.
_KEPT_OPTIONS = ("seed", "sensors", "model", "noise")


def _route(half: np.ndarray, margin: float) -> list[tuple[float, float]]:
    """A walk around and across the room (refinement.yaml's, scaled to the venue)."""
    x, y = float(half[0] - margin), float(half[1] - margin)
    points = [(-x, -y), (x, -y), (x, y), (0.0, 0.0), (-x, y), (-x, -y), (x, y), (-x, y)]
    return [(round(a, 3), round(b, 3)) for a, b in points]


@dataclasses.dataclass
class _Order:
    """One operator command: its action and scene, the board, the floor places, whether
    only pairs of sensors matter (move_board), the sensor shown the board (show_board)."""

    action: str
    scene: str = ""
    board: Checkerboard | None = None
    places: int = 0
    pairs: bool = False
    shown: int = -1
    hold: float = 0.0  # seconds the board is held still at each place (0: the params')


class SimulatedOperator:
    """The ``operator`` command of a simulated site (see the module docstring).

    ``sensors`` lists the detector nodes as (name, scenario index) and ``uris`` their
    own sensor URIs (what ``people`` goes back to). :meth:`serve` answers the ``operator``
    command on a bus and switches the detector nodes to the operator's scenes.
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
        self.send: SendCommand | None = None
        self.params = params if params is not None else OPERATOR_PARAMS.create()
        self.log = logger
        self.action = "people"
        self.scene = ""
        self.options = dict(options or {})
        self.count = 0
        self.error = ""
        self.until = 0.0  # wall clock when the scene's placements are all made (0: none)
        self._lock = threading.Lock()

    def status_values(self) -> dict[str, str]:
        """For the site status: what the operator does, its scene, what went wrong, and
        when (wall clock, s) it will have made every placement of its scene ("" when
        it has none to make)."""
        until = f"{self.until:.3f}" if self.until else ""
        return {
            "operator": self.action,
            "operator.scene": self.scene,
            "operator.error": self.error,
            "operator.until": until,
        }

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
            from optrack.sim.scenario import load_scenario

            # its sensors' ids, without loading the renderer before the nodes start
            venue = load_scenario(str(site_params.scenario)).sensors.sensor_ids()
            ids = {sensor_id: k for k, sensor_id in enumerate(venue)}
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
    def serve(self, bus: Bus, send: SendCommand) -> None:
        """Answer ``operator`` commands on ``command/site``; ``send`` sends the detector
        nodes their ``sim_scene`` commands."""

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

        self.bus, self.send = bus, send
        bus.serve(bus.keys.command("site"), CommandRequest, answer)

    def command(self, args: dict[str, Any]) -> dict[str, Any]:
        """``{action, cols, rows, square, places, pairs, sensor, hold}`` -> ``{action, scene}``;
        the nodes restart on the scene in the background (their status ``sensor`` names
        the scene; a scene that cannot be made is ``operator.error`` in the site status).
        ``pairs`` (move_board): skip the placements facing one sensor (the extrinsics need
        pairs). ``sensor`` (show_board): the detector node whose intrinsics are wanted.
        ``hold``: seconds to hold the board still at each place (default
        ``sim_operator.hold_s``; longer where the nodes search their images slowly)."""
        action = str(args.get("action", ""))
        if action not in OPERATOR_ACTIONS:
            raise OperatorError(
                f"the simulated operator cannot '{action}'; ask one of "
                f"{', '.join(OPERATOR_ACTIONS)}."
            )
        if action == "status":
            return {"action": self.action, "scene": self.scene, "actions": list(OPERATOR_ACTIONS)}
        order = _Order(action, pairs=bool(args.get("pairs", False)))
        if action == "show_board":
            names = {name: index for name, index in self.sensors}
            order.shown = names.get(str(args.get("sensor", "")), -1)
            if order.shown < 0:
                raise OperatorError(
                    f"the simulated operator shows the board to one of the site's sensors "
                    f"({', '.join(names)}); got {args.get('sensor')!r}."
                )
        if action in ("move_board", "show_board", "lay_board"):
            order.board = self._board(args)
        order.places = int(args.get("places", self.params.floor_places))
        try:
            order.hold = float(args.get("hold", 0.0) or 0.0)
        except (TypeError, ValueError):
            raise OperatorError(
                f"the simulated operator holds the board for a number of seconds; got "
                f"hold={args.get('hold')!r}."
            ) from None
        if not 0.0 <= order.hold <= 60.0:
            raise OperatorError(
                f"the simulated operator holds the board 0 to 60 s at a place; got {order.hold:g}."
            )
        if action == "lay_board" and not 1 <= order.places <= 10:
            raise OperatorError(
                f"the operator lays the board at 1 to 10 places; got {order.places}."
            )
        with self._lock:
            self.count += 1
            order.scene = "" if action == "people" else f"operator-{self.count}-{action}"
            self.action, self.scene, self.error = action, order.scene, ""
            self.until = 0.0
        threading.Thread(target=self._prepare, args=(order,), daemon=True).start()
        return {"action": action, "scene": order.scene}

    def _board(self, args: Mapping[str, Any]) -> Checkerboard:
        """The board to carry: the command's, what it leaves out the site scenario's."""
        site = self.base.board
        given = {k: args[k] for k in ("cols", "rows", "square") if k in args}
        if site is not None:
            given = {"cols": site.cols, "rows": site.rows, "square": site.square, **given}
        try:
            board = Checkerboard(int(given["cols"]), int(given["rows"]), float(given["square"]))
        except KeyError as missing:
            raise OperatorError(
                f"the simulated operator needs the board's {missing.args[0]} (cols, rows, "
                "square): the site's scenario has no board."
            ) from None
        except (TypeError, ValueError):
            raise OperatorError(
                "the simulated operator needs cols and rows as whole numbers and square in "
                f"metres; got cols={given.get('cols')!r}, rows={given.get('rows')!r}, "
                f"square={given.get('square')!r}."
            ) from None
        board.require_asymmetric()
        return board

    def _prepare(self, order: _Order) -> None:
        try:
            uris = [""] * len(self.sensors) if order.action == "people" else self._scene_uris(order)
            with self._lock:
                if self.scene != order.scene:  # a newer command came meanwhile
                    return
            self._switch(uris)
        except Exception as error:
            sentence = (
                str(error) if isinstance(error, UserError) else f"{type(error).__name__}: {error}"
            )
            self.log.error(
                "the simulated operator could not prepare '%s': %s", order.action, sentence
            )
            with self._lock:
                if self.scene == order.scene:
                    self.error = sentence
            return
        self.log.info("simulated operator: %s", order.action)

    def _switch(self, uris: list[str]) -> None:
        """Each detector node reads its sensor of the scene from its next frame ("": its
        own sensor again). Every node is asked even when one does not answer."""
        assert self.bus is not None and self.send is not None
        problems = []
        timeout = float(self.params.command_timeout_s)
        for (name, _), uri in zip(self.sensors, uris, strict=True):
            try:
                self.send(self.bus, name, "sim_scene", {"uri": uri}, timeout)
            except UserError as error:
                problems.append(str(error))
        if problems:
            raise OperatorError(problems[0])

    def _scene_uris(self, order: _Order) -> list[str]:
        """Write the order's scene (the site's scenario with the operator in it) and the
        sim:// URI of each detector node's sensor of it."""
        from optrack.sim.scenario import BoardSpec, PeopleSpec
        from optrack.sim.venue import Venue

        p, action, board = self.params, order.action, order.board
        if action == "walk":
            half = Venue(self.base.venue).half
            people = PeopleSpec(count=1, routes=[_route(half, float(p.walk_margin))])
            spec = None
        else:
            assert board is not None
            people = PeopleSpec(count=0)
            # Only the placements the page needs: the operator starts at the first of them.
            steps = "floor" if action == "lay_board" else "pairs" if order.pairs else "all"
            spec = BoardSpec(
                cols=board.cols,
                rows=board.rows,
                square=board.square,
                floor_placements=order.places if action == "lay_board" else 0,
                floor_per_sensor=int(p.floor_per_sensor) if action == "lay_board" else 0,
                intrinsics_sensor=order.shown,
                intrinsics_placements=int(p.intrinsics_places),
                steps=steps,
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
        path = self.run_dir / f"{order.scene}.yaml"
        # whole or not at all: detector nodes load the scene as soon as the file appears
        atomic_write_text(path, yaml.safe_dump(data, sort_keys=False))
        # at least the operator's own hold (longer when asked: slow nodes)
        own = {"show_board": p.intrinsics_hold_s, "lay_board": p.floor_hold_s}
        hold = max(order.hold, float(own.get(action, p.hold_s)))
        planned = self._check_steps(path, hold) if spec is not None else 0.0
        start = time.time() + float(p.lead_s)
        if planned:
            with self._lock:
                if self.scene == order.scene:
                    self.until = start + planned
        extra = "".join(f"&{k}={urllib.parse.quote(v)}" for k, v in sorted(self.options.items()))
        if spec is not None:
            extra += f"&hold={hold:g}"
        return [
            f"sim://{path}/{index}?seed={self.seed}{extra}&start={start:.3f}&id={name}"
            for name, index in self.sensors
        ]

    def _check_steps(self, path: Path, hold: float) -> float:
        """Refuse a scene whose operator has no placement to make (the board is seen by no
        two sensors together, nowhere on the floor, or not whole by the sensor it is shown
        to); else the seconds its placements take (the board held ``hold`` s at each)."""
        from optrack.sim.board import BOARD_PARAMS
        from optrack.sim.world import Simulation

        sensors = self.options.get("sensors")
        sim = Simulation(
            str(path),
            seed=self.seed,
            sensors=int(sensors) if sensors else None,
            sensor_model=self.options.get("model") or None,
            params={"sim_board": BOARD_PARAMS.create({"hold_seconds": hold})},
        )
        if sim.operator is None or not sim.operator.steps:
            raise OperatorError(
                "the simulated operator found no place for the board that the sensors see "
                "(together, on the floor, or whole); use a larger board or check the sensors' "
                "views."
            )
        return sim.operator.planned_seconds(sim.operator.start_point)
