"""A recording played back as a live camera, for detector nodes.

Unlike :class:`~optrack.sensors.playback.PlaybackSensor` (every frame, in
order), :class:`LiveReplay` behaves as a camera does: frames become due on
the node's clock at the pace they were recorded; ``read()`` waits for the
next one, and a consumer that fell behind gets the newest frame due. The
frames it skipped are never decoded (a 2-core computer cannot afford to
decode frames it will not use) and are counted in :attr:`LiveReplay.skipped`.
A frame is stamped with the instant it became due (its capture instant), on
the clock the node gives; a frame not due yet is decoded while waiting for it
(as a camera delivers a frame ready at capture), and a frame already due is
decoded after, so that this time counts in the node's latency. With ``loop`` the recording starts again at
its end, one frame period after its last frame.
"""

from __future__ import annotations

import bisect
import os
import time
from collections.abc import Callable, Iterable
from pathlib import Path

import msgspec

from optrack.recording import RecordingError, SensorInfo
from optrack.sensors.base import Sensor, SensorError
from optrack.sensors.playback import open_recording_sensor
from optrack.types import RGBDFrame

__all__ = ["LiveReplay"]


class LiveReplay(Sensor):
    """One sensor of a recording as a live camera (see the module docstring)."""

    def __init__(
        self,
        path: str | os.PathLike[str],
        sensor: str | None = None,
        *,
        loop: bool = False,
        speed: float = 1.0,
        clock: Callable[[], float] = time.time,
        streams: Iterable[str] | None = None,
        sensor_id: str | None = None,
        uri: str = "",
    ) -> None:
        self.recording, sensor = open_recording_sensor(path, sensor)
        if not speed > 0:
            raise SensorError(f"replay speed must be > 0; got {speed}.")
        self.recorded_id = sensor
        self.sensor_id = sensor_id or sensor
        self.uri = uri or f"file://{Path(path)}#{sensor}"
        self.loop = loop
        self.speed = float(speed)
        self.clock = clock
        self.streams = tuple(streams) if streams is not None else None
        self.entries = list(self.recording.index(sensor))
        if not self.entries:
            raise SensorError(
                f"sensor '{sensor}' of recording {self.recording.path} has no frames."
            )
        self.times = [e.t - self.entries[0].t for e in self.entries]
        period = (self.times[-1] / (len(self.times) - 1)) if len(self.times) > 1 else 1 / 30
        self.period = period
        self.length = self.times[-1] + period  # one loop, s of recording time
        self.skipped = 0
        self.frames = 0
        self._epoch: float | None = None
        self._next = 0  # index (over all loops) of the next frame not yet returned

    @property
    def info(self) -> SensorInfo:
        recorded = self.recording.sensors[self.recorded_id]
        return msgspec.structs.replace(recorded, id=self.sensor_id, uri=self.uri)

    @property
    def fps(self) -> float:
        return self.speed / self.period

    def open(self) -> None:
        if self._epoch is None:
            self._epoch = self.clock()

    def close(self) -> None:
        self._epoch = None
        self._next = 0

    def _due(self, k: int) -> float:
        """Due time of frame k (over loops), on the node's clock."""
        assert self._epoch is not None
        loops, i = divmod(k, len(self.entries))
        return self._epoch + (loops * self.length + self.times[i]) / self.speed

    def _last_due(self, now: float) -> int:
        """Index of the newest frame due at ``now`` (-1 before the first)."""
        assert self._epoch is not None
        elapsed = (now - self._epoch) * self.speed
        loops, within = divmod(elapsed, self.length)
        i = bisect.bisect_right(self.times, within + 1e-9) - 1
        return int(loops) * len(self.entries) + i

    def read(self) -> RGBDFrame | None:
        self.open()
        n = len(self.entries)
        k = max(self._next, self._last_due(self.clock()))
        if not self.loop and k >= n:
            return None
        # Decode first: a frame not due yet is ready when it is (as a camera delivers it).
        entry = self.entries[k % n]
        try:
            if self.streams is None:
                frame = self.recording.load(self.recorded_id, entry)
            else:
                frame = self.recording.load(self.recorded_id, entry, self.streams)
        except RecordingError as error:
            raise SensorError(str(error)) from None
        wait = self._due(k) - self.clock()
        if wait > 0:
            time.sleep(wait)
        self.skipped += k - self._next
        frame.sensor_id = self.sensor_id
        frame.timestamp = self._due(k)
        frame.seq = k
        self._next = k + 1
        self.frames += 1
        return frame

    def __repr__(self) -> str:
        return f"LiveReplay({self.uri!r})"
