"""Play a recording back as a sensor (``file://<recording>[#sensor]``)."""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from pathlib import Path

import msgspec

from optrack.params import Param, Params, Schema, register
from optrack.recording import IndexEntry, Recording, RecordingError, SensorInfo
from optrack.sensors.base import Sensor, SensorError
from optrack.types import RGBDFrame

__all__ = ["PLAYBACK_PARAMS", "PlaybackSensor", "open_recording_sensor"]

PLAYBACK_PARAMS = register(
    Schema(
        "playback",
        [
            Param(
                "realtime",
                False,
                help="Deliver frames at the pace they were recorded (off: as fast as they load).",
            ),
            Param(
                "speed",
                1.0,
                min=0.01,
                max=100.0,
                step=0.01,
                help="Real-time pace multiplier (2 plays twice as fast).",
            ),
            Param(
                "loop",
                False,
                help="Start again at the end (times keep increasing across loops).",
            ),
        ],
        help="Recordings played back as sensors (file:// URIs).",
    )
)


def open_recording_sensor(
    path: str | os.PathLike[str], sensor: str | None
) -> tuple[Recording, str]:
    """Open a recording and pick one of its sensors (the only one when ``sensor`` is None),
    with one sentence when the recording or the sensor is not there."""
    try:
        recording = Recording(path)
    except RecordingError as error:
        raise SensorError(str(error)) from None
    ids = recording.sensor_ids
    if sensor is None:
        if len(ids) != 1:
            raise SensorError(
                f"recording {recording.path} has sensors {', '.join(ids)}; name one, "
                f"e.g. file://{recording.path}#{ids[0]}."
            )
        sensor = ids[0]
    if sensor not in recording.sensors:
        raise SensorError(
            f"recording {recording.path} has no sensor '{sensor}' (it has: "
            f"{', '.join(ids)}); pick one of those after '#'."
        )
    return recording, sensor


class PlaybackSensor(Sensor):
    """One sensor of a recording, frame by frame in time order.

    ``sensor`` picks the recording's sensor; it may be left out when the
    recording has only one; ``sensor_id`` renames it. Frames keep their
    recorded times (shifted by the recording's length on each loop).
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        sensor: str | None = None,
        params: Params | None = None,
        uri: str = "",
        sensor_id: str | None = None,
    ) -> None:
        self.params = params if params is not None else PLAYBACK_PARAMS.create()
        self.recording, sensor = open_recording_sensor(path, sensor)
        self.recorded_id = sensor
        self.sensor_id = sensor_id or sensor
        self.uri = uri or f"file://{Path(path)}#{sensor}"
        self.frames = 0
        self._entries: Iterator[IndexEntry] | None = None
        self._loop_offset = 0.0
        self._first_t: float | None = None
        self._last_t: float | None = None
        self._period = 0.0
        self._started: float | None = None

    @property
    def info(self) -> SensorInfo:
        recorded = self.recording.sensors[self.recorded_id]
        return msgspec.structs.replace(recorded, id=self.sensor_id, uri=self.uri)

    def open(self) -> None:
        if self._entries is None:
            self._entries = self.recording.index(self.recorded_id)

    def close(self) -> None:
        self._entries = None
        self._started = None
        self._loop_offset = 0.0

    def read(self) -> RGBDFrame | None:
        self.open()
        assert self._entries is not None
        entry = next(self._entries, None)
        if entry is None:
            if not self.params.loop or self._first_t is None or self._last_t is None:
                return None
            # Next loop: continue one frame period after the last frame.
            self._loop_offset += self._last_t - self._first_t + (self._period or 1e-3)
            self._entries = self.recording.index(self.recorded_id)
            entry = next(self._entries, None)
            if entry is None:
                return None
        if self._first_t is None:
            self._first_t = entry.t
        elif self._last_t is not None and self._loop_offset == 0.0 and not self._period:
            self._period = entry.t - self._last_t
        if self._loop_offset == 0.0:
            self._last_t = entry.t
        try:
            frame = self.recording.load(self.recorded_id, entry)
        except RecordingError as error:
            raise SensorError(str(error)) from None
        frame.sensor_id = self.sensor_id
        frame.timestamp = entry.t + self._loop_offset
        self._pace(frame.timestamp)
        self.frames += 1
        return frame

    def _pace(self, t: float) -> None:
        if not self.params.realtime:
            return
        now = time.monotonic()
        if self._started is None:
            self._started = now - (t - (self._first_t or t)) / float(self.params.speed)
        due = self._started + (t - (self._first_t or t)) / float(self.params.speed)
        if due > now:
            time.sleep(due - now)
