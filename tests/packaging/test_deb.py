"""The Debian package: built from the wheel (packaging/build-deb.sh), installed with
apt on this machine (as root, as CI runs), run from /usr/bin, and removed without a trace
but the operator's configuration (purge takes that too)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import time
from pathlib import Path

import pytest

import optrack
from tests.conftest import free_port
from tests.packaging.conftest import REPO, clean_env, first_tracks_s

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(
        os.geteuid() != 0 or shutil.which("dpkg-deb") is None or shutil.which("apt-get") is None,
        reason="installs a Debian package: needs root, dpkg-deb and apt-get",
    ),
]

SHIPPED = [
    "./usr/bin/optrack",
    "./opt/optrack/bin/optrack",
    "./usr/share/applications/optrack.desktop",
    "./usr/share/icons/hicolor/scalable/apps/optrack.svg",
    "./usr/lib/udev/rules.d/99-optrack-cameras.rules",
    "./usr/lib/systemd/system/optrack-node@.service",
    "./usr/lib/systemd/system/optrack-tracker.service",
    "./etc/optrack/site.yaml",
    "./etc/optrack/site.env",
    "./usr/share/doc/optrack/deploy.md",
]


def run(
    *args: str, env: dict[str, str] | None = None, **kwargs
) -> subprocess.CompletedProcess[str]:
    env = env or {**clean_env(), "DEBIAN_FRONTEND": "noninteractive"}
    done = subprocess.run(args, capture_output=True, text=True, env=env, **kwargs)
    assert done.returncode == 0, f"{' '.join(args)}: {done.stderr[-3000:]}"
    return done


def build_deb() -> Path:
    out = run("bash", "packaging/build-deb.sh", cwd=REPO).stdout.strip().splitlines()[-1]
    deb = REPO / out
    assert deb.name == f"optrack_{optrack.__version__}_amd64.deb", deb
    return deb


def check_contents(deb: Path) -> None:
    listing = run("dpkg-deb", "-c", str(deb)).stdout
    paths = {line.split()[5] for line in listing.splitlines()}
    missing = [p for p in SHIPPED if p not in paths]
    assert missing == []
    depends = run("dpkg-deb", "-f", str(deb), "Depends").stdout
    assert "python3.11" in depends and "libusb-1.0-0" in depends and "libopenni2-0" in depends
    assert "xvfb" not in depends and "-dev" not in depends and "python3-venv" not in depends


def check_units() -> None:
    """systemd-analyze verify: the template (as one instance) and the tracker's unit."""
    if shutil.which("systemd-analyze") is None:
        return
    verify = subprocess.run(
        ["systemd-analyze", "verify", "--man=no"]
        + ["optrack-node@front.service", "optrack-tracker.service"],
        capture_output=True,
        text=True,
    )
    assert verify.returncode == 0, verify.stderr
    assert [line for line in verify.stderr.splitlines() if "optrack" in line] == []


def check_installed(tmp_path: Path) -> dict[str, float]:
    assert run("/usr/bin/optrack", "--version").stdout.strip() == f"optrack {optrack.__version__}"
    check_units()
    env = {**clean_env(), "XDG_CACHE_HOME": str(tmp_path / "cache"), "HOME": str(tmp_path)}
    config = tmp_path / "site.yaml"  # a port of its own: other sites may run on this computer
    config.write_text(f"bus:\n  local_port: {free_port()}\n")
    # The embedded venue: nothing to render first, nothing cached.
    started = time.perf_counter()
    command = ["/usr/bin/optrack", "run", "--headless", "--seconds", "10", "--config", str(config)]
    run(*command, env=env, timeout=300)
    run_s = time.perf_counter() - started
    assert not (tmp_path / "cache" / "optrack" / "venues").exists()
    # Time to the first UDP datagram with tracks (the run is stopped there).
    first = first_tracks_s(command, env, timeout=60)
    installed_mb = int(run("du", "-sm", "/opt/optrack").stdout.split()[0])
    return {
        "installed_mb": installed_mb,
        "run_10s_s": round(run_s, 1),
        "first_tracks_s": round(first, 1),
    }


def test_the_debian_package_installs_runs_and_goes(wheel: Path, tmp_path: Path) -> None:
    started = time.perf_counter()
    deb = build_deb()
    build_s = time.perf_counter() - started
    check_contents(deb)
    started = time.perf_counter()
    run("apt-get", "install", "-y", "-q", str(deb))
    install_s = time.perf_counter() - started
    try:
        figures = check_installed(tmp_path)
    finally:
        run("apt-get", "remove", "-y", "-q", "optrack")
    assert not Path("/opt/optrack").exists() and not Path("/usr/bin/optrack").exists()
    assert Path("/etc/optrack/site.yaml").is_file()  # the operator's configuration stays
    run("dpkg", "--purge", "optrack")
    assert not Path("/etc/optrack").exists()
    print(
        json.dumps(
            {
                "deb_mb": round(deb.stat().st_size / 1e6, 1),
                **figures,
                "build_s": round(build_s, 1),
                "install_s": round(install_s, 1),
            }
        )
    )
