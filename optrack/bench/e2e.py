"""``optrack bench e2e --json``: frame timestamp to UDP datagram, on this computer.

Three Kinect v2 sensors of the simulated ``mixed`` venue, rendered once into
a recording (cached), are played back at 30 Hz as live cameras by three
detector node processes; the tracker node and the outputs node run as in
``optrack run``; a UDP socket in this process receives the OpenPTrack JSON.
The tracker node sends one tracks datagram per detection batch, stamped with
the capture instant of the frame (in tracker time) whose detections it
carries, and repeats the last one (same stamp) when no batch came for a
period of ``smoothing.rate``. So for every datagram with a stamp not seen
before (every frame that reached the output), after a warm-up, the latency
is its arrival time minus its stamp: frame capture to datagram received, on
this computer's one clock; repeats are counted (``repeat_hz``), not timed.
The nodes' own medians split it: ``detector_wait_ms`` (capture to the start
of detection: the frame waiting for a busy detector, and its decoding),
``detector_processing_ms``, ``detector_latency_ms`` (capture to detections
published), ``tracker_latency_ms`` (capture to datagram sent, measured in
the tracker node, which also sends the outputs). CPU use is read from
``/proc`` for the launcher and every node process over the measured window
(100 % is one core). Nothing is simulated faster or slower than real time:
when the computer cannot keep up, the detectors skip frames, and ``hz``,
``detector_hz`` and ``dropped_frames`` say so.
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from optrack.params import Param, Schema
from optrack.runtime.site_params import SITE_PARAMS

__all__ = ["E2E_BENCH", "bench_e2e"]

# The measurement protocol (not registered: nothing a site runs).
E2E_BENCH = Schema(
    "bench_e2e",
    [
        Param("scenario", "mixed", help="Simulated venue (three Kinect v2)."),
        Param(
            "venue_seconds",
            SITE_PARAMS["venue_seconds"].default,
            min=1.0,
            max=600.0,
            unit="s",
            help="Recording looped (forwards and backwards; the same cache as 'optrack run').",
        ),
        Param(
            "start_timeout_s",
            120.0,
            min=1.0,
            max=600.0,
            unit="s",
            help="Longest wait for every node to report frames before the warm-up.",
        ),
        Param(
            "warmup_s",
            8.0,
            min=0.0,
            max=600.0,
            unit="s",
            help="Not measured (after every node runs).",
        ),
        Param("seconds", 20.0, min=1.0, max=3600.0, unit="s", help="Measured window."),
    ],
    help="End-to-end latency benchmark.",
)


def _cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process, s (0 when it is gone)."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as stat:
            fields = stat.read().rsplit(")", 1)[1].split()
    except (FileNotFoundError, ProcessLookupError, IndexError):
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _running(statuses: dict[str, Any], sensors: list[str]) -> bool:
    """Every detector has processed frames and the tracker has reported."""
    statuses = dict(statuses)
    return "tracker" in statuses and all(
        s in statuses and int(statuses[s].values.get("frames", 0)) > 0 for s in sensors
    )


def _people(recording: Any) -> int | None:
    """Most people the ground truth has at one instant (None without ground truth)."""
    if not recording.has_ground_truth:
        return None
    return max((len(instant.people) for instant in recording.ground_truth()), default=0)


def _percentile(values: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(values), q)) if values else float("nan")


def bench_e2e(args: argparse.Namespace, overrides: dict[str, dict[str, Any]] | None = None) -> int:
    """``overrides``: stage values laid over the site's (to compare settings)."""
    from optrack.recording import Recording
    from optrack.runtime.cli import setup_logging
    from optrack.runtime.config import load_node_config
    from optrack.runtime.site import Site, venue_recording

    protocol = E2E_BENCH.create()
    setup_logging("optrack bench e2e")
    venue = venue_recording(
        str(protocol.scenario), 0, float(protocol.venue_seconds)
    )  # rendered once, then cached
    recording = Recording(venue)
    sensors = recording.sensor_ids
    fps = [float(recording.sensors[s].fps or 0.0) for s in sensors]
    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receiver.bind(("127.0.0.1", 0))
    receiver.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        hub_port = probe.getsockname()[1]
    arrivals: list[tuple[float, bytes]] = []
    stop = threading.Event()

    def receive() -> None:
        receiver.settimeout(0.2)
        while not stop.is_set():
            try:
                data = receiver.recv(65536)
            except TimeoutError:
                continue
            arrivals.append((time.time(), data))

    with tempfile.TemporaryDirectory(prefix="optrack-bench-") as state:
        values: dict[str, dict[str, Any]] = {
            "bus": {"local_port": hub_port},
            "site": {
                "name": "bench",
                "sensors": ",".join(f"file://{venue}?loop=bounce#{s}" for s in sensors),
                "report_s": 0.0,
            },
            # the detectors of the embedded venue, as 'optrack run' starts them
            "node": {
                "state_dir": state,
                "replay_max_age_s": float(SITE_PARAMS["venue_max_age_s"].default),
            },
            "outputs": {"udp": f"127.0.0.1:{receiver.getsockname()[1]}"},
        }
        for stage, changed in (overrides or {}).items():
            values.setdefault(stage, {}).update(changed)
        config = load_node_config(None, values)
        site = Site(config, headless=True)
        thread = threading.Thread(target=receive, daemon=True)
        thread.start()
        load_before = os.getloadavg()
        print(
            f"optrack bench e2e: {len(sensors)} sensors at {statistics.median(fps):g} Hz from "
            f"{venue}; warm-up {float(protocol.warmup_s):g} s, then {float(protocol.seconds):g} s "
            f"measured (load average {load_before[0]:.1f} on {os.cpu_count()} cores)",
            file=sys.stderr,
        )
        try:
            site.start()
            pids = {"launcher": os.getpid()}
            # Every node up and processing first (imports take long on a busy computer),
            # then the warm-up proper.
            ready_by = time.monotonic() + float(protocol.start_timeout_s)
            while time.monotonic() < ready_by and not _running(site.statuses, sensors):
                site.supervise_once(time.monotonic())
                time.sleep(0.1)
            if not _running(site.statuses, sensors):
                print(
                    "optrack bench e2e: not every node was running after "
                    f"{float(protocol.start_timeout_s):g} s; measuring anyway.",
                    file=sys.stderr,
                )
            warm_until = time.monotonic() + float(protocol.warmup_s)
            while time.monotonic() < warm_until:
                site.supervise_once(time.monotonic())
                time.sleep(0.1)
            for child in site.children:
                if child.pid is not None:
                    pids[child.name] = child.pid
            roles = {c.name: c.role for c in site.children}
            cpu_before = {name: _cpu_seconds(pid) for name, pid in pids.items()}
            restarts_before = sum(c.restarts for c in site.children)
            t0_wall, t0 = time.time(), time.monotonic()
            statuses_before = dict(site.statuses)
            end = t0 + float(protocol.seconds)
            while time.monotonic() < end:
                site.supervise_once(time.monotonic())
                time.sleep(0.1)
            elapsed = time.monotonic() - t0
            # A node restarted meanwhile is not counted (its pid is gone); see "restarts".
            cpu = {
                name: max(0.0, _cpu_seconds(pid) - cpu_before[name]) for name, pid in pids.items()
            }
            t1_wall = time.time()
            statuses = dict(site.statuses)
            restarts = sum(c.restarts for c in site.children) - restarts_before
        finally:
            site.stop()
            stop.set()
            thread.join(2.0)
            receiver.close()

    latencies, frames, beats, repeats, tracks_seen = [], 0, 0, 0, 0
    counts: list[int] = []
    stamps_seen: set[tuple[int, int]] = set()
    for arrived, data in arrivals:
        if not t0_wall <= arrived <= t1_wall:
            continue
        document = json.loads(data)
        header = document["header"]
        if header["frame_id"] == "heartbeat":
            beats += 1
            continue
        frames += 1
        tracks_seen = max(tracks_seen, len(document["tracks"]))
        counts.append(len(document["tracks"]))
        key = (header["stamp"]["sec"], header["stamp"]["nsec"])
        if key in stamps_seen:  # a repeat at the fixed rate: no new frame in it
            repeats += 1
            continue
        stamps_seen.add(key)
        stamp = key[0] + key[1] * 1e-9
        latencies.append((arrived - stamp) * 1000.0)
    people = _people(recording)

    def delta(node: str, value: str) -> float | None:
        """How much a node's counter grew over the measured window, per second."""
        if node not in statuses or node not in statuses_before:
            return None
        after = statuses[node].values.get(value)
        before = statuses_before[node].values.get(value)
        if not isinstance(after, (int, float)) or not isinstance(before, (int, float)):
            return None
        return (after - before) / elapsed

    detector_hz = [statuses[s].fps for s in sensors if s in statuses]
    detector_ms = [statuses[s].latency_ms for s in sensors if s in statuses]
    detector_values = [statuses[s].values for s in sensors if s in statuses]
    dropped = sum(
        statuses[s].dropped - (statuses_before[s].dropped if s in statuses_before else 0)
        for s in sensors
        if s in statuses
    )
    by_role: dict[str, float] = {}
    for name, seconds in cpu.items():
        role = roles.get(name, "launcher")
        by_role[role] = by_role.get(role, 0.0) + 100.0 * seconds / elapsed
    result: dict[str, Any] = {
        "latency_ms_median": statistics.median(latencies) if latencies else None,
        "latency_ms_p95": _percentile(latencies, 95) if latencies else None,
        "latency_ms_max": max(latencies) if latencies else None,
        "sensors": len(sensors),
        "hz": statistics.median(fps),
        "detector_hz": detector_hz,
        "detector_latency_ms": detector_ms,
        "detector_frames_hz": [delta(s, "frames") for s in sensors],
        "tracker_batches_hz": delta("tracker", "batches"),
        "tracker_sent_hz": delta("tracker", "published"),
        "tracker_repeats_hz": delta("tracker", "repeats"),
        "detector_wait_ms": [v.get("wait_ms") for v in detector_values],
        "detector_processing_ms": [v.get("processing_ms") for v in detector_values],
        "tracker_latency_ms": statuses["tracker"].latency_ms if "tracker" in statuses else None,
        "outputs_latency_ms": statuses["outputs"].latency_ms if "outputs" in statuses else None,
        "dropped_frames": dropped,
        "output_hz": frames / elapsed,
        "repeat_hz": repeats / elapsed,
        "heartbeat_hz": beats / elapsed,
        "datagrams": frames + beats,
        "max_tracks": tracks_seen,
        "tracks_p95": _percentile([float(c) for c in counts], 95) if counts else None,
        "people": people,
        "tracks_publish": str(config["node"].tracks_publish),
        "cpu_percent": sum(by_role.values()),
        "cpu_percent_by_role": by_role,
        "cpu_cores": os.cpu_count(),
        "load_average_before": load_before[0],
        "seconds": elapsed,
        "restarts": restarts,
        "recording": str(Path(venue)),
        "sensor_model": recording.sensors[sensors[0]].model,
    }
    if args.json:
        sys.stdout.write(json.dumps(result) + "\n")
    else:
        for key, value in result.items():
            print(f"{key}: {value}", file=sys.stderr)
    return 0
