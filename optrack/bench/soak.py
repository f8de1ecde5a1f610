"""``optrack bench soak --minutes N``: a 3-sensor site left running, its memory watched.

The site is ``optrack run --headless`` as a subprocess
(:class:`optrack.bench.site_process.SiteProcess`): three Kinect v2 of the
``mixed`` venue, replayed from the cached venue recording forwards and
backwards (``live``: the embedded venue, each sensor rendered live by its
detector, which on a small computer drops what it cannot render in time), the
tracker node sending UDP JSON to a receiver here. Every ``sample_s`` it reads
the resident memory (``VmRSS`` of ``/proc/<pid>/status``) of every process the
launcher started (found as its descendants; nodes named by the launcher's
``site`` status) and the launcher's own.

Figures: ``rss_growth_pct``, the worst process's growth from its first sample
after the first minute (after half the run when it is shorter) to its last;
``rss_mb`` (each process's first and last sample); ``restarts`` (the
launcher's count); ``dropped_pct`` (frames the detectors skipped, of the
frames their sensors delivered); ``datagrams`` (UDP datagrams received);
``unparseable``; ``minutes``; ``load_average`` before and after.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from typing import Any

from optrack.bench.common import info
from optrack.bench.site_process import DatagramReceiver, SiteProcess, free_port
from optrack.errors import UserError
from optrack.sim.venue_cache import RECORDED_VENUE, venue_recording

__all__ = ["rss_kb", "soak_bench"]

SENSORS = ("kinect2_0", "kinect2_1", "kinect2_2")
START_TIMEOUT_S = 180.0


def rss_kb(pid: int) -> int | None:
    """The resident memory of a process in kB (None when it is gone)."""
    try:
        with open(f"/proc/{pid}/status", encoding="ascii", errors="replace") as status:
            for line in status:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        return None
    return 0  # a zombie has no VmRSS line


def _values(live: bool, state: str, udp: str) -> dict[str, dict[str, Any]]:
    sensors = ""
    if not live:
        venue = venue_recording("mixed", 0, float(RECORDED_VENUE["seconds"]))
        sensors = ",".join(f"file://{venue}?loop=bounce#{s}" for s in SENSORS)
    return {
        "bus": {"local_port": free_port()},
        "site": {"name": "soak", "sensors": sensors, "report_s": 60.0},
        "node": {"state_dir": state, "replay_max_age_s": float(RECORDED_VENUE["max_age_s"])},
        "outputs": {"udp": udp},
    }


def _all_running(site: SiteProcess) -> bool:
    statuses = site.statuses
    return all(s in statuses and statuses[s].fps > 0 for s in SENSORS) and "tracker" in statuses


def _sample(site: SiteProcess, samples: dict[str, list[tuple[float, int]]]) -> None:
    """One RSS sample of every process of the site, by ``name:pid``."""
    now = time.monotonic()
    for pid, name in site.pids().items():
        kb = rss_kb(pid)
        if kb:
            samples.setdefault(f"{name}:{pid}", []).append((now, kb))


def _growth(samples: dict[str, list[tuple[float, int]]], after: float) -> dict[str, Any]:
    """Each process's RSS (first and last, MB) and the worst growth after ``after``."""
    worst = 0.0
    rss = {}
    for name, series in samples.items():
        rss[name] = [round(series[0][1] / 1024, 1), round(series[-1][1] / 1024, 1)]
        later = [kb for t, kb in series if t >= after]
        if len(later) >= 2 and later[0] > 0:
            worst = max(worst, (later[-1] - later[0]) * 100.0 / later[0])
    return {"rss_growth_pct": round(worst, 2), "rss_mb": rss}


def _dropped_pct(site: SiteProcess, start: dict[str, tuple[int, int]]) -> float | None:
    """Frames skipped of frames delivered, over the run, all detectors together."""
    dropped = frames = 0
    for sensor in SENSORS:
        status = site.statuses.get(sensor)
        if status is None:
            continue
        first_dropped, first_frames = start.get(sensor, (0, 0))
        dropped += status.dropped - first_dropped
        frames += int(status.values.get("frames", 0)) - first_frames
    total = dropped + frames
    return round(dropped * 100.0 / total, 3) if total else None


def _counts(site: SiteProcess) -> dict[str, tuple[int, int]]:
    return {
        s: (status.dropped, int(status.values.get("frames", 0)))
        for s, status in site.statuses.items()
        if s in SENSORS
    }


def _parseable(data: bytes) -> bool:
    try:
        return isinstance(json.loads(data.decode("utf-8")), dict)
    except ValueError:
        return False


def soak_bench(minutes: float, live: bool = False, sample_s: float = 5.0) -> dict[str, Any]:
    """Run the site for ``minutes`` (after its nodes deliver frames); the figures of the
    module docstring."""
    if not minutes > 0:
        raise UserError(f"--minutes must be > 0; got {minutes:g}.")
    seconds = minutes * 60.0
    load_before = os.getloadavg()
    receiver = DatagramReceiver()
    samples: dict[str, list[tuple[float, int]]] = {}
    with tempfile.TemporaryDirectory(prefix="optrack-soak-") as state:
        site = SiteProcess(_values(live, state, receiver.address), state)
        receiver.start()
        try:
            site.start(START_TIMEOUT_S)
            if not site.wait(START_TIMEOUT_S, lambda: _all_running(site)):
                raise UserError("the soaked site ended before its nodes ran.")
            if not _all_running(site):
                raise UserError(f"the site's nodes did not all run within {START_TIMEOUT_S:g} s.")
            begun = time.monotonic()
            first_arrival = len(receiver.arrivals)
            start_counts = _counts(site)
            info(f"optrack bench soak: 3 sensors for {minutes:g} min (load {load_before[0]:.1f})")
            while time.monotonic() - begun < seconds:
                _sample(site, samples)
                left = seconds - (time.monotonic() - begun)
                if not site.wait(max(0.0, min(sample_s, left))):
                    raise UserError("the soaked site ended during the run.")
            _sample(site, samples)
            restarts = site.restarts()
            dropped = _dropped_pct(site, start_counts)
        finally:
            site.stop()
            receiver.close()
    arrivals = [data for _, data in receiver.arrivals[first_arrival:]]
    return {
        "minutes": minutes,
        **_growth(samples, begun + min(60.0, seconds / 2)),
        "restarts": restarts,
        "dropped_pct": dropped,
        "datagrams": len(arrivals),
        "unparseable": sum(not _parseable(d) for d in arrivals),
        "venue": "live" if live else "recorded",
        "load_average": [round(load_before[0], 2), round(os.getloadavg()[0], 2)],
    }
