"""The wheel installs into a fresh venv (pinned dependencies from the configured index)
and gives a working ``optrack`` there, with its resources inside the package."""

from __future__ import annotations

import json
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest

import optrack
from optrack.bench.install import clean_env

pytestmark = pytest.mark.slow


def test_the_wheel_holds_the_resources(wheel: Path) -> None:
    names = set(zipfile.ZipFile(wheel).namelist())
    assert "optrack/resources/scenarios/mixed.yaml" in names
    assert "optrack/resources/optrack.desktop" in names
    assert "optrack/resources/config/site.yaml" in names
    assert not any(n.startswith(("tests/", "resources/")) for n in names)


def test_the_wheel_runs_sim_and_detect_from_a_fresh_venv(wheel: Path, tmp_path: Path) -> None:
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    # --no-compile: Python compiles what the commands import as they import it (the
    # whole environment's 12,000 modules would take a minute and a half on 2 cores).
    started = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(venv / "bin" / "python")]
        + ["install", "-q", "--no-compile", "--disable-pip-version-check", str(wheel)],
        check=True,
        capture_output=True,
    )
    install_s = time.perf_counter() - started
    env = clean_env()

    def optrack_cmd(*args: str) -> str:
        done = subprocess.run(
            [str(venv / "bin" / "optrack"), *args],
            cwd=tmp_path,  # the checkout is not on sys.path
            env=env,
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert done.returncode == 0, done.stderr[-2000:]
        return done.stdout

    assert optrack_cmd("--version").strip() == f"optrack {optrack.__version__}"
    where = subprocess.run(
        [str(venv / "bin" / "python"), "-c", "import optrack; print(optrack.__file__)"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert where.startswith(str(venv)), where
    recording = tmp_path / "rec"
    sim = json.loads(
        optrack_cmd("sim", "mixed", "--seconds", "0.5", "--out", str(recording), "--json")
    )
    assert sim["sensors"] == 3 and sim["frames"] > 0
    detect = json.loads(optrack_cmd("detect", str(recording), "--frames", "3", "--json"))
    assert detect["detections"], "no person detected in the installed copy"
    print(json.dumps({"wheel_install_s": round(install_s, 1)}))
