"""The launcher's nodes forked from its fork server (optrack.runtime.starter): a node runs
`MODULE.main(ARGS)` with the imports already done, with the launcher's environment, its own
session and name, its stdout on stderr, and an exit status as `python -m` gives."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from optrack.runtime.node import PARENT_ENV
from optrack.runtime.starter import NodeStarter

MODULE = "tests.runtime.starter_node"


@pytest.fixture(scope="module")
def starter() -> NodeStarter:
    starter = NodeStarter({"OPTRACK_TEST_ADDED": "yes"}, {"OPENBLAS_NUM_THREADS": "1"})
    starter.prepare()
    return starter


def _report(path: Path, timeout: float = 60.0) -> dict:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if path.exists() and path.stat().st_size:
            return json.loads(path.read_text())
        time.sleep(0.05)
    raise AssertionError(f"the node wrote no {path}")


def test_a_node_runs_with_the_imports_done_in_the_launchers_environment(
    starter, tmp_path, monkeypatch
):
    monkeypatch.setenv("OPTRACK_TEST_LATER", "set after the fork server started")
    report = tmp_path / "report.json"
    node = starter.start("kinect2_long_name", MODULE, [str(report), "0"])
    assert node is not None
    assert node.wait(60) == 0
    found = _report(report)
    assert found["imported"]  # the fork server's imports: the node imports nothing more
    assert found["environ"]["OPTRACK_TEST_LATER"] == "set after the fork server started"
    assert found["environ"]["OPTRACK_TEST_ADDED"] == "yes"
    assert found["environ"]["OPENBLAS_NUM_THREADS"] == "1"  # the fork server's too
    assert found["environ"][PARENT_ENV] == str(found["ppid"])  # the fork server
    assert found["ppid"] != os.getpid() and found["pid"] == node.pid
    assert found["sid"] == node.pid  # its own session: Ctrl-C is the launcher's
    assert found["argv"] == [MODULE, str(report), "0"]
    assert found["cwd"] == os.getcwd()
    assert found["comm"] == "kinect2_long_na"  # what `top` shows (15 characters)
    assert found["stdout_is_stderr"]  # the node's output goes where the launcher logs


def test_its_exit_status_and_signals_are_those_of_a_process(starter, tmp_path):
    node = starter.start("failing", MODULE, [str(tmp_path / "a.json"), "7"])
    assert node is not None and node.wait(60) == 7 and node.returncode == 7
    report = tmp_path / "b.json"
    node = starter.start("waiting", MODULE, [str(report), "wait"])
    assert node is not None
    _report(report)
    with pytest.raises(subprocess.TimeoutExpired):
        node.wait(0.2)
    assert node.poll() is None
    node.send_signal(signal.SIGTERM)
    assert node.wait(30) == 3  # its own SIGTERM handler ran
    report = tmp_path / "c.json"
    node = starter.start("killed", MODULE, [str(report), "wait"])
    assert node is not None
    _report(report)
    node.kill()
    assert node.wait(30) == -signal.SIGKILL
    node.kill()  # an ended node: nothing to signal, no error


# A launcher whose fork server cannot start (its interpreter is missing): the launcher says
# so once, in one sentence, and starts each node as its own `python -m` process instead.
FALLBACK = """
import logging, multiprocessing, sys
logging.basicConfig(level=logging.INFO, format="%(message)s")
multiprocessing.set_executable("/nonexistent/python3")
from optrack.runtime.config import load_node_config
from optrack.runtime.site import Child, Site
site = Site(load_node_config(None, {"site": {"name": "fallback"}}))
for name in ("one", "two"):
    child = Child(name, "detector", sys.argv[1], [sys.argv[2] + "/" + name + ".json", "5"])
    site._spawn(child)
    print(name, type(child.process).__name__, child.process.wait(60), flush=True)
"""


def test_without_its_fork_server_the_launcher_says_so_and_starts_each_node_itself(tmp_path):
    root = Path(__file__).resolve().parents[2]
    result = subprocess.run(
        [sys.executable, "-c", FALLBACK, MODULE, str(tmp_path)],
        cwd=root, capture_output=True, text=True, timeout=180,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert result.stdout.split("\n")[:2] == ["one Popen 5", "two Popen 5"]
    said = [line for line in result.stderr.splitlines() if "fork server did not start" in line]
    assert len(said) == 1, result.stderr  # once, not per node
    assert said[0].endswith("each node starts as its own Python process, which takes longer.")
    for name in ("one", "two"):  # each ran as a process of its own, with the launcher's env
        found = _report(tmp_path / f"{name}.json")
        assert not found["imported"] and found["sid"] == found["pid"]
        assert found["environ"][PARENT_ENV] == str(found["ppid"])
        assert found["environ"]["OPENBLAS_NUM_THREADS"] == "1"
