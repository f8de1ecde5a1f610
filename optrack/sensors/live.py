"""What every live camera shares: timestamps, mode choice, reading with reconnection.

A :class:`LiveSensor` subclass opens its device in ``_open_device``, frees
it in ``_close_device`` and returns the next frame (or None on a timeout)
from ``_grab``. This class turns a camera that stops sending frames (pulled
out, powered off, driver error) into a reconnection loop, and gives up with
one sentence when it does not come back in time. ``close()`` may be called
from another thread while ``read()`` waits; ``read()`` then returns None.
"""

from __future__ import annotations

import abc
import dataclasses
import logging
import math
import re
import threading
import time
from collections.abc import Iterable, Sequence

from optrack.params import Param, Params, Schema
from optrack.recording.format import SensorInfo
from optrack.sensors.base import Sensor, SensorError
from optrack.types import RGBDFrame

__all__ = ["DeviceClock", "DeviceLost", "LiveSensor", "Mode", "live_params", "nearest_mode"]

log = logging.getLogger(__name__)

TIMESTAMP_MODES = ("anchored", "device", "host")


def live_params() -> list[Param]:
    """Parameters every live camera has (each backend's schema includes them)."""
    return [
        Param(
            "timestamps",
            "anchored",
            choices=TIMESTAMP_MODES,
            help=(
                "Frame times: 'anchored' = the device clock offset to the host clock at the first "
                "frame (even spacing, comparable across cameras); 'device' = the device clock; "
                "'host' = the host clock when the frame arrived."
            ),
        ),
        Param(
            "max_clock_skew",
            1.0,
            min=0.01,
            max=60.0,
            step=0.01,
            unit="s",
            help="Anchored times that fall this far behind the host clock are anchored again.",
        ),
        Param(
            "read_timeout",
            2.0,
            min=0.1,
            max=60.0,
            step=0.1,
            unit="s",
            help="A camera that sends no frame for this long counts as lost (unplugged).",
        ),
        Param(
            "reconnect_timeout",
            60.0,
            min=0.0,
            max=86400.0,
            step=1.0,
            unit="s",
            help="How long to keep trying to reopen a lost camera (0: give up at once).",
        ),
        Param(
            "reconnect_interval",
            1.0,
            min=0.05,
            max=60.0,
            step=0.05,
            unit="s",
            help="Pause between attempts to reopen a lost camera.",
        ),
    ]


class DeviceClock:
    """Turns device timestamps into frame times that never go back.

    Modes (see :func:`live_params`): ``anchored`` adds to the device time the
    offset to the host clock (``time.time()``) measured at the first frame,
    slews it down (a fiftieth of a period per frame) while frames arrive
    sooner than that offset allows, and
    measures it again after a reconnection or when the frame time falls more
    than ``max_skew`` behind the host clock; ``device`` keeps the device clock (shifted
    only to stay monotonic across a device reset); ``host`` uses the arrival
    time. ``period`` (s) is the spacing used when a reset must be bridged.
    """

    def __init__(self, mode: str = "anchored", period: float = 1 / 30, max_skew: float = 1.0):
        if mode not in TIMESTAMP_MODES:
            raise ValueError(f"timestamp mode must be one of {', '.join(TIMESTAMP_MODES)}.")
        self.mode = mode
        self.period = period
        self.max_skew = max_skew
        self.offset: float | None = None
        self.last = -math.inf
        self.anchors = 0

    def restart(self) -> None:
        """The device clock may start again from zero (device reopened)."""
        self.offset = None

    def stamp(self, device_time: float, now: float | None = None) -> float:
        """Frame time (s) of a frame with device time ``device_time`` (s), arriving ``now``."""
        now = time.time() if now is None else now
        if self.mode == "host":
            t = now
        else:
            if self.offset is None:
                self._anchor(device_time, now)
            t = device_time + self.offset  # type: ignore[operator]
            if self.mode == "anchored":
                latency = now - t
                if latency < 0:
                    # A frame cannot arrive before it was taken: the first frame's latency
                    # was larger than this one's. Slew towards the smaller offset, at most a
                    # fiftieth of a frame period per frame, so that spacing stays even.
                    step = max(latency, -self.period / 50.0)
                    self.offset += step  # type: ignore[operator]
                    t += step
                elif latency > self.max_skew:
                    self._anchor(device_time, now)
                    t = now
        if t <= self.last:
            # The device clock went back (reset) or the host clock stepped: bridge it.
            step = self.period if self.mode != "host" else 1e-6
            if self.mode != "host":
                self.offset = self.last + step - device_time
            t = self.last + step
        self.last = t
        return t

    def _anchor(self, device_time: float, now: float) -> None:
        self.anchors += 1
        self.offset = now - device_time if self.mode == "anchored" else 0.0


@dataclasses.dataclass(frozen=True)
class Mode:
    """A video mode a device offers: size (px), rate (Hz) and a pixel format."""

    width: int
    height: int
    fps: float
    format: object = None

    def __str__(self) -> str:
        return f"{self.width}x{self.height}@{self.fps:g}"


def nearest_mode(
    modes: Iterable[Mode], width: int, height: int, fps: float, formats: Sequence[object] = ()
) -> Mode | None:
    """The mode closest to the wanted one: pixel count first, then rate, then format order.

    Only modes whose format is in ``formats`` count (any when empty); an
    exact match always wins. None when no mode qualifies.
    """
    rank = {f: i for i, f in enumerate(formats)}
    candidates = [m for m in modes if not formats or m.format in rank]
    if not candidates:
        return None
    wanted = max(width * height, 1)

    def cost(mode: Mode) -> tuple[float, float, int, float]:
        size = abs(math.log(max(mode.width * mode.height, 1) / wanted))
        aspect = abs(mode.width * height - mode.height * width) / wanted
        return (round(size + aspect, 6), abs(mode.fps - fps), rank.get(mode.format, 0), -mode.fps)

    return min(candidates, key=cost)


class DeviceLost(Exception):
    """Raised by ``_grab`` when the device fails; the message says how."""


class LiveSensor(Sensor):
    """A camera with reconnection; subclasses talk to the device.

    ``params`` holds :func:`live_params` (and the backend's own). Counters:
    ``frames`` read, ``dropped`` (frames the device numbered but never
    delivered), ``reconnects``.
    """

    backend = "camera"
    #: sensor ids made from a serial start with this (``openni-1d27...``)
    id_prefix = "camera"

    #: the backend's parameter schema (its defaults when no ``params`` are given)
    schema: Schema | None = None
    #: the URI scheme the sensor is opened by (``openni://TARGET``)
    scheme = "camera"

    def __init__(
        self,
        target: str = "",
        params: Params | None = None,
        sensor_id: str | None = None,
        uri: str = "",
    ):
        if params is None:
            if self.schema is None:
                raise TypeError(f"{type(self).__name__} names no parameter schema")
            params = self.schema.create()
        self.target = target
        self.params = params
        self.uri = uri or f"{self.scheme}://{target}"
        self.requested_id = sensor_id
        self.serial = ""
        self._id: str | None = None
        self.frames = 0
        self.dropped = 0
        self.reconnects = 0
        self.clock = DeviceClock(str(params.timestamps), max_skew=float(params.max_clock_skew))
        self._info: SensorInfo | None = None
        self._opened = False
        self._lock = threading.RLock()
        self._closing = threading.Event()
        self._init_backend()

    # ----------------------------------------------------------- subclasses
    def _init_backend(self) -> None:
        """Set the backend's own state (nothing opened yet); raise SensorError when the
        backend's library is missing."""

    @abc.abstractmethod
    def _open_device(self) -> SensorInfo:
        """Open the device, start its streams; return its description. Raise SensorError."""

    @abc.abstractmethod
    def _close_device(self) -> None:
        """Stop and free the device; safe to call when it is already closed."""

    @abc.abstractmethod
    def _grab(self, timeout: float) -> RGBDFrame | None:
        """The next frame within ``timeout`` s, or None; raise DeviceLost on failure."""

    def describe(self) -> str:
        """How messages name this sensor."""
        return f"{self.backend} camera '{self.target or 'first attached'}'"

    @property
    def sensor_id(self) -> str:
        """The id frames carry: the one asked for, else from the serial (fixed at first open),
        at most 63 characters."""
        if self.requested_id:
            return self.requested_id
        if self._id is None:
            name = self.serial or self.target or "camera"
            slug = re.sub(r"[^A-Za-z0-9_.-]", "-", name).strip("-")
            return f"{self.id_prefix}-" + slug[: 62 - len(self.id_prefix)]
        return self._id

    # ------------------------------------------------------------ interface
    @property
    def info(self) -> SensorInfo:
        self.open()
        assert self._info is not None
        return self._info

    @property
    def is_open(self) -> bool:
        return self._opened

    def open(self) -> None:
        with self._lock:
            if self._opened:
                return
            self._closing.clear()
            self._info = self._open_device()
            self._opened = True

    def close(self) -> None:
        self._closing.set()
        # Wait for a read in progress (it returns within one grab slice).
        if not self._lock.acquire(timeout=float(self.params.read_timeout) + 5.0):
            log.warning("%s: a read did not finish; closing skipped.", self.describe())
            return
        try:
            if self._opened:
                self._opened = False
                self._close_device()
        finally:
            self._lock.release()

    def interrupt(self) -> None:
        """Make a ``read()`` waiting in another thread return None soon (``close()`` follows)."""
        self._closing.set()

    def read(self) -> RGBDFrame | None:
        with self._lock:
            if not self._opened:
                if self._closing.is_set():
                    return None  # closed, maybe from another thread: open() to read again
                self.open()
            while not self._closing.is_set():
                try:
                    frame = self._read_within_timeout()
                except DeviceLost as lost:
                    self._reconnect(str(lost))
                    continue
                if frame is not None:
                    self.frames += 1
                    return frame
            return None

    def __del__(self) -> None:
        try:
            if getattr(self, "_opened", False):
                self.close()
        except Exception:  # never raise from a finaliser
            pass

    # --------------------------------------------------------------- private
    def _read_within_timeout(self) -> RGBDFrame | None:
        """A frame, None when closing; DeviceLost after read_timeout without one."""
        timeout = float(self.params.read_timeout)
        waited = 0.0
        slice_s = min(0.25, timeout)
        while waited < timeout:
            if self._closing.is_set():
                return None
            started = time.monotonic()
            frame = self._grab(slice_s)
            if frame is not None:
                return frame
            waited += time.monotonic() - started
        raise DeviceLost(f"no frame for {timeout:g} s")

    def _reconnect(self, reason: str) -> None:
        limit = float(self.params.reconnect_timeout)
        try:
            self._close_device()
        except Exception as error:  # the device is gone; freeing may fail
            log.debug("%s: closing the lost device failed: %s", self.describe(), error)
        if limit <= 0:
            self._opened = False
            raise SensorError(
                f"{self.describe()} stopped ({reason}); check its cable and power "
                "(reconnection is off: reconnect_timeout is 0)."
            )
        log.warning(
            "%s lost (%s); trying to reopen it every %g s for %g s.",
            self.describe(),
            reason,
            float(self.params.reconnect_interval),
            limit,
        )
        deadline = time.monotonic() + limit
        last_error = ""
        while not self._closing.wait(float(self.params.reconnect_interval)):
            try:
                self._info = self._open_device()
            except Exception as error:  # any failure: try again until the deadline
                last_error = str(error)
            else:
                self.reconnects += 1
                self.clock.restart()
                log.warning("%s is back (reconnection %d).", self.describe(), self.reconnects)
                return
            if time.monotonic() >= deadline:
                self._opened = False
                if last_error:
                    log.warning("%s: last attempt to reopen it: %s", self.describe(), last_error)
                raise SensorError(
                    f"{self.describe()} was lost ({reason}) and did not come back within "
                    f"{limit:g} s; check its cable and power, then start again."
                )
