"""``optrack sensors`` (list attached cameras) and ``optrack record`` (record live sensors)."""

from __future__ import annotations

import argparse
import contextlib
import logging
import queue
import re
import sys
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

from optrack.cli import EXIT_ERROR, EXIT_OK, CommandError, add_json, emit_json, info
from optrack.errors import UserError
from optrack.recording import RecordingWriter
from optrack.sensors.base import Sensor, SensorError
from optrack.types import RGBDFrame

__all__ = ["cmd_record", "cmd_sensors"]


@contextlib.contextmanager
def _log_to_stderr() -> Iterator[None]:
    """Show optrack's warnings (reconnections, mode choices) on stderr while a command runs."""
    logger = logging.getLogger("optrack")
    if logger.handlers:
        yield
        return
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("optrack: %(message)s"))
    logger.addHandler(handler)
    level = logger.level
    logger.setLevel(logging.INFO)
    try:
        yield
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)


# ------------------------------------------------------------------ sensors


#: A headless computer's cameras: one ``<name>.env`` each, for ``optrack-node@<name>``.
SENSOR_ENV_DIR = "/etc/optrack/sensors"


def _unit_name(name: str, taken: set[str]) -> str:
    """``name`` as a systemd instance name (letters, digits, ``_.-``), unique in ``taken``."""
    base = re.sub(r"[^a-z0-9_.-]+", "-", name.lower()).strip("-.") or "camera"
    unique, n = base, 2
    while unique in taken:
        unique, n = f"{base}-{n}", n + 1
    taken.add(unique)
    return unique


def _add_config(entries: list[dict[str, Any]], name_of: Callable[[dict], str]) -> None:
    """Each entry with a URI gets ``config``: the file of ``/etc/optrack/sensors`` its
    detector node service reads, and the line to put in it."""
    taken: set[str] = set()
    for entry in entries:
        if entry.get("uri"):
            name = _unit_name(name_of(entry), taken)
            entry["config"] = {
                "name": name,
                "file": f"{SENSOR_ENV_DIR}/{name}.env",
                "line": f"OPTRACK_SENSOR={entry['uri']}",
            }


def _usb_name(device: dict[str, Any]) -> str:
    from optrack.sensors.uri import expected_sensor_id

    known = expected_sensor_id(device["uri"])
    return known or "-".join(str(p) for p in (device["model"], device["serial"]) if p)


def _opened(uris: list[str]) -> list[dict[str, Any]]:
    """The sensors ``--sensor`` names, each opened and read once: its id, model, URI."""
    import optrack.sim.sensor  # noqa: F401 - registers sim://
    from optrack.sensors.uri import open_sensor

    found = []
    for uri in uris:
        with contextlib.closing(open_sensor(uri)) as sensor:
            if sensor.read() is None:
                raise CommandError(f"the sensor {uri} opened but gave no frame; check it.")
            found.append({"uri": uri, "id": sensor.info.id, "model": sensor.info.model})
    return found


def _print_config(entries: list[dict[str, Any]]) -> None:
    """The lines a headless computer's configuration needs for these sensors."""
    configs = [entry for entry in entries if "config" in entry]
    if not configs:
        return
    print(
        f"\nFor the detector node services of this computer (optrack-node@<name>), "
        f"one file each in {SENSOR_ENV_DIR}:"
    )
    for entry in configs:
        config = entry["config"]
        print(f"  {config['file']}: {config['line']}")
    names = " ".join(f"optrack-node@{entry['config']['name']}" for entry in configs)
    print(f"then: sudo systemctl enable --now {names}")
    uris = ",".join(entry["uri"] for entry in configs)
    print(
        f"Or, for optrack run on this computer alone, in its site.yaml:\n  site:\n    sensors: {uris}"
    )


def cmd_sensors(args: argparse.Namespace) -> int:
    """List the depth cameras on the USB bus (``devices``), or open the sensors that
    ``--sensor`` names (``sensors``); each with the line of its node's configuration."""
    from optrack.sensors import usb

    if getattr(args, "udev_rules", False):
        sys.stdout.write(usb.udev_rules())
        return EXIT_OK
    if args.sensor:
        with _log_to_stderr():
            opened = _opened(args.sensor)
        _add_config(opened, lambda entry: entry["id"])
        if args.json:
            emit_json({"sensors": opened})
            return EXIT_OK
        for entry in opened:
            print(f"{entry['uri']:40s} {entry['model']}  id {entry['id']}")
        _print_config(opened)
        return EXIT_OK
    cameras = usb.list_cameras()
    devices = [camera.as_dict() for camera in cameras]
    if any(c.known.backend == usb.REALSENSE for c in cameras):
        _realsense_serials(cameras, devices)
    for camera in cameras:
        if camera.access == "denied":
            info(usb.permission_message(camera))
    _add_config(devices, _usb_name)
    if args.json:
        emit_json({"devices": devices})
        return EXIT_OK
    if not devices:
        print("No depth camera is attached (openni://Dummy is OpenNI2's test device).")
        return EXIT_OK
    for device in devices:
        uri = device["uri"] or "(no optrack backend)"
        serial = f"  serial {device['serial']}" if device["serial"] else ""
        print(
            f"{uri:40s} {device['model']}  [{device['vendor_id']}:{device['product_id']}]"
            f"  bus {device['bus']} device {device['address']}{serial}"
        )
    _print_config(devices)
    return EXIT_OK


def _realsense_serials(cameras: list, devices: list[dict]) -> None:
    """Give RealSense cameras the serial librealsense knows them by, when it is installed."""
    from optrack.sensors import realsense

    try:
        seen = realsense.attached_devices()
    except SensorError:
        return
    for camera, device in zip(cameras, devices, strict=True):
        if camera.known.backend != "realsense":
            continue
        pid = f"{camera.known.product_id:04x}"
        same_pid = [s for s in seen if s["product_id"] == pid]
        by_port = [s for s in same_pid if camera.port_path and f"/{camera.port_path}/" in s["port"]]
        match = by_port or (same_pid if len(same_pid) == 1 else [])
        if match:
            device["serial"] = match[0]["serial"]
            device["uri"] = f"realsense://{match[0]['serial']}"


# ------------------------------------------------------------------- record


class _Capture(threading.Thread):
    """Reads one sensor until told to stop; frames go to the shared queue."""

    def __init__(self, sensor: Sensor, out: queue.Queue, stop: threading.Event) -> None:
        super().__init__(name=f"capture-{sensor.uri}", daemon=True)
        self.sensor = sensor
        self.out = out
        self.stop_event = stop
        self.error: UserError | None = None
        self.ended = False

    def run(self) -> None:
        try:
            while not self.stop_event.is_set():
                frame = self.sensor.read()
                if frame is None:
                    self.ended = True
                    return
                self.out.put((time.monotonic(), frame))
        except UserError as error:
            self.error = error
        finally:
            self.out.put((time.monotonic(), None))


def cmd_record(args: argparse.Namespace) -> int:
    """Record live sensors for ``--seconds`` into a new recording directory."""
    import optrack.sim.sensor  # noqa: F401 - registers sim://
    from optrack.sensors.uri import open_sensor

    if not args.seconds > 0:
        raise CommandError(f"--seconds must be > 0; got {args.seconds:g}.")
    with _log_to_stderr():
        sensors: list[Sensor] = []
        try:
            for uri in args.sensor:
                sensors.append(open_sensor(uri))
            return _record(args, sensors)
        finally:
            for sensor in sensors:
                sensor.close()


def _record(args: argparse.Namespace, sensors: list[Sensor]) -> int:
    infos = [sensor.info for sensor in sensors]
    ids = [i.id for i in infos]
    for sid in ids:
        if ids.count(sid) > 1:
            raise CommandError(
                f"two sensors have the id '{sid}'; give one another id, e.g. "
                f"{sensors[ids.index(sid)].uri}?id={sid}-2 (in quotes)."
            )
    frames: queue.Queue[tuple[float, RGBDFrame | None]] = queue.Queue(maxsize=64 * len(sensors))
    stop = threading.Event()
    writer = RecordingWriter(
        args.out, infos, source="optrack record " + " ".join(s.uri for s in sensors)
    )
    captures = [_Capture(sensor, frames, stop) for sensor in sensors]
    interactive = sys.stderr.isatty()
    started = time.monotonic()
    deadline = started + float(args.seconds)
    for capture in captures:
        capture.start()
    running = len(captures)
    last_report = started
    interrupted = False
    try:
        while running and time.monotonic() < deadline:
            try:
                arrived, frame = frames.get(timeout=0.1)
            except queue.Empty:
                continue
            if frame is None:
                running -= 1
            elif arrived <= deadline:
                writer.write(frame)
            now = time.monotonic()
            if now - last_report >= (0.25 if interactive else 1.0):
                last_report = now
                _progress(writer.frame_counts, now - started, float(args.seconds), interactive)
    except KeyboardInterrupt:
        interrupted = True
        raise
    finally:
        elapsed = min(time.monotonic(), deadline) - started
        _stop_captures(captures, sensors, stop, frames, writer, deadline, interrupted)
        writer.close()
    counts = writer.frame_counts
    _progress(counts, elapsed, float(args.seconds), interactive, final=True)
    errors = [c.error for c in captures if c.error is not None]
    total = sum(counts.values())
    payload = {
        "out": str(args.out),
        "seconds": round(elapsed, 3),
        "frames": total,
        "sensors": [
            {
                "id": sensor_info.id,
                "uri": sensor.uri,
                "model": sensor_info.model,
                "frames": counts[sensor_info.id],
                "fps": round(counts[sensor_info.id] / elapsed, 2) if elapsed > 0 else 0.0,
                "dropped": int(getattr(sensor, "dropped", 0)),
                "reconnects": int(getattr(sensor, "reconnects", 0)),
            }
            for sensor, sensor_info in zip(sensors, infos, strict=True)
        ],
    }
    if errors:
        payload["error"] = str(errors[0])
        info(f"optrack record: {errors[0]} (the frames before it are saved in {args.out}).")
    if args.json:
        emit_json(payload)
    else:
        info(f"wrote {args.out}: {total} frames in {elapsed:.1f} s.")
    return EXIT_ERROR if errors else EXIT_OK


def _stop_captures(
    captures: list[_Capture],
    sensors: list[Sensor],
    stop: threading.Event,
    frames: queue.Queue,
    writer: RecordingWriter,
    deadline: float,
    interrupted: bool,
) -> None:
    """Stop the capture threads, writing the frames that arrived before the deadline."""
    stop.set()
    for sensor in sensors:
        interrupt = getattr(sensor, "interrupt", None)
        if interrupt is not None:
            interrupt()  # a camera being reconnected stops waiting
    give_up = time.monotonic() + 10.0
    while any(c.is_alive() for c in captures) or not frames.empty():
        try:
            arrived, frame = frames.get(timeout=0.05)
        except queue.Empty:
            if time.monotonic() > give_up:
                break
            continue
        if frame is not None and arrived <= deadline and not interrupted:
            writer.write(frame)


def _progress(
    counts: dict[str, int], elapsed: float, seconds: float, interactive: bool, final: bool = False
) -> None:
    parts = ", ".join(f"{sid} {n}" for sid, n in counts.items())
    line = f"recording {min(elapsed, seconds):.1f}/{seconds:g} s: {parts} frames"
    if interactive:
        end = "\n" if final else ""
        sys.stderr.write(f"\r{line}{end}")
        sys.stderr.flush()
    elif not final:
        info(line)


def add_commands(commands: Any, command: Any) -> None:
    """Declare this package's commands on the ``optrack`` parser (see optrack/cli.py)."""
    p = command(
        "sensors",
        "List the depth cameras attached to this computer.",
        "optrack.sensors.cli:cmd_sensors",
    )
    p.add_argument(
        "--udev-rules",
        action="store_true",
        help="print the udev rules that let users open the cameras (Linux) and exit",
    )
    p.add_argument(
        "--sensor",
        action="append",
        metavar="URI",
        help="open this sensor (e.g. openni://Dummy) instead of listing the USB bus, and "
        "print its configuration line (repeat for several)",
    )
    add_json(p)
    p = command("record", "Record live sensors into a recording.", "optrack.sensors.cli:cmd_record")
    p.add_argument(
        "--sensor",
        action="append",
        required=True,
        metavar="URI",
        help="sensor URI (repeat for several)",
    )
    p.add_argument("--seconds", type=float, required=True, help="how long to record, s")
    p.add_argument("--out", required=True, help="output recording directory (must be new)")
    add_json(p)
