"""A recording played back as a live camera, for detector nodes.

Unlike :class:`~optrack.sensors.playback.PlaybackSensor` (every frame, in
order), :class:`LiveReplay` behaves as a camera does: frames become due on
the node's clock at the pace they were recorded; ``read()`` waits for the
next one, and a consumer that fell behind gets the newest frame due (never a
queue of stale ones). The frames it skipped are never decoded (a 2-core
computer cannot afford to decode frames it will not use) and are counted in
:attr:`LiveReplay.skipped`. A frame is stamped with the instant it became
due (its capture instant), on the clock the node gives; a frame not due yet
is decoded while waiting for it (as a camera delivers a frame ready at
capture), and a frame already due is decoded after, so that this time counts
in the node's latency.

Every sensor of a recording keeps the recording's own time base, so the
sensors of one recording, replayed by separate nodes, show the same instant
of the scene at the same moment once :meth:`LiveReplay.lock_phase` ties their
loops to the site's (tracker's) clock. ``loop``:

- ``off``: the replay ends after the last frame;
- ``restart``: it starts again one frame period after its last frame (people
  jump back to where they were at the start);
- ``bounce``: it plays forwards, then backwards, and so on: nobody ever jumps,
  which is what a tracker fed by a looped recording needs (a jump ends every
  track and starts new ones).

Playback control (thread-safe: a node's commands call it from the bus's
thread): :meth:`LiveReplay.pause` freezes the playhead; :meth:`LiveReplay.step`
lets one frame through while paused (stamped when it is delivered, the
playhead moved to it); :meth:`LiveReplay.resume` goes on from the playhead;
:meth:`LiveReplay.set_speed` changes the pace from the playhead;
:meth:`LiveReplay.seek` moves a paused playhead. ``paused=True`` starts
paused at the recording's first instant (a site resumes all its replays at
once, so a recording played once starts in step on every sensor).
"""

from __future__ import annotations

import bisect
import math
import os
import threading
import time
from collections.abc import Callable, Iterable
from pathlib import Path

import msgspec

from optrack.recording import RecordingError, SensorInfo
from optrack.sensors.base import Sensor, SensorError
from optrack.sensors.playback import open_recording_sensor
from optrack.types import RGBDFrame

__all__ = ["LOOP_MODES", "LiveReplay"]

LOOP_MODES = ("off", "restart", "bounce")


def _loop_mode(loop: bool | str) -> str:
    if loop is True:
        return "restart"
    if loop is False:
        return "off"
    if loop not in LOOP_MODES:
        raise SensorError(f"replay loop must be one of {', '.join(LOOP_MODES)}; got '{loop}'.")
    return str(loop)


class LiveReplay(Sensor):
    """One sensor of a recording as a live camera (see the module docstring)."""

    def __init__(
        self,
        path: str | os.PathLike[str],
        sensor: str | None = None,
        *,
        loop: bool | str = False,
        speed: float = 1.0,
        clock: Callable[[], float] = time.time,
        streams: Iterable[str] | None = None,
        sensor_id: str | None = None,
        uri: str = "",
        paused: bool = False,
    ) -> None:
        self.recording, sensor = open_recording_sensor(path, sensor)
        if not speed > 0:
            raise SensorError(f"replay speed must be > 0; got {speed}.")
        self.recorded_id = sensor
        self.sensor_id = sensor_id or sensor
        self.uri = uri or f"file://{Path(path)}#{sensor}"
        self.loop = _loop_mode(loop)
        self.speed = float(speed)
        self.clock = clock
        self.streams = tuple(streams) if streams is not None else None
        self.entries = list(self.recording.index(sensor))
        if not self.entries:
            raise SensorError(
                f"sensor '{sensor}' of recording {self.recording.path} has no frames."
            )
        # The recording's time base (its first frame, any sensor), shared by all its sensors.
        spans = [self._span(s) for s in self.recording.sensor_ids]
        t0 = min(first for first, _ in spans if math.isfinite(first))
        end = max(last for _, last in spans if math.isfinite(last)) - t0
        self.times = [e.t - t0 for e in self.entries]
        n = len(self.times)
        own = self.times[-1] - self.times[0]
        self.period = own / (n - 1) if n > 1 else 1 / 30
        self.length = end + self.period  # one plain loop, s of recording time
        # One cycle of the loop: (recording time within the cycle, entry index).
        if self.loop == "bounce" and n > 1:
            back = [(2 * end - self.times[i], i) for i in range(n - 2, 0, -1)]
            cycle = [(t, i) for i, t in enumerate(self.times)] + back
            self.cycle_length = 2 * end
        else:
            cycle = [(t, i) for i, t in enumerate(self.times)]
            self.cycle_length = self.length
        self.cycle_times = [t for t, _ in cycle]
        self.cycle_index = [i for _, i in cycle]
        self.skipped = 0
        self.frames = 0
        self._epoch: float | None = None
        self._next = 0  # index (over all cycles) of the next frame not yet returned
        self._start_paused = paused
        self._paused_at: float | None = None  # node clock when paused (None: playing)
        self._steps = 0  # frames asked for by step() and not read yet
        #: A frame already older than this when read() is called is skipped for the next one
        #: (None: always the newest due): fresher frames, fewer of them.
        self.max_age_s: float | None = None
        self._seeks = 0
        self._control = threading.Condition()  # an RLock inside

    def _span(self, sensor: str) -> tuple[float, float]:
        """First and last stamps of a sensor of the recording (inf when it has none)."""
        if sensor == self.recorded_id and getattr(self, "entries", None):
            return self.entries[0].t, self.entries[-1].t
        first = last = math.inf
        for entry in self.recording.index(sensor):
            if first == math.inf:
                first = entry.t
            last = entry.t
        return first, last

    @property
    def info(self) -> SensorInfo:
        recorded = self.recording.sensors[self.recorded_id]
        return msgspec.structs.replace(recorded, id=self.sensor_id, uri=self.uri)

    @property
    def fps(self) -> float:
        return self.speed / self.period

    def open(self) -> None:
        with self._control:
            if self._epoch is None:
                self._epoch = self.clock()
                if self._start_paused:
                    self._paused_at = self._epoch

    def lock_phase(self, offset_s: float = 0.0) -> None:
        """Tie a looping replay to the site clock (``node clock + offset_s``): the cycle
        starts at every multiple of its length on that clock, so every sensor of the
        recording, wherever it is replayed, shows the same instant of the scene. The next
        frame is the newest one due (nothing counted as skipped)."""
        if self.loop == "off" or self._start_paused:  # a paused start waits for resume()
            self.open()
            return
        now = self.clock()
        cycle = self.cycle_length / self.speed
        self._epoch = math.floor((now + offset_s) / cycle) * cycle - offset_s
        self._next = max(0, self._last_due(now))

    def close(self) -> None:
        with self._control:
            self._epoch = None
            self._next = 0
            self._control.notify_all()

    # ------------------------------------------------------------ control
    @property
    def paused(self) -> bool:
        return self._paused_at is not None

    @property
    def held(self) -> bool:
        """Paused with no step asked for: ``read()`` would wait."""
        return self._paused_at is not None and self._steps == 0

    def wait_unheld(self, timeout: float) -> bool:
        """Wait up to ``timeout`` s for a step or a resume; False if still held."""
        with self._control:
            return self._control.wait_for(lambda: not self.held, timeout)

    def position(self) -> float:
        """The playhead in recording time (s since the recording's first frame)."""
        self.open()
        with self._control:
            assert self._epoch is not None
            now = self._paused_at if self._paused_at is not None else self.clock()
            within = ((now - self._epoch) * self.speed) % self.cycle_length
            if self.loop == "off":
                within = (now - self._epoch) * self.speed
            elif within > self.length:  # bounce: on the way back
                within = self.cycle_length - within
            return min(max(within, 0.0), self.length)

    def pause(self) -> None:
        """Freeze the playhead: no frame is due until :meth:`step` or :meth:`resume`."""
        self.open()
        with self._control:
            if self._paused_at is None:
                self._paused_at = self.clock()

    def resume(self) -> None:
        """Go on from the playhead at the current speed."""
        self.open()
        with self._control:
            if self._paused_at is not None:
                assert self._epoch is not None
                self._epoch += self.clock() - self._paused_at
                self._paused_at = None
                self._steps = 0
                self._start_paused = False
            self._control.notify_all()

    def step(self) -> None:
        """While paused, let the next frame through (once per call)."""
        with self._control:
            if self._paused_at is None:
                raise SensorError(f"{self.uri} is playing; pause it before stepping.")
            self._steps += 1
            self._control.notify_all()

    def set_speed(self, speed: float) -> None:
        """Play ``speed`` times the recorded pace from the playhead on."""
        if not speed > 0:
            raise SensorError(f"replay speed must be > 0; got {speed}.")
        self.open()
        with self._control:
            assert self._epoch is not None
            now = self._paused_at if self._paused_at is not None else self.clock()
            played = (now - self._epoch) * self.speed
            self.speed = float(speed)
            self._epoch = now - played / self.speed

    def seek(self, played: float) -> None:
        """Move a paused playhead to ``played`` s of recording time since the replay began
        (over loops: the ``played`` of :meth:`playhead`). As a video player shows the picture
        at a seek, the frame at the new playhead is delivered once, unless it is the frame
        last delivered (a node that lagged behind its peers is then shown the same instant
        as they are); the frame after it comes with the next step."""
        self.open()
        with self._control:
            if self._paused_at is None:
                raise SensorError(f"{self.uri} is playing; pause it before seeking.")
            self._epoch = self._paused_at - played / self.speed
            at = self._last_due(self._paused_at)
            if at >= 0 and at != self._next - 1:
                self._next = at
                self._steps += 1
                self._control.notify_all()
            else:
                self._next = at + 1
            self._seeks += 1

    def playhead(self) -> float:
        """Recording time played since the replay began, s (growing over loops)."""
        self.open()
        with self._control:
            assert self._epoch is not None
            now = self._paused_at if self._paused_at is not None else self.clock()
            return (now - self._epoch) * self.speed

    def _time(self, k: int) -> float:
        """Recording time of frame k (over cycles) since the replay began, s."""
        loops, i = divmod(k, len(self.cycle_times))
        return loops * self.cycle_length + self.cycle_times[i]

    def _due(self, k: int) -> float:
        """Due time of frame k (over cycles), on the node's clock."""
        assert self._epoch is not None
        loops, i = divmod(k, len(self.cycle_times))
        return self._epoch + (loops * self.cycle_length + self.cycle_times[i]) / self.speed

    def _last_due(self, now: float) -> int:
        """Index of the newest frame due at ``now`` (-1 before the first)."""
        assert self._epoch is not None
        elapsed = (now - self._epoch) * self.speed
        loops, within = divmod(elapsed, self.cycle_length)
        i = bisect.bisect_right(self.cycle_times, within + 1e-9) - 1
        return int(loops) * len(self.cycle_times) + i

    def read(self) -> RGBDFrame | None:
        self.open()
        n = len(self.cycle_times)
        with self._control:
            self._control.wait_for(lambda: not self.held or self._epoch is None)
            if self._epoch is None:  # closed while paused
                return None
            stepping = self._paused_at is not None
            if stepping:  # paused: the next frame, now; the playhead moves to it
                k = self._next
                self._steps -= 1
                self._epoch = self._paused_at - self._time(k) / self.speed
            else:
                now = self.clock()
                k = max(self._next, self._last_due(now))
                if self.max_age_s is not None and now - self._due(k) > self.max_age_s:
                    k += 1  # too old already: wait for the next frame (decoded meanwhile)
            seeks = self._seeks
        if self.loop == "off" and k >= n:
            return None
        # Decode first: a frame not due yet is ready when it is (as a camera delivers it).
        entry = self.entries[self.cycle_index[k % n]]
        try:
            if self.streams is None:
                frame = self.recording.load(self.recorded_id, entry)
            else:
                frame = self.recording.load(self.recorded_id, entry, self.streams)
        except RecordingError as error:
            raise SensorError(str(error)) from None
        due = self.clock() if stepping else self._due(k)
        wait = due - self.clock()
        if wait > 0:
            time.sleep(wait)
        with self._control:
            if not stepping and self._paused_at is not None and due > self._paused_at:
                return self.read()  # paused before this frame was captured: not delivered
            self.skipped += max(0, k - self._next)
            if self._seeks == seeks:  # a seek meanwhile chose the next frame itself
                self._next = k + 1
        frame.sensor_id = self.sensor_id
        frame.timestamp = due
        frame.seq = k
        self.frames += 1
        return frame

    def __repr__(self) -> str:
        return f"LiveReplay({self.uri!r})"
