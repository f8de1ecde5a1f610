"""``optrack bench e2e --json``: frame timestamp to UDP datagram, on this computer.

Three Kinect v2 sensors of the simulated ``mixed`` venue, rendered once into
a recording (cached), are played back at 30 Hz as live cameras by three
detector node processes of a site that ``optrack run --headless`` starts from a
config file, as a black box (:mod:`optrack.bench.site_process`); the tracker
node sends the outputs as in ``optrack run``; a UDP socket in this process
receives the OpenPTrack JSON, and the nodes' statuses come from the site's bus.
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
``/proc`` for the launcher and every process it started over the measured
window (100 % is one core; this process, the receiver, is not counted).
Nothing is simulated faster or slower than real time: when the computer
cannot keep up, the detectors skip frames, and ``hz``, ``detector_hz`` and
``dropped_frames`` say so.
"""

from __future__ import annotations

import dataclasses
import json
import os
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from optrack.bench.common import info
from optrack.bench.site_process import (
    LAUNCHER,
    DatagramReceiver,
    SiteProcess,
    cpu_seconds,
    free_port,
)
from optrack.params import Param, Params, Schema
from optrack.recording import Recording
from optrack.sim.venue_cache import RECORDED_VENUE, venue_recording

__all__ = ["E2E_BENCH", "e2e_bench"]

# The measurement protocol (not registered: nothing a site runs).
E2E_BENCH = Schema(
    "bench_e2e",
    [
        Param("scenario", "mixed", help="Simulated venue (three Kinect v2)."),
        Param(
            "venue_seconds",
            RECORDED_VENUE["seconds"],
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


def _site_values(
    venue: Path, sensors: list[str], state: str, udp: str, overrides: dict | None
) -> dict[str, dict[str, Any]]:
    """The site's configuration: the venue's sensors as ``optrack run`` starts them, its
    outputs to ``udp``, ``overrides`` laid over it."""
    values: dict[str, dict[str, Any]] = {
        "bus": {"local_port": free_port()},
        "site": {
            "name": "bench",
            "sensors": ",".join(f"file://{venue}?loop=bounce#{s}" for s in sensors),
            "report_s": 0.0,
        },
        # the detectors of the embedded venue, as 'optrack run' starts them
        "node": {
            "state_dir": state,
            "replay_max_age_s": float(RECORDED_VENUE["max_age_s"]),
        },
        "outputs": {"udp": udp},
    }
    for stage, changed in (overrides or {}).items():
        values.setdefault(stage, {}).update(changed)
    return values


@dataclasses.dataclass
class _Window:
    """What the site did over the measured window."""

    t0_wall: float
    t1_wall: float
    elapsed: float
    statuses_before: dict[str, Any]
    statuses: dict[str, Any]
    cpu: dict[str, float]  # CPU seconds by node name ("launcher": the launcher and the rest)
    roles: dict[str, str]
    restarts: int


def _cpu_by_name(
    before: dict[int, float], after: dict[int, float], names: dict[int, str]
) -> dict[str, float]:
    """CPU seconds of each node over the window (by node name; ``launcher``: the launcher
    and any other process it started). A process that ended meanwhile (a node restarted)
    is not counted; see "restarts"."""
    cpu: dict[str, float] = {LAUNCHER: 0.0}
    for pid, seconds in sorted(before.items(), key=lambda item: names.get(item[0], LAUNCHER)):
        name = names.get(pid, LAUNCHER)
        cpu[name] = cpu.get(name, 0.0) + max(0.0, after.get(pid, 0.0) - seconds)
    return cpu


def _measure(site: SiteProcess, protocol: Params, sensors: list[str]) -> _Window:
    """Start the site, wait until every node runs, warm up, then measure the window."""
    started = time.monotonic()
    site.start(float(protocol.start_timeout_s))
    # Every node up and processing first (imports take long on a busy computer),
    # then the warm-up proper.

    def running() -> bool:
        return _running(site.statuses, sensors)

    left = float(protocol.start_timeout_s) - (time.monotonic() - started)
    if not site.wait(left, running) or not running():
        info(
            "optrack bench e2e: not every node was running after "
            f"{float(protocol.start_timeout_s):g} s; measuring anyway."
        )
    site.wait(float(protocol.warmup_s))
    names = site.pids()
    cpu_before = {pid: cpu_seconds(pid) for pid in names}
    restarts_before = site.restarts()
    t0_wall, t0 = time.time(), time.monotonic()
    statuses_before = site.statuses
    site.wait(float(protocol.seconds))
    elapsed = time.monotonic() - t0
    cpu_after = {pid: cpu_seconds(pid) for pid in cpu_before}
    statuses = site.statuses
    names.update({pid: name for pid, name in site.pids().items() if name != LAUNCHER})
    return _Window(
        t0_wall=t0_wall,
        t1_wall=time.time(),
        elapsed=elapsed,
        statuses_before=statuses_before,
        statuses=statuses,
        cpu=_cpu_by_name(cpu_before, cpu_after, names),
        roles={n: statuses[n].role for n in set(names.values()) if n in statuses},
        restarts=site.restarts() - restarts_before,
    )


def _datagram_figures(arrivals: list[tuple[float, bytes]], window: _Window) -> dict[str, Any]:
    """Latency of every datagram with a stamp not seen before, and the datagram rates."""
    latencies, frames, beats, repeats, tracks_seen = [], 0, 0, 0, 0
    counts: list[int] = []
    stamps_seen: set[tuple[int, int]] = set()
    for arrived, data in arrivals:
        if not window.t0_wall <= arrived <= window.t1_wall:
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
    elapsed = window.elapsed
    return {
        "latency_ms_median": statistics.median(latencies) if latencies else None,
        "latency_ms_p95": _percentile(latencies, 95) if latencies else None,
        "latency_ms_max": max(latencies) if latencies else None,
        "output_hz": frames / elapsed,
        "repeat_hz": repeats / elapsed,
        "heartbeat_hz": beats / elapsed,
        "datagrams": frames + beats,
        "max_tracks": tracks_seen,
        "tracks_p95": _percentile([float(c) for c in counts], 95) if counts else None,
    }


def _node_figures(window: _Window, sensors: list[str]) -> dict[str, Any]:
    """The nodes' own figures over the window (their status reports) and their CPU use."""
    statuses, before = window.statuses, window.statuses_before

    def delta(node: str, value: str) -> float | None:
        """How much a node's counter grew over the measured window, per second."""
        if node not in statuses or node not in before:
            return None
        after_value = statuses[node].values.get(value)
        before_value = before[node].values.get(value)
        if not isinstance(after_value, (int, float)) or not isinstance(before_value, (int, float)):
            return None
        return (after_value - before_value) / window.elapsed

    detector_values = [statuses[s].values for s in sensors if s in statuses]
    by_role: dict[str, float] = {}
    for name, seconds in window.cpu.items():
        role = window.roles.get(name, LAUNCHER)
        by_role[role] = by_role.get(role, 0.0) + 100.0 * seconds / window.elapsed
    return {
        "detector_hz": [statuses[s].fps for s in sensors if s in statuses],
        "detector_latency_ms": [statuses[s].latency_ms for s in sensors if s in statuses],
        "detector_frames_hz": [delta(s, "frames") for s in sensors],
        "tracker_batches_hz": delta("tracker", "batches"),
        "tracker_sent_hz": delta("tracker", "published"),
        "tracker_repeats_hz": delta("tracker", "repeats"),
        "detector_wait_ms": [v.get("wait_ms") for v in detector_values],
        "detector_processing_ms": [v.get("processing_ms") for v in detector_values],
        "tracker_latency_ms": statuses["tracker"].latency_ms if "tracker" in statuses else None,
        "outputs_latency_ms": statuses["outputs"].latency_ms if "outputs" in statuses else None,
        "dropped_frames": sum(
            statuses[s].dropped - (before[s].dropped if s in before else 0)
            for s in sensors
            if s in statuses
        ),
        "cpu_percent": sum(by_role.values()),
        "cpu_percent_by_role": by_role,
    }


def e2e_bench(overrides: dict[str, dict[str, Any]] | None = None) -> dict[str, Any]:
    """The figures of ``optrack bench e2e`` (see the module docstring); ``overrides``:
    stage values laid over the site's (to compare settings)."""
    protocol = E2E_BENCH.create()
    venue = venue_recording(
        str(protocol.scenario), 0, float(protocol.venue_seconds)
    )  # rendered once, then cached
    recording = Recording(venue)
    sensors = recording.sensor_ids
    fps = [float(recording.sensors[s].fps or 0.0) for s in sensors]
    receiver = DatagramReceiver()
    try:
        with tempfile.TemporaryDirectory(prefix="optrack-bench-") as state:
            values = _site_values(Path(venue), sensors, state, receiver.address, overrides)
            site = SiteProcess(values, state)
            receiver.start()
            load_before = os.getloadavg()
            info(
                f"optrack bench e2e: {len(sensors)} sensors at {statistics.median(fps):g} Hz "
                f"from {venue}; warm-up {float(protocol.warmup_s):g} s, then "
                f"{float(protocol.seconds):g} s measured (load average {load_before[0]:.1f} "
                f"on {os.cpu_count()} cores)"
            )
            try:
                window = _measure(site, protocol, sensors)
            finally:
                site.stop()
    finally:
        receiver.close()
    return {
        **_datagram_figures(receiver.arrivals, window),
        "sensors": len(sensors),
        "hz": statistics.median(fps),
        **_node_figures(window, sensors),
        "people": _people(recording),
        "tracks_publish": _tracks_publish(window, values),
        "cpu_cores": os.cpu_count(),
        "load_average_before": load_before[0],
        "seconds": window.elapsed,
        "restarts": window.restarts,
        "recording": str(Path(venue)),
        "sensor_model": recording.sensors[sensors[0]].model,
    }


def _tracks_publish(window: _Window, values: dict[str, dict[str, Any]]) -> str | None:
    """How the tracker node sent tracks (``node.tracks_publish``, as its status reports)."""
    tracker = window.statuses.get("tracker")
    if tracker is not None and "tracks_publish" in tracker.params.get("node", {}):
        return str(tracker.params["node"]["tracks_publish"])
    chosen = values.get("node", {}).get("tracks_publish")
    return None if chosen is None else str(chosen)
