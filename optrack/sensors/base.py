"""The sensor interface: anything that yields :class:`~optrack.types.RGBDFrame`.

Nothing downstream may tell a simulated sensor, a recording and a camera
apart: they all open, read frames in time order, describe themselves with a
:class:`~optrack.recording.SensorInfo`, and close.
"""

from __future__ import annotations

import abc
from collections.abc import Iterator

from optrack.errors import UserError
from optrack.params import Param
from optrack.recording.format import SensorInfo
from optrack.types import RGBDFrame


def stream_mode_params(max_fps: int) -> list[Param]:
    """The mode a camera driver asks its device for (the nearest one it has is used)."""
    return [
        Param(
            "width",
            640,
            min=1,
            max=4096,
            step=1,
            unit="px",
            help="Depth image width wanted; the device's nearest mode is used.",
        ),
        Param(
            "height",
            480,
            min=1,
            max=4096,
            step=1,
            unit="px",
            help="Depth image height wanted; the device's nearest mode is used.",
        ),
        Param(
            "fps",
            30,
            min=1,
            max=max_fps,
            step=1,
            unit="Hz",
            help="Frame rate wanted; the device's nearest mode is used.",
        ),
    ]


class SensorError(UserError):
    """A sensor that cannot be opened or read (unplugged, busy, unknown URI)."""


class Sensor(abc.ABC):
    """One RGB-D source.

    ``read()`` blocks until the next frame and returns it, or returns None
    when the source has ended (a recording played to its end, a simulation
    past its duration). A live sensor that fails raises :class:`SensorError`
    with a sentence saying what to do. Sensors are context managers and
    iterables of frames.
    """

    uri: str = ""
    #: (added) True when ``read()`` stamps each frame with this computer's wall clock
    #: (``time.time()``) at its capture: a node then takes the capture time from the
    #: stamp, not from the frame's arrival.
    host_clock: bool = False

    @property
    @abc.abstractmethod
    def info(self) -> SensorInfo:
        """Id, model, intrinsics (and true pose when known) of this sensor."""

    @abc.abstractmethod
    def read(self) -> RGBDFrame | None:
        """The next frame, or None at the end of the source."""

    def open(self) -> None:  # noqa: B027 - optional hook
        """Acquire the device (called by ``__enter__``); idempotent."""

    def close(self) -> None:  # noqa: B027 - optional hook
        """Release the device; idempotent."""

    def __enter__(self) -> Sensor:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __iter__(self) -> Iterator[RGBDFrame]:
        while (frame := self.read()) is not None:
            yield frame
