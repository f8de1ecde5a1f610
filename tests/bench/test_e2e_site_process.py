"""A site measured as a black box (optrack.bench.site_process): the processes a launcher
started and their CPU time from /proc, and a launcher that cannot start said in one
sentence."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time

import pytest

from optrack.bench.site_process import (
    DatagramReceiver,
    SiteProcess,
    _children_by_parent,
    cpu_seconds,
    descendants,
    free_port,
)
from optrack.errors import UserError
from optrack.net.messages import StatusMessage

# A child that starts a grandchild, prints its pid, then both wait to be ended.
PARENT = (
    "import subprocess, sys\n"
    "g = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)'])\n"
    "print(g.pid, flush=True)\n"
    "g.wait()\n"
)


def test_descendants_are_children_and_their_children():
    child = subprocess.Popen([sys.executable, "-c", PARENT], stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout is not None
        grandchild = int(child.stdout.readline())
        assert descendants(child.pid) == [grandchild]
        assert set(descendants(os.getpid())) >= {child.pid, grandchild}
        assert grandchild in _children_by_parent()[child.pid]  # where /proc has no children files
        assert descendants(grandchild) == []
    finally:
        for pid in descendants(child.pid):
            os.kill(pid, 9)
        child.wait()


def test_cpu_seconds_grow_while_a_process_works_and_are_zero_once_it_is_gone():
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        deadline = time.monotonic() + 30.0
        while cpu_seconds(busy.pid) < 0.05 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert cpu_seconds(busy.pid) >= 0.05
    finally:
        busy.kill()
        busy.wait()
    assert cpu_seconds(busy.pid) == 0.0


def test_a_launcher_that_refuses_its_config_is_one_sentence(tmp_path, capfd):
    values = {"bus": {"local_port": free_port()}, "site": {"name": "bench", "report_s": -1.0}}
    site = SiteProcess(values, tmp_path)
    with pytest.raises(UserError, match=r"^'optrack run' ended at start \(exit status 1\)"):
        site.start(120.0)
    assert site.stop() == 1
    assert "report_s" in capfd.readouterr().err  # the launcher's own sentence, on stderr
    assert (tmp_path / "site.yaml").read_text().startswith("bus:\n  local_port:")


def test_the_receiver_keeps_every_datagram_with_its_arrival_time():
    receiver = DatagramReceiver()
    receiver.start()
    host, port = receiver.address.split(":")
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
            for k in range(3):
                sender.sendto(json.dumps({"sec": k}).encode(), (host, int(port)))
            deadline = time.monotonic() + 5.0
            while len(receiver.arrivals) < 3 and time.monotonic() < deadline:
                time.sleep(0.01)
    finally:
        receiver.close()
    assert [json.loads(data)["sec"] for _, data in receiver.arrivals] == [
        0,
        1,
        2,
    ]
    assert all(abs(arrived - time.time()) < 10 for arrived, _ in receiver.arrivals)


def test_the_launchers_site_status_names_its_nodes_and_counts_their_restarts(tmp_path):
    values = {"bus": {"local_port": free_port()}, "site": {"name": "bench"}}
    site = SiteProcess(values, tmp_path)
    assert site.restarts() == 0 and site.site_values() == {}
    # a stand-in launcher: a process with one child (a node), the site status naming it
    site.process = subprocess.Popen([sys.executable, "-c", PARENT], stdout=subprocess.PIPE)
    try:
        node = int(site.process.stdout.readline())
        status = StatusMessage(
            node="site",
            role="site",
            state="running",
            stamp=time.time(),
            values={"pid.cam0": node, "restarts.cam0": 2, "pid.cam1": 0, "restarts.cam1": 1},
        )
        site._on_status(status, "optrack/bench/status/site")
        assert site.restarts() == 3
        assert site.pids() == {site.process.pid: "launcher", node: "cam0"}
    finally:
        for pid in descendants(site.process.pid):
            os.kill(pid, 9)
        site.process.wait()
    assert site.stop() == site.process.returncode
