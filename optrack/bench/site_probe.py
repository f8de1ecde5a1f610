"""The two processes ``optrack bench site`` runs inside its computers (network namespaces).

``python -m optrack.bench.site_probe watch ...``: an operator station. It joins the
site's bus with its own certificate and prints one JSON line on stdout for each
status of a node (``{"kind": "status", ...}``), each datagram of the site's UDP
output that it receives (``{"kind": "udp", "ok": parseable, "ids": [...], "tracks": [[id, x, y]...]}``) and
each message it sees that an injection sent (``{"kind": "seen", ...}``: a
parameter update, a calibration, detections on another sensor's key or of a
sensor of no calibration). It stops when its stdin closes.

``python -m optrack.bench.site_probe join ...``: a node that tries to join the site
with keys of another site, or without keys; it prints whether it could.

``python -m optrack.bench.site_probe inject ...``: a compromised detector computer.
With that detector's own certificate it tries what only an operator may do, then
prints one JSON line naming each try (``{"kind": "injected", ...}``): a
``record_start`` command to another detector, a parameter update to the tracker
(a second UDP destination), detections of a sensor of no calibration and of
another detector's sensor, a calibration. As a control it also sends what it
may send (its own status, state ``control``); the watcher must see that one.
"""

from __future__ import annotations

import argparse
import json
import socket
import sys
import threading
import time
from typing import Any

from optrack.errors import UserError
from optrack.net.bus import Bus
from optrack.net.config import BUS_PARAMS
from optrack.net.keys import SiteKeys
from optrack.net.messages import (
    CalibrationMessage,
    CommandReply,
    CommandRequest,
    DetectionsMessage,
    ParamsMessage,
    StatusMessage,
)
from optrack.types import Detection, DetectionBatch, NetworkCalibration, SensorCalibration

__all__ = ["INTRUDER_SENSOR", "inject", "main", "watch"]

INTRUDER_SENSOR = "intruder"  # a sensor of no calibration
MARK = "injected"  # in every injected message that can carry it
_print_lock = threading.Lock()


def emit(kind: str, **values: Any) -> None:
    """One JSON line on stdout."""
    line = json.dumps({"kind": kind, "t": time.time(), **values})
    with _print_lock:
        sys.stdout.write(line + "\n")
        sys.stdout.flush()


def bus_for(args: argparse.Namespace, node: str) -> Bus:
    params = BUS_PARAMS.create(
        {
            "mode": "peer",
            "connect": args.connect,
            "multicast_scouting": False,
            "keys": args.keys,
            "identity": args.identity,
            "connect_timeout_s": 15.0,
        }
    )
    return Bus(args.site, node, params)


# ------------------------------------------------------------------ watching
def _on_status(message: StatusMessage, key: str) -> None:
    keep = ("silent_sensors", "synchronised", "tracks", "insecure")
    values = {k: v for k, v in message.values.items() if k in keep or "." in k}
    emit("status", node=message.node, state=message.state, sender=message.sender, values=values)


def _on_detections(message: DetectionsMessage, key: str) -> None:
    sensor = SiteKeys.last_chunk(key)
    if message.batch.sensor_id == INTRUDER_SENSOR or message.sender != sensor:
        emit("seen", key=key, sender=message.sender, what="detections")


def _receive_udp(port: int, stop: threading.Event) -> None:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
    sock.bind(("0.0.0.0", port))
    sock.settimeout(0.2)
    while not stop.is_set():
        try:
            data = sock.recv(65536)
        except TimeoutError:
            continue
        try:
            document = json.loads(data.decode("utf-8"))
            tracks = document.get("tracks")
            found = tracks if isinstance(tracks, list) else []
            people = [[int(t["id"]), float(t["x"]), float(t["y"])] for t in found]
            ids = [p[0] for p in people] if isinstance(tracks, list) else None
            emit("udp", ok=True, ids=ids, tracks=people)
        except (ValueError, TypeError, KeyError, AttributeError):
            emit("udp", ok=False, ids=None, tracks=[])
    sock.close()


def watch(args: argparse.Namespace) -> int:
    stop = threading.Event()
    receiver = threading.Thread(target=_receive_udp, args=(args.udp_port, stop), daemon=True)
    receiver.start()
    with bus_for(args, "watcher") as bus:
        keys = bus.keys
        bus.subscribe(keys.status(), StatusMessage, _on_status)
        bus.subscribe(keys.detections(), DetectionsMessage, _on_detections)
        bus.subscribe(
            keys.params(),
            ParamsMessage,
            lambda m, k: emit("seen", key=k, sender=m.sender, what="params"),
        )
        bus.subscribe(
            keys.calibration,
            CalibrationMessage,
            lambda m, k: emit("seen", key=k, sender=m.sender, what="calibration"),
        )
        emit("ready")
        sys.stdin.read()  # until the benchmark closes it
    stop.set()
    receiver.join(2.0)
    return 0


# ----------------------------------------------------------------- injecting
def _fake_batch(sensor: str) -> DetectionBatch:
    person = Detection(x=0.5, y=0.5, z=0.9, height=1.75, confidence=1.0)
    return DetectionBatch(sensor_id=sensor, stamp=time.time(), detections=[person])


def _fake_calibration(sensors: list[str]) -> NetworkCalibration:
    identity = tuple(tuple(1.0 if r == c else 0.0 for c in range(4)) for r in range(4))
    poses = {s: SensorCalibration(world_T_camera=identity) for s in sensors}  # type: ignore[arg-type]
    return NetworkCalibration(sensors=poses, notes=MARK)


def inject(args: argparse.Namespace) -> int:
    """Each try, then the control; one line: what was tried and what answered."""
    victim, me = args.victim, args.identity
    with bus_for(args, me) as bus:
        keys = bus.keys
        time.sleep(1.0)  # let the links and the routes settle
        replies = bus.query(
            keys.command(victim),
            CommandRequest(action="record_start", args={"folder": args.folder}),
            CommandReply,
            timeout=3.0,
        )
        update = {"outputs": {"udp": f"{args.udp_target},{args.udp_target}"}}
        bus.publish(
            keys.params("tracker"), ParamsMessage(updates=update, request=MARK), realtime=False
        )
        for sensor in (INTRUDER_SENSOR, victim):
            for _ in range(5):
                message = DetectionsMessage(batch=_fake_batch(sensor))
                bus.publish(keys.detections(sensor), message)
                time.sleep(0.05)
        calibration = CalibrationMessage(calibration=_fake_calibration([victim, me]))
        bus.publish(keys.calibration, calibration, realtime=False)
        for _ in range(3):
            control = StatusMessage(node=me, role="detector", state="control", stamp=time.time())
            bus.publish(keys.status(me), control)
            time.sleep(0.2)
        time.sleep(1.0)  # reliable puts leave before the session closes
    tried = ["command", "params", "detections_foreign_sensor", "detections_other_sensor"]
    emit("injected", tried=[*tried, "calibration"], command_replies=len(replies))
    return 0


def join(args: argparse.Namespace) -> int:
    """Join as a client of ``--connect`` with ``--keys`` (``--keys ''``: without keys,
    insecure), as a node of the site would; one line: joined or the sentence why not."""
    params = {"mode": "client", "connect": args.connect, "multicast_scouting": False}
    params.update({"connect_timeout_s": 4.0, "identity": args.identity})
    params.update({"keys": args.keys} if args.keys else {"insecure": True})
    try:
        with Bus(args.site, args.identity, BUS_PARAMS.create(params)):
            emit("join", joined=True, error="")
    except UserError as error:
        emit("join", joined=False, error=str(error))
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m optrack.bench.site_probe")
    parser.add_argument("what", choices=("watch", "inject", "join"))
    parser.add_argument("--site", required=True)
    parser.add_argument("--keys", default="", help="the site's keys folder")
    parser.add_argument("--identity", required=True, help="the certificate to present")
    parser.add_argument("--connect", required=True, help="Zenoh endpoint(s)")
    parser.add_argument("--udp-port", type=int, default=0, help="watch: the outputs' port")
    parser.add_argument("--victim", default="", help="inject: another detector's sensor")
    parser.add_argument("--folder", default="", help="inject: where record_start would write")
    parser.add_argument("--udp-target", default="", help="inject: the UDP destination to add")
    args = parser.parse_args(argv)
    return {"watch": watch, "inject": inject, "join": join}[args.what](args)


if __name__ == "__main__":
    sys.exit(main())
