"""A simulated RGB-D sensor: one sensor of a simulated venue, as a :class:`Sensor`.

``SimulatedSensor("mixed", 1)`` is sensor 1 of the ``mixed`` scenario. In
real time (the default) ``read()`` waits until each frame is due on the wall
clock and stamps it with wall-clock seconds, like a camera; a consumer that
falls behind misses frames, as with a camera. With ``real_time=False`` it
renders frames as fast as asked and stamps them with simulated seconds
(recording, tests). Sensors of one venue in different processes agree on
where everyone is when they share the seed and ``start_time`` (the wall
clock time of the simulation's t = 0).

The one thing a camera cannot do: :meth:`SimulatedSensor.truth` gives the
ground truth at the last frame's capture time.

URI: ``sim://SCENARIO/N?seed=0&people=5&sensors=3&model=kinect1&seconds=60
&realtime=false&noise=false&start=1700000000.0&id=cam0&hold=5&loop=true`` (all optional;
``hold``: seconds the board operator holds the board still at each place; ``loop``: at
the end of ``seconds`` the venue starts again from its beginning, on every sensor that
shares ``start`` at the same instant, and each loop ends as it began: people walk back
to where they started, :mod:`optrack.sim.venue_loop`);
``sim:///abs/path/scenario.yaml/N`` for a scenario file. Importing this module
registers the scheme with :func:`optrack.sensors.uri.register_scheme`, so that
:func:`optrack.sensors.open_sensor` opens ``sim://`` URIs from then on.
"""

from __future__ import annotations

import math
import time
import urllib.parse
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import msgspec

from optrack.errors import UserError
from optrack.params import Params
from optrack.recording.format import GroundTruth, SensorInfo
from optrack.sensors.base import Sensor, SensorError
from optrack.sensors.uri import SensorURI, register_scheme
from optrack.sim.scenario import Scenario, load_scenario
from optrack.types import RGBDFrame

if TYPE_CHECKING:  # the renderer (Open3D) loads with the first sensor, not with the scheme
    from optrack.sim.world import WorldState

__all__ = ["SimulatedSensor"]

_TRUE = {"1", "true", "yes", "on"}
_FALSE = {"0", "false", "no", "off"}


def _operator_params(hold_seconds: float | None) -> dict | None:
    """``hold``: how long the scenario's board operator holds the board still at each
    place (sim_board.hold_seconds); None keeps the default."""
    if hold_seconds is None:
        return None
    from optrack.sim.board import BOARD_PARAMS

    return {"sim_board": BOARD_PARAMS.create({"hold_seconds": hold_seconds})}


def parse_sim_uri(text: str) -> tuple[str, int, dict[str, Any]]:
    """The scenario, sensor number and :class:`SimulatedSensor` options of
    ``sim://SCENARIO/N?option=value&...`` (see the module docstring)."""
    parsed = urllib.parse.urlsplit(text)
    if parsed.scheme != "sim":
        raise SensorError(f"'{text}' is not a sim:// URI; write sim://SCENARIO/N.")
    # sim:///abs/path/scenario.yaml/N names a scenario file by its absolute path.
    absolute = not parsed.netloc and parsed.path.startswith("/")
    target = (parsed.netloc + parsed.path).strip("/")
    if absolute:
        target = "/" + target
    scenario, _, number = target.rpartition("/")
    if not scenario or not number.isdigit():
        raise SensorError(
            f"sensor URI '{text}' must be sim://SCENARIO/N with N the sensor number (0, 1, ...)."
        )
    options = dict(urllib.parse.parse_qsl(parsed.query, keep_blank_values=True))
    known = {
        "seed",
        "people",
        "sensors",
        "model",
        "seconds",
        "hold",
        "realtime",
        "noise",
        "start",
        "id",
        "loop",
    }
    unknown = sorted(set(options) - known)
    if unknown:
        raise SensorError(
            f"sensor URI '{text}' has unknown option '{unknown[0]}' "
            f"(known: {', '.join(sorted(known))})."
        )

    def number_of(name: str, kind: type) -> int | float | None:
        if name not in options:
            return None
        try:
            value = kind(options[name])
        except ValueError:
            what = "a whole number" if kind is int else "a number"
            raise SensorError(
                f"sensor URI '{text}': {name} must be {what}; got '{options[name]}'."
            ) from None
        if kind is float and not math.isfinite(value):
            raise SensorError(f"sensor URI '{text}': {name} must be finite.")
        return value

    def flag(name: str, default: bool) -> bool:
        value = options.get(name)
        if value is None:
            return default
        if value.lower() in _TRUE:
            return True
        if value.lower() in _FALSE:
            return False
        raise SensorError(f"sensor URI '{text}': {name} must be true or false; got '{value}'.")

    return (
        scenario,
        int(number),
        dict(
            seed=int(number_of("seed", int) or 0),
            people=number_of("people", int),  # type: ignore[arg-type]
            sensors=number_of("sensors", int),  # type: ignore[arg-type]
            sensor_model=options.get("model"),
            seconds=number_of("seconds", float),
            hold_seconds=number_of("hold", float),
            real_time=flag("realtime", True),
            noise=flag("noise", True),
            start_time=number_of("start", float),
            sensor_id=options.get("id") or None,
            uri=text,
            loop=flag("loop", False),
        ),
    )


class SimulatedSensor(Sensor):
    """Sensor ``index`` of a simulated scenario (see the module docstring)."""

    def __init__(
        self,
        scenario: str | Scenario = "mixed",
        index: int = 0,
        *,
        seed: int = 0,
        people: int | None = None,
        sensors: int | None = None,
        sensor_model: str | None = None,
        seconds: float | None = None,
        hold_seconds: float | None = None,
        real_time: bool = True,
        noise: bool = True,
        start_time: float | None = None,
        sensor_id: str | None = None,
        uri: str = "",
        clock: object = time,
        loop: bool = False,
    ) -> None:
        from optrack.sim.world import Simulation

        self._make = lambda: Simulation(
            scenario,
            seed=seed,
            people=people,
            sensors=sensors,
            sensor_model=sensor_model,
            seconds=seconds,
            params=_operator_params(hold_seconds),
        )
        if loop:  # each loop ends as it began (optrack.sim.venue_loop): no jump
            from optrack.sim.venue_loop import close_loop

            make = self._make
            self._make = lambda: close_loop(make())
        self.simulation = self._make()
        if loop and not real_time:
            raise SensorError("a simulated sensor loops in real time only (realtime=true).")
        self.loop = loop
        count = len(self.simulation.sensors)
        if not 0 <= index < count:
            raise SensorError(
                f"scenario '{self.simulation.scenario.name}' has {count} sensor(s) (0-{count - 1}); "
                f"sensor {index} does not exist, pick one of those or add sensors."
            )
        self.index = index
        self.real_time = real_time
        self.noise = noise
        self.start_time = start_time
        self._sensor = self.simulation.sensors[index]
        self._id = sensor_id or self._sensor.id
        self.uri = uri or self._sensor.uri
        self._clock = clock
        self._next = 0
        self._epoch: float | None = None
        self._state: WorldState | None = None
        self._count = self.simulation.frame_count(index)

    # ------------------------------------------------------------ creation
    @classmethod
    def from_uri(cls, text: str) -> SimulatedSensor:
        """A sensor from ``sim://SCENARIO/N?option=value&...`` (see the module docstring)."""
        scenario, index, options = parse_sim_uri(text)
        return cls(scenario, index, **options)

    # ----------------------------------------------------------- interface
    @property
    def info(self) -> SensorInfo:
        info = self._sensor.info
        if self._id != info.id or self.uri != info.uri:
            info = msgspec.structs.replace(info, id=self._id, uri=self.uri)
        return info

    @property
    def fps(self) -> float:
        return self._sensor.model.fps

    @property
    def host_clock(self) -> bool:  # type: ignore[override]
        """(added) In real time on the wall clock, frames carry their capture time on this
        computer's clock (rendering one takes a while after it: a node stamping arrivals
        would stamp each sensor late by its own rendering time). A simulated camera with
        a clock offset of its own is stamped on arrival, as an unsynchronised camera is."""
        return self.real_time and self._clock is time and self._sensor.clock_offset == 0.0

    def open(self) -> None:
        if self._epoch is None:
            self._epoch = self.start_time if self.start_time is not None else self._clock.time()

    def read(self) -> RGBDFrame | None:
        self.open()
        sensor, sim = self._sensor, self.simulation
        if self.real_time:
            elapsed = self._clock.time() - self._epoch
            # A consumer that fell behind gets the latest frame due, as from a camera.
            due = math.floor((elapsed - sensor.phase) * sensor.model.fps + 1e-9)
            self._next = max(self._next, min(due, self._count))
        n = self._next
        if n >= self._count and self.loop:
            # Again from the beginning: the same venue, a loop later on the clock.
            self._epoch += self.simulation.seconds
            self.simulation, self._next = self._make(), 0
            self._sensor = self.simulation.sensors[self.index]
            return self.read()
        if n >= self._count:
            return None
        t = sensor.frame_time(n)
        if self.real_time:
            wait = self._epoch + t - self._clock.time()
            if wait > 0:
                self._clock.sleep(wait)
        self._state = sim.snapshot(t)
        frame = sim.frame(self.index, n, self._state, noise=self.noise)
        if self.real_time:
            frame.timestamp += self._epoch
        frame.sensor_id = self._id
        self._next = n + 1
        return frame

    def truth(self, visibility: bool = True) -> GroundTruth | None:
        """Ground truth at the last frame's capture time (world clock), or None before
        the first frame. Its ``t`` is simulated seconds (plus ``start_time`` in real time)."""
        if self._state is None:
            return None
        truth = self.simulation.truth(self._state, visibility=visibility)
        if self.real_time and self._epoch is not None:
            truth = msgspec.structs.replace(truth, t=truth.t + self._epoch)
        return truth

    def __repr__(self) -> str:
        return f"SimulatedSensor({self.uri!r})"


def _open(uri: SensorURI, config: Mapping[str, Params]) -> SimulatedSensor:
    return SimulatedSensor.from_uri(uri.text)


def _identify(uri: SensorURI) -> str | None:
    """The id sensor N of a simulated venue reports (``kinect2_1``), read from its
    scenario without simulating it; None when the URI or the scenario cannot tell."""
    try:
        scenario, index, options = parse_sim_uri(uri.text)
        spec = load_scenario(scenario).sensors
        ids = spec.sensor_ids(options["sensors"], options["sensor_model"])
    except UserError:
        return None
    return ids[index] if 0 <= index < len(ids) else None


register_scheme("sim", "sim://SCENARIO/N", _open, _identify)
