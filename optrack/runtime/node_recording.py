"""Recording and playback on a site's detector nodes, driven by bus commands.

Node side (each detector node, on its own computer):

* :class:`NodeRecorder` answers ``record_start {folder}`` and ``record_stop``.
  It writes the frames its node reads with :class:`~optrack.recording.RecordingWriter`
  (``join=True``: the detector nodes of a computer write their sensors into one
  take folder, one manifest listing them all), on a thread of its own so that
  detection keeps its pace: frames wait in a queue of ``recorder.queue_frames``
  and are counted as dropped when it is full. Frames are stamped in tracker
  time, so the sensors of a take share one clock. Each frame's index line is
  written last, so a node that crashes loses nothing already written. Its
  status values: ``recording``, ``recording.folder``, ``recording.refused``
  (folders outside the site's data folder, ``node.data_folder``), ``recording.frames``,
  ``recording.bytes``, ``recording.seconds``, ``recording.dropped``,
  ``recording.error``.
* :class:`NodePlayback` answers ``playback {action: pause | resume | step |
  speed | seek | state}`` on a node whose sensor is a recording
  (:class:`~optrack.runtime.replay.LiveReplay`). Its status values:
  ``playback.paused``, ``playback.position_s``, ``playback.duration_s``,
  ``playback.speed``, ``playback.frame``, ``playback.waiting`` (started paused
  and not yet told to play).

Client side (the GUI, ``optrack run --recording``): :class:`SiteControl` sends
the same command to every detector node and turns refusals into sentences
naming the node. Pausing aligns every playhead on the furthest one, so a step
then gives each sensor its next frame at the same recording instant.
"""

from __future__ import annotations

import dataclasses
import errno
import logging
import queue
import socket
import threading
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import msgspec
import numpy as np

from optrack.errors import UserError
from optrack.net.bus import Bus
from optrack.params import Param, Params, Schema, register
from optrack.recording import RecordingWriter, SensorInfo
from optrack.runtime.node import CommandError, Node, send_command
from optrack.runtime.replay import LiveReplay
from optrack.types import RGBDFrame

__all__ = [
    "PLAYBACK_ACTIONS",
    "RECORDER_PARAMS",
    "NodePlayback",
    "NodeRecorder",
    "RecordingCommandError",
    "SiteControl",
]

log = logging.getLogger("optrack.runtime.recording")

RECORDER_PARAMS = register(
    Schema(
        "recorder",
        [
            Param(
                "queue_frames",
                60,
                min=1,
                max=1000,
                step=1,
                help="Frames a detector node holds for its recording thread; when the disk "
                "cannot keep up, further frames are left out of the recording and counted.",
            ),
            Param(
                "stop_wait_s",
                0.5,
                min=0.0,
                max=30.0,
                step=0.1,
                unit="s",
                help="How long a node waits for its recording to close before answering "
                "'record_stop' (it closes anyway; its status then shows the final counts).",
            ),
            Param(
                "hold_s",
                0.05,
                min=0.005,
                max=1.0,
                step=0.005,
                unit="s",
                help="A paused replay's node looks for a step, a resume or a stop this often.",
            ),
            Param(
                "min_speed",
                0.25,
                min=0.01,
                max=1.0,
                step=0.01,
                help="Slowest playback speed a node accepts (times the recorded pace).",
            ),
            Param(
                "max_speed",
                4.0,
                min=1.0,
                max=100.0,
                step=0.5,
                help="Fastest playback speed a node accepts (times the recorded pace).",
            ),
            Param(
                "command_timeout_s",
                5.0,
                min=0.1,
                max=60.0,
                step=0.1,
                unit="s",
                help="How long a client waits for each node to answer a recording or "
                "playback command.",
            ),
        ],
        help="Recording and playback of a site's sensors on their detector nodes.",
    )
)

PLAYBACK_ACTIONS = ("pause", "resume", "step", "speed", "seek", "state")


class RecordingCommandError(UserError):
    """A recording or playback command a node refuses."""


# ------------------------------------------------------------------ node side


class NodeRecorder:
    """A detector node's recording of the frames it reads (see the module docstring)."""

    def __init__(self, node: Node, info: SensorInfo, params: Params | None = None) -> None:
        self.node = node
        self.info = info
        self.params = params if params is not None else RECORDER_PARAMS.create()
        self.folder = ""
        self.frames = 0
        self.bytes = 0
        self.dropped = 0
        self.error = ""
        self.refused = 0  # record_start into a folder outside the site's data folder
        self._first_t: float | None = None
        self._last_t: float | None = None
        self._lock = threading.Lock()
        self._queue: queue.Queue[tuple[RGBDFrame, float] | None] = queue.Queue(
            int(self.params.queue_frames)
        )
        self._writer: RecordingWriter | None = None
        self._thread: threading.Thread | None = None
        node.add_command("record_start", self._start)
        node.add_command("record_stop", self._stop)

    @property
    def recording(self) -> bool:
        return self._writer is not None

    # ------------------------------------------------------------- commands
    def _start(self, args: dict[str, Any]) -> dict[str, Any]:
        folder = args.get("folder")
        if not isinstance(folder, str) or not folder.strip():
            raise RecordingCommandError(
                "record_start needs a folder (args: {'folder': PATH}); choose one."
            )
        with self._lock:
            if self._writer is not None:
                raise RecordingCommandError(
                    f"sensor '{self.info.id}' is already recording into {self.folder}; stop "
                    "that recording first."
                )
            path = self._inside_data_folder(folder)
            info = self.info
            pose = getattr(self.node, "world_T_camera", None)  # kept with the take
            if pose is not None:
                rows = np.asarray(pose, dtype=float).tolist()
                info = msgspec.structs.replace(info, world_T_camera=tuple(map(tuple, rows)))
            try:
                writer = RecordingWriter(
                    path, [info], join=True, source=f"optrack detector node '{self.node.name}'"
                )
            except OSError as error:
                raise RecordingCommandError(_os_sentence(error, path, self.info.id, 0)) from None
            self._writer = writer
            self.folder = str(path)
            self.frames = self.bytes = self.dropped = 0
            self.error = ""
            self._first_t = self._last_t = None
            self._queue = queue.Queue(int(self.params.queue_frames))
            self._thread = threading.Thread(
                target=self._write_loop, args=(writer, self._queue), name="recorder", daemon=True
            )
            self._thread.start()
        self.node.log.info("recording sensor '%s' into %s", self.info.id, path)
        return {"folder": str(path), "sensor": self.info.id, "host": socket.gethostname()}

    def _inside_data_folder(self, folder: str) -> Path:
        """``folder`` when it lies inside the site's data folder (``node.data_folder``);
        else the refusal, counted (``recording.refused``)."""
        path = Path(folder).expanduser()
        base = Path(str(self.node.node_params.data_folder)).expanduser()
        if not path.resolve().is_relative_to(base.resolve()):
            self.refused += 1
            raise RecordingCommandError(
                f"sensor '{self.info.id}' records only inside the site's data folder {base} "
                f"(node.data_folder), not into {path}; choose a folder there."
            )
        return path

    def _stop(self, args: dict[str, Any]) -> dict[str, Any]:
        thread = self.stop()
        if thread is not None:
            thread.join(float(self.params.stop_wait_s))
        return self.result()

    def stop(self) -> threading.Thread | None:
        """End the recording (the writer thread writes what is queued, then closes)."""
        with self._lock:
            writer, self._writer = self._writer, None
            thread = self._thread
        if writer is None:
            return None
        self._queue.put(None)  # after every frame already queued
        return thread

    def result(self) -> dict[str, Any]:
        closing = self._thread is not None and self._thread.is_alive()
        return {
            "sensor": self.info.id,
            "folder": self.folder,
            "frames": self.frames,
            "bytes": self.bytes,
            "seconds": self.seconds,
            "dropped": self.dropped,
            "closed": not closing and self._writer is None,
            "error": self.error,
        }

    # --------------------------------------------------------------- frames
    def offer(self, frame: RGBDFrame, stamp: float) -> None:
        """Queue a frame the node has read, stamped ``stamp`` (tracker time, s)."""
        if self._writer is None:
            return
        try:
            self._queue.put_nowait((frame, stamp))
        except queue.Full:
            self.dropped += 1

    def _write_loop(
        self, writer: RecordingWriter, frames: queue.Queue[tuple[RGBDFrame, float] | None]
    ) -> None:
        while True:
            item = frames.get()
            if item is None:
                break
            frame, stamp = item
            if self._last_t is not None:
                stamp = max(stamp, self._last_t)  # a clock-offset update must not go back
            copy = dataclasses.replace(frame, timestamp=stamp)
            try:
                writer.write(copy)
            except OSError as error:
                self._failed(_os_sentence(error, writer.path, self.info.id, self.frames))
                break
            except UserError as error:
                self._failed(f"recording of sensor '{self.info.id}' stopped: {error}")
                break
            self.frames = writer.frame_counts[self.info.id]
            self.bytes = writer.byte_counts[self.info.id]
            if self._first_t is None:
                self._first_t = stamp
            self._last_t = stamp
        try:
            writer.close()  # after a failure too: what was written stays readable
        except OSError as error:
            if not self.error:
                self._failed(_os_sentence(error, writer.path, self.info.id, self.frames))
        self.node.log.info(
            "recording of sensor '%s' closed: %d frames in %s",
            self.info.id,
            self.frames,
            self.folder,
        )

    def _failed(self, sentence: str) -> None:
        with self._lock:
            self._writer = None  # no further frames are queued; status says "not recording"
        self.error = sentence
        self.node.report_error(sentence)

    @property
    def seconds(self) -> float:
        if self._first_t is None or self._last_t is None:
            return 0.0
        return self._last_t - self._first_t

    def status_values(self) -> dict[str, Any]:
        return {
            "recording": self.recording,
            "recording.folder": self.folder,
            "recording.frames": self.frames,
            "recording.bytes": self.bytes,
            "recording.seconds": self.seconds,
            "recording.dropped": self.dropped,
            "recording.error": self.error,
            "recording.refused": self.refused,
        }


def _os_sentence(error: OSError, path: Path, sensor: str, frames: int) -> str:
    host = socket.gethostname()
    kept = f" (the {frames} frames written are kept)" if frames else ""
    if error.errno in (errno.ENOSPC, errno.EDQUOT):
        return (
            f"the disk holding {path} on {host} is full; sensor '{sensor}' stopped recording"
            f"{kept}. Free space or choose another folder."
        )
    if error.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        return (
            f"{path} on {host} cannot be written (permission denied or read-only); sensor "
            f"'{sensor}' is not recording{kept}. Choose a folder this computer can write."
        )
    return (
        f"writing {path} on {host} failed ({error.strerror or error}); sensor '{sensor}' is "
        f"not recording{kept}. Check the disk and the folder."
    )


class NodePlayback:
    """Pause, step, speed and seek of a detector node's recorded sensor (see the module
    docstring)."""

    def __init__(self, node: Node, replay: LiveReplay, params: Params | None = None) -> None:
        self.node = node
        self.replay = replay
        self.params = params if params is not None else RECORDER_PARAMS.create()
        self.waiting = replay.paused  # started paused: not yet told to play
        self.last_frame = -1
        node.add_command("playback", self._command)

    def _command(self, args: dict[str, Any]) -> dict[str, Any]:
        action = args.get("action")
        if action not in PLAYBACK_ACTIONS:
            raise RecordingCommandError(
                f"playback action '{action}' is unknown; use one of {', '.join(PLAYBACK_ACTIONS)}."
            )
        replay = self.replay
        if action == "pause":
            replay.pause()
        elif action == "resume":
            replay.resume()
        elif action == "step":
            if not replay.paused:
                raise RecordingCommandError(
                    f"sensor '{self.node.name}' is playing; pause it before stepping."
                )
            replay.step()
        elif action == "speed":
            replay.set_speed(self._speed(args.get("value")))
        elif action == "seek":
            played = args.get("played_s")
            if not isinstance(played, (int, float)) or not replay.paused:
                raise RecordingCommandError(
                    f"seek needs a number of seconds and a paused sensor ('{self.node.name}')."
                )
            replay.seek(float(played))
        if action != "state":
            self.waiting = False
        return self.state()

    def _speed(self, value: Any) -> float:
        low, high = float(self.params.min_speed), float(self.params.max_speed)
        if not isinstance(value, (int, float)) or not low <= float(value) <= high:
            raise RecordingCommandError(
                f"playback speed must be between {low:g}x and {high:g}x; got {value!r}."
            )
        return float(value)

    def hold(self) -> bool:
        """True while the replay is paused and no step was asked for (waits up to
        ``recorder.hold_s`` for one first): the node then reads no frame."""
        if not self.replay.held:
            return False
        return not self.replay.wait_unheld(float(self.params.hold_s))

    def release(self) -> None:
        """Let a paused replay go (the node is stopping)."""
        if self.replay.paused:
            self.replay.resume()

    def state(self) -> dict[str, Any]:
        replay = self.replay
        return {
            "sensor": self.node.name,
            "paused": replay.paused,
            "position_s": replay.position(),
            "played_s": replay.playhead(),
            "duration_s": replay.length,
            "speed": replay.speed,
            "frame": self.last_frame,
            "frames": len(replay.entries),
            "waiting": self.waiting,
        }

    def status_values(self) -> dict[str, Any]:
        return {f"playback.{key}": value for key, value in self.state().items() if key != "sensor"}


# ---------------------------------------------------------------- client side


class SiteControl:
    """Recording and playback commands to a site's detector nodes, from any client."""

    def __init__(self, bus: Bus, params: Params | None = None) -> None:
        self.bus = bus
        self.params = params if params is not None else RECORDER_PARAMS.create()

    def _all(
        self, nodes: Iterable[str], action: str, args: dict[str, Any] | None = None
    ) -> tuple[dict[str, dict[str, Any]], list[str]]:
        results: dict[str, dict[str, Any]] = {}
        errors: list[str] = []
        timeout = float(self.params.command_timeout_s)
        for node in nodes:
            try:
                results[node] = send_command(self.bus, node, action, args, timeout=timeout)
            except CommandError as error:
                errors.append(str(error))
        return results, errors

    @staticmethod
    def _check(nodes: list[str], what: str) -> None:
        if not nodes:
            raise RecordingCommandError(
                f"no detector node is running, so nothing can {what}; start the site first."
            )

    @staticmethod
    def _raise(errors: list[str]) -> None:
        if errors:
            raise RecordingCommandError(" ".join(_sentence(e) for e in errors))

    def start_recording(self, nodes: Iterable[str], folder: str) -> dict[str, dict[str, Any]]:
        """Every node records into ``folder`` (on its own computer); when one refuses, the
        others are stopped again and the refusals raised."""
        nodes = sorted(nodes)
        self._check(nodes, "record")
        results, errors = self._all(nodes, "record_start", {"folder": folder})
        if errors:
            self._all(results, "record_stop")
            self._raise(errors)
        return results

    def stop_recording(self, nodes: Iterable[str]) -> dict[str, dict[str, Any]]:
        results, errors = self._all(sorted(nodes), "record_stop")
        self._raise(errors)
        return results

    def playback(self, nodes: Iterable[str], action: str, **args: Any) -> dict[str, dict[str, Any]]:
        """``action`` on every node; ``pause`` also aligns the paused playheads."""
        nodes = sorted(nodes)
        self._check(nodes, f"{action} the playback")
        results, errors = self._all(nodes, "playback", {"action": action, **args})
        self._raise(errors)
        if action == "pause" and len(results) > 1:
            played = max(r["played_s"] for r in results.values())
            results, errors = self._all(nodes, "playback", {"action": "seek", "played_s": played})
            self._raise(errors)
        return results

    def start_playback(self, nodes: Iterable[str], timeout: float) -> dict[str, dict[str, Any]]:
        """Wait up to ``timeout`` s for every node to answer, then resume them together."""
        nodes = sorted(nodes)
        deadline = time.monotonic() + timeout
        while True:
            results, errors = self._all(nodes, "playback", {"action": "state"})
            if not errors or time.monotonic() > deadline:
                break
            time.sleep(0.2)
        self._raise(errors)
        return self.playback(nodes, "resume")


def _sentence(text: str) -> str:
    text = text.strip()
    return text if text.endswith((".", "!", "?")) else text + "."


class SitePlayback:
    """``optrack run --recording PATH``: the recording's sensors as the site's detector
    nodes, started paused and resumed together once every one has answered; a detector
    restarted meanwhile is put at the others' playhead (and speed) before it plays."""

    def __init__(
        self, path: str, speed: float = 1.0, loop: bool = False, params: Params | None = None
    ) -> None:
        from optrack.recording import Recording

        self.params = params if params is not None else RECORDER_PARAMS.create()
        low, high = float(self.params.min_speed), float(self.params.max_speed)
        if not low <= speed <= high:
            raise RecordingCommandError(
                f"--speed must be between {low:g} and {high:g}; got {speed:g}."
            )
        self.recording = Recording(path)  # a sentence now if it is not a recording
        self.path = self.recording.path.resolve()
        self.speed = float(speed)
        self.loop = loop
        self.started = False
        self._aligned: dict[str, int] = {}  # detector -> pid already put in step

    def uris(self) -> list[str]:
        loop = "restart" if self.loop else "off"
        return [
            f"file://{self.path}?paused=true&speed={self.speed:g}&loop={loop}#{sid}"
            for sid in self.recording.sensor_ids
        ]

    def tick(self, bus: Bus, children: list[Any], statuses: dict[str, Any], lock: Any) -> bool:
        """Start or keep the playback in step; False once the recording has played through."""
        detectors = [c for c in children if c.role == "detector"]
        if not self.loop and detectors and all(c.state == "ended" for c in detectors):
            log.info("the recording %s has played to its end; stopping.", self.path)
            return False
        with lock:
            status = dict(statuses)
        running = [c for c in detectors if c.state == "running"]
        ready = [c for c in running if c.name in status and status[c.name].role == "detector"]
        control = SiteControl(bus, self.params)
        try:
            if not self.started:
                if running and len(ready) == len(running):
                    control.playback([c.name for c in ready], "resume")
                    self.started = True
                    self._aligned = {c.name: c.pid or 0 for c in ready}
                    log.info("playing %s on %d sensor(s)", self.path, len(ready))
                return True
            fresh = [
                c
                for c in ready
                if status[c.name].values.get("playback.waiting")
                and self._aligned.get(c.name) != c.pid
            ]
            playing = [c for c in ready if c not in fresh]
            if fresh and playing:
                state = send_command(
                    bus, playing[0].name, "playback", {"action": "state"},
                    timeout=float(self.params.command_timeout_s),
                )  # fmt: skip
                names = [c.name for c in fresh]
                control.playback(names, "speed", value=state["speed"])
                control.playback(names, "seek", played_s=state["played_s"])
                if not state["paused"]:
                    control.playback(names, "resume")
                for c in fresh:
                    self._aligned[c.name] = c.pid or 0
                log.info("put %s in step with the others", ", ".join(names))
        except UserError as error:
            log.warning("playback: %s", error)
        return True
