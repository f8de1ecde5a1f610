"""``optrack run``: a whole site on this computer, one process per node.

The launcher hosts the site's bus hub (a Zenoh router on
``tcp/127.0.0.1:<bus.local_port>``, loopback only), then starts as child
processes one detector node per sensor and the tracker node, which sends the
outputs itself, all connecting to the hub. Each node is forked from one fork
server that imported what nodes need once (:mod:`optrack.runtime.starter`). Without ``site.sensors`` the
sensors are the embedded venue: the simulated ``site.scenario`` (``mixed``:
three Kinect v2, four to six people), each sensor rendered live by its
detector node (``sim://``, :func:`optrack.runtime.venue.venue_uris`), every
one on the same clock, forwards only; nothing is rendered before the start.

It supervises the children: one that stops unexpectedly is reported (on
stderr and in the ``site`` status on the bus) and restarted after
``site.restart_delay_s`` (longer when it keeps failing at start); a
detector whose recording ended is not. Ctrl-C (or ``--seconds``) sends every
node SIGTERM (each stops its loop, closes its bus and exits) and kills what
has not ended after ``site.stop_timeout_s``.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from optrack.errors import UserError
from optrack.net.bus import Bus
from optrack.net.keys import check_name
from optrack.net.messages import StatusMessage
from optrack.outputs.udp import join_destinations, no_receiver_note
from optrack.params import Params, save_config
from optrack.runtime.config import NodeConfig, state_dir
from optrack.runtime.display import display_problem
from optrack.runtime.node import PARENT_ENV
from optrack.runtime.starter import NodeProcess, NodeStarter
from optrack.runtime.venue import venue_uris

__all__ = ["Child", "Site", "SiteError"]

log = logging.getLogger("optrack.runtime.site")

QUICK_FAILURE_S = 10.0  # a child that dies sooner than this after starting backs off


class SiteError(UserError):
    """A site that cannot start."""


@dataclasses.dataclass
class Child:
    """One node process of the site."""

    name: str
    role: str  # detector, tracker, gui (outputs: a separate outputs process)
    module: str
    args: list[str]
    process: subprocess.Popen[bytes] | NodeProcess | None = None
    state: str = "new"  # running, waiting (to restart), ended, stopped
    started_at: float = 0.0
    restart_at: float = 0.0
    restarts: int = 0
    delay: float = 0.0
    last_exit: int | None = None

    @property
    def label(self) -> str:
        return {
            "detector": f"detector node '{self.name}'",
            "tracker": "tracker node",
            "outputs": "outputs node",
            "skeleton": "skeleton node",
            "gui": "operator application",
        }[self.role]

    @property
    def argv(self) -> list[str]:
        return [sys.executable, "-m", self.module, *self.args]

    @property
    def pid(self) -> int | None:
        return self.process.pid if self.process is not None else None


def describe_exit(code: int) -> str:
    if code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exit status {code}"


class Site:
    """The local site launcher and supervisor (see the module docstring)."""

    def __init__(
        self,
        config: NodeConfig,
        udp: list[str] | None = None,
        headless: bool = True,
        seconds: float | None = None,
        recording: str | None = None,
        speed: float = 1.0,
        loop: bool = False,
        skeleton: bool = False,
        nodes: str = "all",
    ) -> None:
        """``nodes``: which of the site's nodes run on this computer (``all``; ``tracker``:
        every node but the detectors; ``detectors``: only them), for a site spread over
        several computers (docs/runtime.md, Several computers).
        ``recording``: play it through the pipeline instead of ``site.sensors`` (one
        detector node per sensor, started paused and resumed together; ``speed`` times
        the recorded pace; ``loop`` plays it again at its end, else the site stops there).
        ``skeleton``: turn the skeleton stage on (``skeleton_live.enabled``: the
        detectors publish people's points, a skeleton node is started)."""
        if skeleton:
            config["skeleton_live"].update({"enabled": True})
            config.explicit.setdefault("skeleton_live", {})["enabled"] = True
        self.config = config
        self.params: Params = config["site"]
        self.name = check_name("site", str(self.params.name))
        if udp:
            config["outputs"].update({"udp": join_destinations(udp)})
        if seconds is not None and not seconds > 0:
            raise SiteError(f"--seconds must be > 0; got {seconds:g}.")
        self.headless = headless
        self.seconds = seconds
        self.nodes = nodes
        self.children: list[Child] = []
        self.statuses: dict[str, StatusMessage] = {}
        self.hub: Bus | None = None
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._run_dir: Path | None = None
        self._starter: NodeStarter | None = None
        self.operator: Any = None  # the simulated operator (calibration wizard), if simulated
        self._receivers: dict[str, tuple[str, int]] = {}  # destination -> (said, errors then)
        self._venue_sensors = False  # the sensors are the embedded venue
        self._skeleton_wanted = False
        self.playback = None
        if recording is not None:
            from optrack.runtime.node_recording import SitePlayback

            self.playback = SitePlayback(recording, speed, loop)

    # ---------------------------------------------------------------- setup
    def sensor_uris(self) -> list[str]:
        if self.playback is not None:
            return self.playback.uris()
        listed = [u.strip() for u in str(self.params.sensors).split(",") if u.strip()]
        if listed:
            return listed
        # Rendered live by each detector node: nothing to render first, forwards only.
        self._venue_sensors = True
        return venue_uris(str(self.params.scenario), int(self.params.seed))

    def _write_configs(self, run_dir: Path) -> dict[str, Path]:
        """The children's config files: the values the user's file set, the hub to connect
        to, and the outputs (``--udp`` included). Stages left out keep their defaults (a
        detector's ``detection`` defaults are its sensor model's)."""
        endpoint = f"tcp/127.0.0.1:{int(self.config['bus'].local_port)}"
        common = {stage: dict(values) for stage, values in self.config.explicit.items()}
        common.setdefault("bus", {}).update(  # the hub's bus.listen is not theirs
            {"mode": "client", "connect": endpoint, "listen": "", "multicast_scouting": False}
        )
        common["bus"]["gossip"] = False
        common["bus"].pop("identity", None)  # each node presents its own (bus.keys)
        # An insecure peer hub listens on plain tcp: its nodes join it the same way (and
        # a secure one's with keys, whatever the user's file says of bus.insecure).
        common["bus"]["insecure"] = self.hub is not None and self.hub.insecure
        common.setdefault("node", {})["state_dir"] = str(state_dir(self.config, self.name))
        common["outputs"] = self.config["outputs"].as_dict()
        paths = {}
        for role in ("detector", "tracker", "skeleton"):
            values = {stage: dict(v) for stage, v in common.items()}
            if role == "skeleton":  # started when the stage is on, at start or later
                values.setdefault("skeleton_live", {})["enabled"] = True
            if role == "detector":
                values["node"]["nice"] = int(self.params.detector_nice)
                if self._venue_sensors and "replay_max_age_s" not in self.config.explicit.get(
                    "node", {}
                ):
                    values["node"]["replay_max_age_s"] = float(self.params.venue_max_age_s)
            if role == "tracker":  # the outputs in the tracker's process: no hop to the datagram
                values["node"]["outputs"] = True
            paths[role] = run_dir / f"{role}.yaml"
            save_config(paths[role], values)
        if str(self.config["bus"].mode) != "local":  # the window joins this hub as they do
            values = {stage: dict(v) for stage, v in common.items()}
            identity = self.config.explicit.get("bus", {}).get("identity")
            if identity:  # the station's certificate of bus.keys
                values["bus"]["identity"] = identity
            paths["gui"] = run_dir / "gui.yaml"
            save_config(paths["gui"], values)
        return paths

    def _children(self, uris: list[str], configs: dict[str, Path]) -> list[Child]:
        import optrack.sim.sensor  # noqa: F401 - registers sim://
        from optrack.sensors.uri import expected_sensor_id

        children = []
        seen: set[str] = set()
        for k, uri in enumerate(uris):
            # the node's own name (the one the operator and the wizard wait for)
            name = expected_sensor_id(uri) or f"sensor{k}"
            if name in seen:
                raise SiteError(
                    f"two sensors of site.sensors are both named '{name}'; give each a unique "
                    "id with ?id=NAME."
                )
            seen.add(name)
            args = ["node", "detect", "--sensor", uri, "--site", self.name]
            children.append(
                Child(
                    name, "detector", "optrack.cli", [*args, "--config", str(configs["detector"])]
                )
            )
        children.append(
            Child(
                "tracker",
                "tracker",
                "optrack.cli",
                ["node", "track", "--site", self.name, "--config", str(configs["tracker"])],
            )
        )
        if self.config["skeleton_live"].enabled:
            children.append(self._skeleton_child(configs["skeleton"]))
        if not self.headless:
            problem = display_problem()
            if problem is None:
                args = ["gui", "--join", "--site", self.name]
                config = configs.get("gui", self.config.path)
                if config is not None:
                    args += ["--config", str(config)]
                children.append(Child("gui", "gui", "optrack.cli", args))
            else:
                log.info("no window (%s); running headless.", problem)
        return children

    def _skeleton_child(self, config: Path) -> Child:
        args = ["--site", self.name, "--config", str(config)]
        return Child("skeleton", "skeleton", "optrack.runtime.skeleton_node", args)

    @staticmethod
    def _server_env() -> dict[str, str]:
        """What the nodes' environment has for the libraries they load."""
        return {
            "PYTHONUNBUFFERED": "1",
            # Each node is its own process: OpenBLAS's threads per node (as many as cores)
            # would only spin against the other nodes (a 640x480 transform: 40 ms of CPU).
            "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS", "1"),
        }

    def _node_env(self) -> dict[str, str]:
        """What a node's environment adds to the launcher's."""
        return {PARENT_ENV: str(os.getpid()), **self._server_env()}

    def _popen(self, argv: list[str]) -> subprocess.Popen[bytes]:
        return subprocess.Popen(
            argv,
            stdin=subprocess.DEVNULL,
            stdout=sys.stderr.fileno(),
            stderr=sys.stderr.fileno(),
            env={**os.environ, **self._node_env()},
            start_new_session=True,  # Ctrl-C reaches the launcher only; it stops the nodes
        )

    def _node_starter(self) -> NodeStarter:
        """The fork server's starter, started on first use."""
        if self._starter is None:
            self._starter = NodeStarter(self._node_env(), self._server_env())
            self._starter.prepare()
        return self._starter

    def _spawn(self, child: Child) -> None:
        """Start a child: a node forked from the fork server (imports done,
        :mod:`optrack.runtime.starter`), the window as its own process."""
        process: subprocess.Popen[bytes] | NodeProcess | None = None
        if child.role != "gui":
            process = self._node_starter().start(child.name, child.module, child.args)
        if process is None:
            process = self._popen(child.argv)
        child.process = process
        child.state = "running"
        child.started_at = time.monotonic()

    def host(self) -> None:
        """Host the site's hub (a Zenoh router on loopback) and listen to every status."""
        if self.hub is None:
            self.hub = Bus(self.name, "site", self.config["bus"], host=True)
            self.hub.subscribe(self.hub.keys.status(), StatusMessage, self._on_status)
            if self.hub.insecure:
                log.warning(
                    "site '%s' runs insecure (bus.insecure, no keys): anyone on the network "
                    "may join it and send commands; secure it with 'optrack site init' and "
                    "bus.keys.",
                    self.name,
                )

    def start(self) -> None:
        """Host the hub, render/prepare the sensors (progress in the site status), start
        every node."""
        self._node_starter()  # its imports run while the hub starts
        self.host()
        uris = self.sensor_uris()
        self._run_dir = Path(tempfile.mkdtemp(prefix="optrack-run-"))
        configs = self._write_configs(self._run_dir)
        self.children = [
            c
            for c in self._children(uris, configs)
            if self.nodes == "all" or (c.role == "detector") == (self.nodes == "detectors")
        ]
        if self.playback is None and self.nodes != "tracker":
            self._attach_operator(uris)
        order = ("tracker", "detector", "skeleton", "gui")  # the clock first
        for role in order:
            for child in self.children:
                if child.role == role:
                    self._spawn(child)
        log.info(
            "site '%s' on tcp/127.0.0.1:%d: %d detector node(s), tracker with outputs (%s)",
            self.name,
            int(self.config["bus"].local_port),
            sum(c.role == "detector" for c in self.children),
            ", ".join(self._outputs_described()) or "none",
        )

    def _outputs_described(self) -> list[str]:
        out = self.config["outputs"]
        found = []
        if str(out.udp).strip():
            found.append(f"UDP JSON to {out.udp}")
        if str(out.osc).strip():
            found.append(f"OSC to {out.osc}")
        if str(out.websocket).strip():
            found.append(f"WebSocket on {out.websocket}")
        return found

    def _on_status(self, message: StatusMessage, key: str) -> None:
        with self._lock:
            self.statuses[message.node] = message
        if message.role == "detector" and message.params.get("skeleton_live", {}).get("enabled"):
            self._skeleton_wanted = True  # turned on live: the skeleton node starts

    def _start_skeleton(self) -> None:
        """Start the skeleton node once a detector runs the skeleton stage (turned on live)."""
        if not self._skeleton_wanted or self._run_dir is None:
            return
        if any(child.role == "skeleton" for child in self.children):
            return
        child = self._skeleton_child(self._run_dir / "skeleton.yaml")
        self.children.append(child)
        self._spawn(child)
        log.info("the skeleton stage is on: started the skeleton node (pid %s).", child.pid)

    # ------------------------------------------------- the simulated operator
    def _attach_operator(self, uris: list[str]) -> None:
        """On a simulated site, answer the ``operator`` command (calibration wizard)."""
        from optrack.runtime.node import send_command
        from optrack.sim.operator import SimulatedOperator

        assert self.hub is not None and self._run_dir is not None
        names = [c.name for c in self.children if c.role == "detector"]
        self.operator = SimulatedOperator.for_site(self.params, uris, names, self._run_dir)
        if self.operator is not None:
            self.operator.serve(self.hub, send_command)

    # ----------------------------------------------------------- supervision
    def supervise_once(self, now: float) -> None:
        """Notice ended children, restart the ones due; start the skeleton node when the
        skeleton stage was turned on."""
        self._start_skeleton()
        for child in self.children:
            if child.state == "running" and child.process is not None:
                code = child.process.poll()
                if code is None:
                    continue
                child.last_exit = code
                if child.role == "gui":
                    log.info("the operator application closed; stopping the site.")
                    child.state = "ended"
                    self._stop.set()
                    continue
                if code == 0 and child.role == "detector":
                    child.state = "ended"
                    log.info("%s ended: its sensor has no more frames.", child.label)
                    continue
                ran = now - child.started_at
                base = float(self.params.restart_delay_s)
                if ran < QUICK_FAILURE_S and child.restarts > 0:
                    child.delay = min(
                        max(child.delay * 2, base, 0.5), float(self.params.max_restart_delay_s)
                    )
                else:
                    child.delay = base
                child.state = "waiting"
                child.restart_at = now + child.delay
                log.warning(
                    "%s stopped unexpectedly (%s) after %.1f s; restarting it in %.1f s.",
                    child.label,
                    describe_exit(code),
                    ran,
                    child.delay,
                )
                self.publish_status()
            elif child.state == "waiting" and now >= child.restart_at:
                self._spawn(child)
                child.restarts += 1
                log.info(
                    "restarted %s (restart %d, pid %s).", child.label, child.restarts, child.pid
                )
                self.publish_status()

    def status(self) -> StatusMessage:
        values: dict[str, Any] = {}
        for child in self.children:
            values[f"state.{child.name}"] = child.state
            values[f"pid.{child.name}"] = child.pid or 0
            values[f"restarts.{child.name}"] = child.restarts
        if self.operator is not None:
            values.update(self.operator.status_values())
        if self.hub is not None and self.hub.insecure:  # as every node's status says
            values["insecure"] = True
        return StatusMessage(
            node="site",
            role="site",
            state="stopping" if self._stop.is_set() else "running",
            stamp=time.time(),
            values=values,
            counters=self.hub.stats.snapshot() if self.hub is not None else {},
        )

    def publish_status(self) -> None:
        if self.hub is not None and not self.hub.closed:
            self.hub.publish(self.hub.keys.status("site"), self.status())

    def summary(self) -> str:
        """One line: each node's rate, latency and drops; tracks; outputs."""
        with self._lock:
            statuses = dict(self.statuses)
        parts = []
        detectors = [c for c in self.children if c.role == "detector"]
        for child in detectors:
            s = statuses.get(child.name)
            if child.state != "running" or s is None:
                parts.append(
                    f"{child.name} {child.state if child.state != 'running' else 'starting'}"
                )
            else:
                parts.append(
                    f"{child.name} {s.fps:.1f} fps {s.latency_ms:.0f} ms dropped {s.dropped}"
                )
        tracker = statuses.get("tracker")
        if tracker is not None:
            parts.append(
                f"tracker {tracker.fps:.0f} Hz {tracker.latency_ms:.0f} ms, "
                f"{tracker.values.get('tracks', 0)} tracks"
            )
        skeleton = statuses.get("skeleton")
        if skeleton is not None:
            count = skeleton.values.get("skeletons", 0)
            parts.append(f"skeleton {skeleton.fps:.0f} Hz, {count} skeletons")
        outputs = statuses.get("outputs")
        if outputs is not None:
            for d in outputs.destinations:
                parts.append(f"{d.kind} {d.address} sent {d.sent}{self._receiver_note(d)}")
        return "; ".join(parts)

    def _receiver_note(self, d: Any) -> str:
        """What the summary says of a destination's receiver: "no receiver on ADDRESS yet"
        once (not at every report while nobody listens), "a receiver listens on ADDRESS
        now" once when its errors stop, the error count for real faults."""
        waiting = no_receiver_note(d.address, d.last_error)
        if not waiting:
            return f", {d.errors} errors" if d.errors else ""
        key = f"{d.kind} {d.address}"
        said, errors = self._receivers.get(key, ("", -1))
        self._receivers[key] = (said, d.errors)
        if said != "waiting" and d.errors > errors:  # nobody listens (again)
            self._receivers[key] = ("waiting", d.errors)
            return f", {waiting}"
        if said == "waiting" and d.errors == errors:  # refused no datagram since the last report
            self._receivers[key] = ("listening", d.errors)
            return f", a receiver listens on {d.address} now"
        return ""

    # ------------------------------------------------------------------ stop
    def request_stop(self) -> None:
        self._stop.set()

    def stop(self) -> None:
        """Stop every child (SIGTERM, then SIGKILL after ``site.stop_timeout_s``), then the
        hub."""
        self._stop.set()
        timeout = float(self.params.stop_timeout_s)
        started = time.monotonic()
        killed = 0
        # All at once: each node stops its loop, closes its bus and exits by itself.
        running = [c for c in self.children if c.process is not None and c.process.poll() is None]
        for child in running:
            try:
                child.process.send_signal(signal.SIGTERM)  # type: ignore[union-attr]
            except ProcessLookupError:
                pass
        deadline = time.monotonic() + timeout
        for child in running:
            assert child.process is not None
            try:
                child.process.wait(max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                log.warning("%s did not stop within %.1f s; killing it.", child.label, timeout)
                child.process.kill()
                child.process.wait()
                killed += 1
        for child in self.children:
            if child.state in ("running", "waiting"):
                child.state = "stopped"
        if self.hub is not None:
            try:
                self.publish_status()
            finally:
                self.hub.close()
        if self.children:
            log.info(
                "site stopped in %.1f s (%d node(s) stopped%s).",
                time.monotonic() - started,
                len(self.children),
                f", {killed} killed" if killed else " cleanly",
            )
        if self._run_dir is not None:
            shutil.rmtree(self._run_dir, ignore_errors=True)
            self._run_dir = None

    def run(self) -> int:
        """Start, supervise until Ctrl-C, ``--seconds`` or the window closing, stop."""
        previous = {
            sig: signal.signal(sig, lambda number, frame: self.request_stop())
            for sig in (signal.SIGINT, signal.SIGTERM)
        }
        started = time.monotonic()
        try:
            self.start()  # starting the nodes does not count in --seconds
            started = time.monotonic()
            deadline = started + self.seconds if self.seconds is not None else None
            report_s = float(self.params.report_s)
            next_report = time.monotonic() + report_s
            next_status = time.monotonic()
            while not self._stop.is_set():
                now = time.monotonic()
                if deadline is not None and now >= deadline:
                    break
                self.supervise_once(now)
                if self.playback is not None and self.hub is not None:
                    if not self.playback.tick(self.hub, self.children, self.statuses, self._lock):
                        break  # the recording has played to its end
                if now >= next_status:
                    self.publish_status()
                    next_status = now + 1.0
                if report_s > 0 and now >= next_report:
                    log.info("%s", self.summary())
                    next_report = now + report_s
                self._stop.wait(0.1)
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)
            log.info("stopping the site after %.1f s.", time.monotonic() - started)
            self.stop()
        return 0
