"""``optrack bench site``: a ``peer`` site across several computers, made on this one.

Five computers (Linux network namespaces on one bridge, :mod:`optrack.bench.netns`),
each with its own address: ``trk`` runs the tracker (``optrack run --nodes tracker``:
the tracker node with the outputs, supervised), ``d0``..``d2`` one detector each
(``optrack run --nodes detectors``, each playing one sensor of a recording of the
simulated ``mixed`` venue, looped forwards and backwards), ``obs`` is an operator
station (:mod:`optrack.bench.site_probe` ``watch``: statuses from the bus, the
site's UDP output). The site's keys come from ``optrack site init``; every link is
mutual TLS. It follows docs/runtime.md, "Several computers", step by step:

0. the keys (``optrack site init``), copied to each computer without the
   authority's private key; 1. one configuration file per computer; 2. each
   computer's ``optrack run`` and the station's watcher;
3. tracks flow at the station and the tracker hears every sensor;
4. ``d0``'s cable is pulled for ``cut_s`` (5 s): tracks keep flowing from the
   others and the tracker names ``kinect2_0`` silent; the cable is plugged back:
   ``link_rejoin_s`` is the time until the tracker hears that sensor again;
5. the tracker process is killed (SIGKILL): its launcher restarts it, the
   detectors reconnect: ``tracker_recovery_s`` is the time from the kill to the
   first datagram with tracks;
6. from ``d2``, a node with keys of another site and one without keys try to join
   as a detector node does (a client of the tracker computer's hub):
   ``foreign_node_refused``;
7. from ``d2``, with that detector's own certificate, the injections of
   :mod:`optrack.bench.site_probe` (``injections_refused`` of ``injections_tried``:
   a try counts as refused when nothing of it reached the station, or answered,
   and the control message sent beside it did arrive);

and ``datagrams_unparseable`` counts the UDP datagrams that are not JSON.
Nothing here imports the runtime: the site is driven as subprocesses.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import yaml

from optrack.bench.common import info
from optrack.bench.netns import Lab, netns_problem
from optrack.bench.site_process import descendants
from optrack.errors import UserError
from optrack.net.security import init_site
from optrack.sim.venue_cache import RECORDED_VENUE, venue_recording

__all__ = ["SiteProtocol", "site_bench"]

SITE = "lab"
SENSORS = ("kinect2_0", "kinect2_1", "kinect2_2")
DETECTOR_HOSTS = ("d0", "d1", "d2")
HOSTS = ("trk", *DETECTOR_HOSTS, "obs")
PORT = 7447
UDP_PORT = 21234
PY = sys.executable


@dataclasses.dataclass
class SiteProtocol:
    """How long each step may take (the limits are where the bench gives up on a step, not
    the targets: those are 5 s, reported as measured)."""

    recording_s: float = RECORDED_VENUE["seconds"]  # the venue rendered when none is given
    start_timeout_s: float = 120.0  # until tracks flow with every sensor
    cut_s: float = 5.0
    rejoin_timeout_s: float = 30.0
    recovery_timeout_s: float = 30.0
    settle_s: float = 3.0  # tracks flowing before each step


# ------------------------------------------------------------------ the watcher
class Watcher:
    """The station's probe (``site_probe watch`` in ``obs``), its lines as events."""

    def __init__(self, argv: list[str], log: Path) -> None:
        self.events: list[dict[str, Any]] = []
        self._lock = threading.Lock()
        self._log = log.open("wb")
        self.process = subprocess.Popen(
            argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self._log
        )
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            try:
                event = json.loads(line)
            except ValueError:
                continue
            with self._lock:
                self.events.append(event)

    def select(self, kind: str, since: float = 0.0) -> list[dict[str, Any]]:
        with self._lock:
            return [e for e in self.events if e["kind"] == kind and e["t"] >= since]

    def first(
        self, kind: str, since: float, test: Callable[[dict[str, Any]], bool]
    ) -> dict[str, Any] | None:
        return next((e for e in self.select(kind, since) if test(e)), None)

    def close(self) -> None:
        if self.process.poll() is None:
            assert self.process.stdin is not None
            self.process.stdin.close()
            try:
                self.process.wait(10.0)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self._thread.join(2.0)
        self._log.close()


def wait_for(test: Callable[[], Any], timeout: float, what: str, alive: Callable[[], None]) -> Any:
    """``test()``'s first true value within ``timeout`` (checked every 0.05 s), calling
    ``alive()`` (which raises when the site died) meanwhile."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        found = test()
        if found:
            return found
        alive()
        time.sleep(0.05)
    raise UserError(f"the namespaced site: {what} did not happen within {timeout:g} s.")


def tracking(event: dict[str, Any]) -> bool:
    return bool(event["ok"] and event["ids"])


def silent(event: dict[str, Any], sensor: str) -> bool:
    return sensor in str(event["values"].get("silent_sensors", "")).split(",")


# -------------------------------------------------------------------- the lab
class SiteLab:
    """The computers, the site's keys and configs, its processes (see the module doc)."""

    def __init__(self, folder: Path, recording: Path) -> None:
        self.folder = folder
        self.recording = recording
        self.lab = Lab(HOSTS)
        self.keys = folder / "keys"
        self.launchers: dict[str, subprocess.Popen[bytes]] = {}
        self.watcher: Watcher | None = None

    def address(self, host: str) -> str:
        return self.lab.addresses[host]

    @property
    def hub(self) -> str:
        return f"tcp/{self.address('trk')}:{PORT}"

    def run(self, argv: list[str], timeout: float, host: str | None = None) -> str:
        """A command to its end (inside ``host``), its output; a failure raises."""
        argv = self.lab.command(host, argv) if host else argv
        done = subprocess.run(argv, capture_output=True, text=True, timeout=timeout, check=False)
        if done.returncode != 0:
            raise UserError(f"{' '.join(argv[:6])}... failed: {done.stderr.strip()[-400:]}")
        return done.stdout

    def make_keys(self) -> None:
        """Step 0: ``optrack site init``."""
        nodes = ",".join(["site", "tracker", *SENSORS])
        init = [PY, "-m", "optrack.cli", "site", "init", "--site", SITE]
        self.run([*init, "--out", str(self.keys), "--nodes", nodes, "--stations", "bench"], 120)

    def copied_keys(self, host: str) -> str:
        """The keys as copied to one computer: everything but the authority's private key."""
        copy = self.folder / f"keys-{host}"
        if not copy.is_dir():
            shutil.copytree(self.keys, copy, ignore=shutil.ignore_patterns("ca-key.pem"))
        return str(copy)

    def config(self, host: str) -> Path:
        """Step 1: the site file of one computer (the same but for its sensor and hub)."""
        k = DETECTOR_HOSTS.index(host) if host in DETECTOR_HOSTS else -1
        sensors = f"file://{self.recording}?loop=bounce#{SENSORS[k]}" if k >= 0 else ""
        values = {
            "site": {"name": SITE, "sensors": sensors, "restart_delay_s": 0.5, "report_s": 0.0},
            "bus": {
                "mode": "peer",
                "keys": self.copied_keys(host),
                "listen": f"tcp/0.0.0.0:{PORT}",
                "connect": self.hub if k >= 0 else "",
                "multicast_scouting": False,
                "local_port": PORT,
            },
            "node": {"status_period_s": 0.25, "state_dir": str(self.folder / f"state-{host}")},
            "outputs": {"udp": f"{self.address('obs')}:{UDP_PORT}"},
        }
        path = self.folder / f"{host}.yaml"
        path.write_text(yaml.safe_dump(values, sort_keys=False), encoding="utf-8")
        return path

    def start(self) -> None:
        """Step 2: the station's watcher, then each computer's ``optrack run``."""
        watch = [PY, "-m", "optrack.bench.site_probe", "watch", "--site", SITE]
        keys = self.copied_keys("obs")
        watch += ["--keys", keys, "--identity", "bench", "--connect", self.hub]
        watch += ["--udp-port", str(UDP_PORT)]
        self.watcher = Watcher(self.lab.command("obs", watch), self.folder / "obs.log")
        for host in ("trk", *DETECTOR_HOSTS):
            nodes = "tracker" if host == "trk" else "detectors"
            argv = [PY, "-m", "optrack.cli", "run", "--headless", "--nodes", nodes]
            argv += ["--config", str(self.config(host))]
            with (self.folder / f"{host}.log").open("wb") as log:
                self.launchers[host] = subprocess.Popen(
                    self.lab.command(host, argv),
                    stdin=subprocess.DEVNULL,
                    stdout=log,
                    stderr=subprocess.STDOUT,
                    env=dict(os.environ, PYTHONUNBUFFERED="1"),
                    start_new_session=True,
                )

    def alive(self) -> None:
        """Raise when a launcher or the watcher ended."""
        for host, process in self.launchers.items():
            if process.poll() is not None:
                tail = (self.folder / f"{host}.log").read_text(errors="replace")[-600:]
                raise UserError(f"'optrack run' on {host} ended ({process.returncode}): {tail}")
        if self.watcher is not None and self.watcher.process.poll() is not None:
            tail = (self.folder / "obs.log").read_text(errors="replace")[-600:]
            raise UserError(f"the station's watcher ended: {tail}")

    def tracker_pid(self) -> int:
        """The tracker node's process on ``trk``, as its launcher's ``site`` status names it
        (every node is a fork of the launcher's fork server, which has that one's command)."""
        assert self.watcher is not None
        named = [e for e in self.watcher.select("status") if "pid.tracker" in e["values"]]
        pid = int(named[-1]["values"]["pid.tracker"]) if named else 0
        if pid <= 0 or pid not in descendants(self.launchers["trk"].pid):
            raise UserError("no tracker node runs on the tracker computer.")
        return pid

    def stop(self) -> None:
        """Every launcher as Ctrl-C stops it (then killed, with its nodes), the watcher."""
        trees = {h: descendants(p.pid) for h, p in self.launchers.items()}
        for process in self.launchers.values():
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
        for host, process in self.launchers.items():
            try:
                process.wait(15.0)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
            for pid in trees[host]:
                try:
                    os.kill(pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
        if self.watcher is not None:
            self.watcher.close()


# ------------------------------------------------------------------ the steps
def _started(site: SiteLab, protocol: SiteProtocol) -> float:
    """Step 3: tracks at the station and the tracker hearing every sensor; the time."""
    watcher = site.watcher
    assert watcher is not None
    begun = time.monotonic()

    def heard_all() -> bool:
        status = [e for e in watcher.select("status") if e["node"] == "tracker"][-1:]
        values = status[0]["values"] if status else {}
        every = all(float(values.get(f"hz.{s}", 0.0)) > 0 for s in SENSORS)
        return (
            every
            and not str(values.get("silent_sensors", ""))
            and bool(watcher.first("udp", time.time() - 1.0, tracking))
        )

    wait_for(heard_all, protocol.start_timeout_s, "tracks from all three sensors", site.alive)
    time.sleep(protocol.settle_s)
    return time.monotonic() - begun


def _link_cut(site: SiteLab, protocol: SiteProtocol) -> dict[str, Any]:
    """Step 4: ``d0``'s cable out for ``cut_s``, then back."""
    watcher = site.watcher
    assert watcher is not None
    sensor = SENSORS[0]
    cut = time.time()
    site.lab.cable("d0", up=False)
    try:
        time.sleep(protocol.cut_s)
    finally:
        site.lab.cable("d0", up=True)
    back = time.time()
    reported = watcher.first("status", cut, lambda e: e["node"] == "tracker" and silent(e, sensor))
    during = [e for e in watcher.select("udp", cut) if e["t"] < back and tracking(e)]

    def heard_again() -> dict[str, Any] | None:
        return watcher.first(
            "status",
            back,
            lambda e: (
                e["node"] == "tracker"
                and not silent(e, sensor)
                and float(e["values"].get(f"hz.{sensor}", 0.0)) > 0
            ),
        )

    rejoined = wait_for(heard_again, protocol.rejoin_timeout_s, f"{sensor} heard again", site.alive)
    synced = watcher.first(
        "status", back, lambda e: e["node"] == sensor and e["values"].get("synchronised")
    )
    return {
        "link_rejoin_s": round(rejoined["t"] - back, 2),
        "link_silent_reported_s": round(reported["t"] - cut, 2) if reported else None,
        "link_cut_tracks_datagrams": len(during),
        "link_resynced_status_s": round(synced["t"] - back, 2) if synced else None,
    }


def _tracker_kill(site: SiteLab, protocol: SiteProtocol) -> dict[str, Any]:
    """Step 5: SIGKILL the tracker node; its launcher restarts it."""
    watcher = site.watcher
    assert watcher is not None
    pid = site.tracker_pid()
    before = [e for e in watcher.select("udp", time.time() - 1.0) if tracking(e)]
    killed = time.time()
    os.kill(pid, signal.SIGKILL)
    after = killed + 0.05  # a datagram already in flight is not the new tracker's
    first = wait_for(
        lambda: watcher.first("udp", after, tracking),
        protocol.recovery_timeout_s,
        "tracks after the tracker was killed",
        site.alive,
    )
    last = before[-1] if before else {"t": killed, "tracks": []}
    kept = _ids_kept(last["tracks"], first["tracks"], first["t"] - last["t"])
    return {
        "tracker_recovery_s": round(first["t"] - killed, 2),
        "tracker_ids_kept": f"{kept}/{len(last['tracks'])}",
    }


def _ids_kept(before: list[list[float]], after: list[list[float]], gap_s: float) -> int:
    """How many people of the last frame before the kill have their ID in the first frame
    after it: the nearest track after, within what a walker covers in the gap (0.5 m +
    1.5 m/s), carries the same ID."""
    gate = 0.5 + 1.5 * gap_s
    kept = 0
    for ident, x, y in before:
        near = min(after, key=lambda t: math.hypot(t[1] - x, t[2] - y), default=None)
        if near is not None and math.hypot(near[1] - x, near[2] - y) <= gate:
            kept += int(near[0]) == int(ident)
    return kept


def _foreign_nodes(site: SiteLab) -> dict[str, subprocess.Popen[str]]:
    """Step 6 (started): from ``d2``, a node with another site's keys and one without keys
    try to join the site as a detector node would (:func:`site_probe.join`)."""
    init_site(site.folder / "foreign-keys", [SENSORS[0]], site="elsewhere")
    started = {}
    for label, keys in (("foreign_keys", str(site.folder / "foreign-keys")), ("no_keys", "")):
        argv = [PY, "-m", "optrack.bench.site_probe", "join", "--site", SITE, "--keys", keys]
        argv += ["--identity", SENSORS[0], "--connect", site.hub]
        started[label] = subprocess.Popen(
            site.lab.command("d2", argv), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
    return started


def _refused(started: dict[str, subprocess.Popen[str]]) -> dict[str, Any]:
    """Step 6 (the answers): each must have been refused."""
    refused = {}
    for label, process in started.items():
        out, err = process.communicate(timeout=120)
        lines = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
        refused[label] = bool(lines) and not lines[-1]["joined"]
        if not refused[label]:
            info(f"{label} was not refused: {(out + err).strip()[-300:]}")
    return {"foreign_node_refused": all(refused.values()), "foreign_nodes": refused}


def _injections(site: SiteLab) -> dict[str, Any]:
    """Step 7: what a compromised detector computer (``d2``, its own keys) tries."""
    watcher = site.watcher
    assert watcher is not None
    folder = site.folder / "injected-recording"
    start = time.time()
    argv = [PY, "-m", "optrack.bench.site_probe", "inject", "--site", SITE]
    argv += ["--keys", site.copied_keys("d2"), "--identity", SENSORS[2], "--connect", site.hub]
    argv += ["--victim", SENSORS[0], "--folder", str(folder)]
    argv += ["--udp-target", f"{site.address('d2')}:{UDP_PORT}"]
    out = site.run(argv, 120, host="d2")
    report = json.loads(out.strip().splitlines()[-1])
    time.sleep(1.0)
    seen = {(e["what"], e["key"].rsplit("/", 1)[-1]) for e in watcher.select("seen", start)}
    control = watcher.first(
        "status", start, lambda e: e["node"] == SENSORS[2] and e["state"] == "control"
    )
    reached = {
        "command": report["command_replies"] > 0 or folder.exists(),
        "params": ("params", "tracker") in seen,
        "detections_foreign_sensor": ("detections", "intruder") in seen,
        "detections_other_sensor": ("detections", SENSORS[0]) in seen,
        "calibration": any(what == "calibration" for what, _ in seen),
    }
    refused = sum(not r for r in reached.values()) if control else 0
    return {
        "injections_tried": len(report["tried"]),
        "injections_refused": refused,
        "injections_reached": sorted(k for k, r in reached.items() if r),
        "injection_control_seen": control is not None,
    }


def _datagrams(site: SiteLab) -> dict[str, Any]:
    assert site.watcher is not None
    udp = site.watcher.select("udp")
    return {"datagrams": len(udp), "datagrams_unparseable": sum(not e["ok"] for e in udp)}


def _restarts(site: SiteLab) -> dict[str, int]:
    """Restarts of each node, from the launchers' ``site`` statuses."""
    assert site.watcher is not None
    counts: dict[str, int] = {}
    for event in site.watcher.select("status"):
        for key, value in event["values"].items():
            if event["node"] == "site" and key.startswith("restarts."):
                counts[key.removeprefix("restarts.")] = int(value)
    return counts


def site_bench(
    recording: str | os.PathLike[str] | None = None, protocol: SiteProtocol | None = None
) -> dict[str, Any]:
    """Run the steps of the module docstring; the figures (``recording``: the venue to
    play, three sensors ``kinect2_0..2``; default: rendered once and cached)."""
    problem = netns_problem()
    if problem is not None:
        raise UserError(f"optrack bench site needs network namespaces: {problem}.")
    protocol = protocol or SiteProtocol()
    path = Path(recording or venue_recording("mixed", 0, protocol.recording_s))
    with tempfile.TemporaryDirectory(prefix="optrack-bench-site-") as temp:
        site = SiteLab(Path(temp), path.resolve())
        began = time.monotonic()
        site.make_keys()
        with site.lab:
            try:
                site.start()
                result = _steps(site, protocol)
            finally:
                site.stop()
        result["bench_s"] = round(time.monotonic() - began, 1)
    return result


def _steps(site: SiteLab, protocol: SiteProtocol) -> dict[str, Any]:
    """Steps 3 to 7 on the running site; the figures."""
    result: dict[str, Any] = {"start_s": round(_started(site, protocol), 1)}
    info(f"site up on {len(HOSTS)} computers in {result['start_s']} s")
    result.update(_link_cut(site, protocol))
    info(f"link cut: rejoined in {result['link_rejoin_s']} s")
    wait_for(lambda: _fresh_tracks(site), 30.0, "tracks before the kill", site.alive)
    result.update(_tracker_kill(site, protocol))
    info(f"tracker killed: tracks again in {result['tracker_recovery_s']} s")
    intruders = time.monotonic()
    joining = _foreign_nodes(site)
    result.update(_injections(site))
    result.update(_refused(joining))
    result["intruders_s"] = round(time.monotonic() - intruders, 1)
    result.update(_datagrams(site))
    result["restarts"] = _restarts(site)
    result["computers"] = {h: site.address(h) for h in HOSTS}
    result["load_average"] = [round(x, 2) for x in os.getloadavg()]
    return result


def _fresh_tracks(site: SiteLab) -> bool:
    assert site.watcher is not None
    return site.watcher.first("udp", time.time() - 0.5, tracking) is not None
