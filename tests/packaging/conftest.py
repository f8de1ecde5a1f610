"""Shared by the packaging tests: the wheel, built once per session into dist/."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

import optrack

REPO = Path(__file__).resolve().parents[2]


def clean_env() -> dict[str, str]:
    """The environment for an installed copy: nothing that points at the checkout."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["PATH"] = "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"
    return env


@pytest.fixture(scope="session")
def wheel() -> Path:
    """dist/optrack-<version>-py3-none-any.whl, built from this checkout (as make wheel does)."""
    dist = REPO / "dist"
    path = dist / f"optrack-{optrack.__version__}-py3-none-any.whl"
    path.unlink(missing_ok=True)
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(dist), str(REPO)],
        check=True,
        cwd=REPO,
    )
    assert path.is_file()
    return path


def first_tracks_s(command: list[str], env: dict[str, str], timeout: float = 60.0) -> float:
    """Seconds from starting ``command`` (an ``optrack run`` without ``--udp``: this adds
    one) to its first UDP datagram with a track in it; the command is then stopped."""
    import json
    import signal
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        sock.settimeout(0.5)
        port = sock.getsockname()[1]
        started = time.perf_counter()
        proc = subprocess.Popen(
            [*command, "--udp", f"127.0.0.1:{port}"],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,
        )
        try:
            while time.perf_counter() - started < timeout and proc.poll() is None:
                try:
                    data = sock.recv(65536)
                except TimeoutError:
                    continue
                if json.loads(data).get("tracks"):
                    return time.perf_counter() - started
            raise AssertionError(
                f"no track in {timeout:g} s (exit {proc.poll()}): {proc.stderr.read()[-2000:] if proc.poll() is not None else ''}"
            )
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGTERM)
                try:
                    proc.wait(30)
                except subprocess.TimeoutExpired:
                    os.killpg(proc.pid, signal.SIGKILL)
                    proc.wait()
