"""A site measured as a black box: ``optrack run --headless`` started from a config file.

A benchmark sits below the runtime, so it never imports it: it writes the site's
configuration (the YAML file ``optrack run --config`` reads, one mapping per stage),
starts the launcher as a subprocess (``python -m optrack.cli run --headless``), and
watches what any client could: the statuses on the site's bus (the launcher's hub on
``tcp/127.0.0.1:<bus.local_port>``, joined as a client), its own outputs (UDP, ...),
and ``/proc`` (CPU time of the launcher and of every process it started). The ``site``
status of the launcher names its nodes' pids and counts their restarts.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import yaml

from optrack.errors import UserError
from optrack.net.bus import Bus, BusError
from optrack.net.config import BUS_PARAMS
from optrack.net.messages import StatusMessage

__all__ = [
    "LAUNCHER",
    "DatagramReceiver",
    "SiteProcess",
    "cpu_seconds",
    "descendants",
    "free_port",
]

#: How the launcher's own processes are named in :meth:`SiteProcess.pids`.
LAUNCHER = "launcher"


def free_port() -> int:
    """A TCP port of 127.0.0.1 that nothing listens on now."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _stat_fields(pid: int) -> list[str] | None:
    """The fields of /proc/<pid>/stat after the command name (None when it is gone)."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as stat:
            return stat.read().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process, s (0 when it is gone)."""
    fields = _stat_fields(pid)
    if fields is None or len(fields) < 13:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _children(pid: int) -> list[int] | None:
    """The children of ``pid`` from /proc/<pid>/task/*/children (None where the kernel
    does not keep those files)."""
    tasks = Path(f"/proc/{pid}/task")
    found: list[int] = []
    try:
        for task in tasks.iterdir():
            found += [int(c) for c in (task / "children").read_text().split()]
    except FileNotFoundError:
        return None if tasks.is_dir() else []
    except (OSError, ValueError):
        return []
    return found


def _children_by_parent() -> dict[int, list[int]]:
    """Every process's children, from the parent pid in each /proc/<pid>/stat."""
    table: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            fields = _stat_fields(int(entry.name))
            if fields is not None and len(fields) > 1:
                table.setdefault(int(fields[1]), []).append(int(entry.name))
    return table


def descendants(pid: int) -> list[int]:
    """Every process ``pid`` started, their children and so on (not ``pid`` itself)."""
    table: dict[int, list[int]] | None = None
    found: list[int] = []
    pending = [pid]
    while pending:
        parent = pending.pop()
        children = _children(parent)
        if children is None:  # no children files: read every process's parent once
            table = _children_by_parent() if table is None else table
            children = table.get(parent, [])
        found += children
        pending += children
    return found


class DatagramReceiver:
    """A UDP socket on 127.0.0.1 that keeps every datagram with its arrival time (a site's
    outputs to ``address``), from :meth:`start` to :meth:`close`."""

    def __init__(self) -> None:
        self.socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.socket.bind(("127.0.0.1", 0))
        self.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        self.arrivals: list[tuple[float, bytes]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._receive, daemon=True)

    @property
    def address(self) -> str:
        return f"127.0.0.1:{self.socket.getsockname()[1]}"

    def start(self) -> None:
        self._thread.start()

    def _receive(self) -> None:
        self.socket.settimeout(0.2)
        while not self._stop.is_set():
            try:
                data = self.socket.recv(65536)
            except TimeoutError:
                continue
            self.arrivals.append((time.time(), data))

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(2.0)
        self.socket.close()


def _bus_params(port: int, timeout_s: float) -> Any:
    """A client of the local site's hub on ``port``, as the site's own nodes connect."""
    return BUS_PARAMS.create(
        {
            "mode": "client",
            "connect": f"tcp/127.0.0.1:{port}",
            "multicast_scouting": False,
            "gossip": False,
            "connect_timeout_s": timeout_s,
        }
    )


class SiteProcess:
    """``optrack run --headless --config <folder>/site.yaml`` with ``values`` in the file
    (``bus.local_port`` and ``site.name`` must be set), its statuses gathered from the
    bus. Use as a context manager, or :meth:`start` then :meth:`stop`."""

    def __init__(
        self,
        values: Mapping[str, Mapping[str, Any]],
        folder: str | os.PathLike[str],
        args: tuple[str, ...] = (),
    ) -> None:
        self.values = {stage: dict(stage_values) for stage, stage_values in values.items()}
        self.site = str(self.values["site"]["name"])
        self.port = int(self.values["bus"]["local_port"])
        self.config = Path(folder) / "site.yaml"
        self.args = args
        self.process: subprocess.Popen[bytes] | None = None
        self.bus: Bus | None = None
        self._statuses: dict[str, StatusMessage] = {}
        self._lock = threading.Lock()

    # ---------------------------------------------------------------- start
    @property
    def argv(self) -> list[str]:
        command = ["run", "--headless", "--config", str(self.config), *self.args]
        return [sys.executable, "-m", "optrack.cli", *command]

    def start(self, timeout_s: float) -> None:
        """Write the config, start the launcher (its output on this process's stderr) and
        join its bus within ``timeout_s``."""
        self.config.write_text(yaml.safe_dump(self.values, sort_keys=False), encoding="utf-8")
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        self.process = subprocess.Popen(
            self.argv,
            stdin=subprocess.DEVNULL,
            stdout=sys.stderr.fileno(),  # this process's stdout carries only its figures
            stderr=sys.stderr.fileno(),
            env=env,
            start_new_session=True,  # a Ctrl-C here reaches this process, which stops it
        )
        deadline = time.monotonic() + timeout_s
        while self.bus is None:
            if not self.alive:
                raise UserError(f"'optrack run' ended at start ({self._exit()}); see above.")
            try:
                self.bus = Bus(self.site, "bench", _bus_params(self.port, 1.0))
            except BusError:
                if time.monotonic() >= deadline:
                    raise UserError(
                        f"'optrack run' did not open its hub on port {self.port} within "
                        f"{timeout_s:g} s."
                    ) from None
        self.bus.subscribe(self.bus.keys.status(), StatusMessage, self._on_status)

    def _on_status(self, message: StatusMessage, key: str) -> None:
        with self._lock:
            self._statuses[message.node] = message

    def _exit(self) -> str:
        code = self.process.poll() if self.process is not None else None
        return "not started" if code is None and self.process is None else f"exit status {code}"

    # ------------------------------------------------------------- watching
    @property
    def alive(self) -> bool:
        return self.process is not None and self.process.poll() is None

    @property
    def statuses(self) -> dict[str, StatusMessage]:
        """The latest status of every node (and of the launcher: ``site``)."""
        with self._lock:
            return dict(self._statuses)

    def wait(self, seconds: float, done: Callable[[], bool] | None = None) -> bool:
        """Wait ``seconds`` or until ``done()`` (checked every 0.1 s); False when the
        launcher ended meanwhile."""
        end = time.monotonic() + seconds
        while time.monotonic() < end and not (done is not None and done()):
            if not self.alive:
                return False
            time.sleep(0.1)
        return self.alive

    def site_values(self) -> dict[str, Any]:
        """The launcher's ``site`` status values (``pid.<node>``, ``restarts.<node>``...)."""
        site = self.statuses.get("site")
        return dict(site.values) if site is not None else {}

    def restarts(self) -> int:
        """How many times the launcher restarted a node so far (its ``site`` status)."""
        return sum(int(v) for k, v in self.site_values().items() if k.startswith("restarts."))

    def pids(self) -> dict[int, str]:
        """Every process of the site by pid: the node's name for a node (from the ``site``
        status), ``launcher`` for the launcher and any other process it started."""
        assert self.process is not None
        named = {
            int(v): k.removeprefix("pid.")
            for k, v in self.site_values().items()
            if k.startswith("pid.") and int(v) > 0
        }
        tree = [self.process.pid, *descendants(self.process.pid)]
        return {pid: named.get(pid, LAUNCHER) for pid in tree}

    def cpu(self) -> dict[int, float]:
        """CPU seconds used so far by each process of the site (see :meth:`pids`)."""
        return {pid: cpu_seconds(pid) for pid in self.pids()}

    # ----------------------------------------------------------------- stop
    def stop(self, timeout_s: float = 30.0) -> int | None:
        """Leave the bus, stop the launcher as Ctrl-C does (it stops its nodes), wait for
        it; kill what is left after ``timeout_s``. Returns its exit status."""
        if self.bus is not None:
            self.bus.close()
            self.bus = None
        if self.process is None:
            return None
        if self.process.poll() is None:
            tree = descendants(self.process.pid)
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(timeout_s)
            except subprocess.TimeoutExpired:
                for pid in [self.process.pid, *tree]:
                    try:
                        os.kill(pid, signal.SIGKILL)
                    except ProcessLookupError:
                        pass
                self.process.wait()
        return self.process.returncode

    def __enter__(self) -> SiteProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
