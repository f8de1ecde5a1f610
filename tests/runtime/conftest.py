"""Runtime fixtures: a small simulated venue recording, buses on free loopback ports,
and child processes that are always cleaned up."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.conftest import free_port  # noqa: F401 - the runtime tests import it from here

VENUE_SECONDS = 1.5


@pytest.fixture(scope="session")
def venue(tmp_path_factory) -> Path:
    """1.5 s of the 'mixed' venue: three simulated Kinect v2 and walking people."""
    from optrack.sim.recorder import write_recording
    from optrack.sim.world import Simulation

    path = tmp_path_factory.mktemp("venue") / "mixed"
    write_recording(Simulation("mixed", seed=0, seconds=VENUE_SECONDS), path)
    return path


class Processes:
    """Child processes started by a test, their output in log files; each is stopped
    (then killed, with anything left in its process group) at the end."""

    def __init__(self, logs: Path) -> None:
        self.logs = logs
        self.started: list[tuple[subprocess.Popen[bytes], Path]] = []

    def start(self, args: list[str], name: str, env: dict[str, str] | None = None):
        log = self.logs / f"{name}.log"
        with log.open("wb") as out:
            process = subprocess.Popen(
                [sys.executable, "-m", *args],
                stdout=out,
                stderr=subprocess.STDOUT,
                env={**os.environ, "PYTHONUNBUFFERED": "1", **(env or {})},
                start_new_session=True,
            )
        self.started.append((process, log))
        return process

    def output(self, process: subprocess.Popen[bytes]) -> str:
        for p, log in self.started:
            if p is process:
                return log.read_text(errors="replace")
        return ""

    def stop_all(self) -> None:
        for process, _ in self.started:
            if process.poll() is None:
                process.send_signal(signal.SIGTERM)
        for process, _ in self.started:
            try:
                process.wait(15)
            except subprocess.TimeoutExpired:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait()


@pytest.fixture
def processes(tmp_path) -> Iterator[Processes]:
    p = Processes(tmp_path)
    yield p
    p.stop_all()
