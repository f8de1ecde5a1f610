"""The Debian package: built from the wheel (packaging/build-deb.sh), installed with
apt on this machine (as root, as CI runs), run from /usr/bin (headless and its window
under Xvfb), and removed without a trace but the operator's configuration (purge takes
that too). The install, run and removal are optrack bench install's own steps."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import time
from pathlib import Path

import pytest

import optrack
from optrack.bench.install import (
    INSTALLED,
    apt,
    clean_env,
    deb_path,
    installed_figures,
    watch_tracks,
)
from tests.conftest import free_port
from tests.packaging.conftest import REPO

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
    "./opt/optrack/python/bin/python3.11",
    "./opt/optrack/python/lib/python3.11/os.py",
    "./usr/share/applications/optrack.desktop",
    "./usr/share/icons/hicolor/scalable/apps/optrack.svg",
    "./usr/lib/udev/rules.d/99-optrack-cameras.rules",
    "./usr/lib/systemd/system/optrack-node@.service",
    "./usr/lib/systemd/system/optrack-tracker.service",
    "./etc/optrack/site.yaml",
    "./etc/optrack/site.env",
    "./usr/share/doc/optrack/deploy.md",
]


def run(*args: str, env: dict[str, str] | None = None, **kwargs) -> str:
    done = subprocess.run(args, capture_output=True, text=True, env=env or clean_env(), **kwargs)
    assert done.returncode == 0, f"{' '.join(args)}: {done.stderr[-3000:]}"
    return done.stdout


def build_deb() -> Path:
    """packaging/build-deb.sh from the session's wheel (make package's second half)."""
    out = run("nice", "-n", "19", "bash", "packaging/build-deb.sh", cwd=REPO).splitlines()[-1]
    deb = REPO / out
    assert deb == deb_path(REPO), deb
    return deb


def check_contents(deb: Path) -> None:
    paths = {line.split()[5] for line in run("dpkg-deb", "-c", str(deb)).splitlines()}
    assert [p for p in SHIPPED if p not in paths] == []
    depends = [d.strip() for d in run("dpkg-deb", "-f", str(deb), "Depends").split(",")]
    assert "libusb-1.0-0" in depends and "libopenni2-0" in depends
    # Its own interpreter: no Python of the target's, but that interpreter's libraries
    # under both names Ubuntu 24.04 and Debian 12 give them.
    assert not [d for d in depends if d.startswith("python")], depends
    assert "libssl3 | libssl3t64" in depends and "libffi8" in depends
    assert "libc6 (>= 2.35)" in depends  # Ubuntu 22.04's C library
    assert "xvfb" not in depends and "-dev" not in depends and "python3-venv" not in depends


def check_units() -> None:
    """systemd-analyze verify: the template (as one instance) and the tracker's unit."""
    verify = subprocess.run(
        ["systemd-analyze", "verify", "--man=no"]
        + ["optrack-node@front.service", "optrack-tracker.service"],
        capture_output=True,
        text=True,
    )
    assert verify.returncode == 0, verify.stderr
    assert [line for line in verify.stderr.splitlines() if "optrack" in line] == []


def check_window(home: Path) -> dict[str, float | None]:
    """``optrack gui`` from /usr/bin under Xvfb (xcb) on its embedded site, which sends
    its tracks by UDP: a screenshot of the window 30 s after it opened, and the time
    from starting it to the first tracks (None: none in those 30 s, on a loaded computer)."""
    from PySide6.QtGui import QImage

    shot = home / "window.png"

    def command(udp: str) -> list[str]:
        config = home / "gui.yaml"
        config.write_text(f"bus:\n  local_port: {free_port()}\noutputs:\n  udp: {udp}\n")
        return [
            *("xvfb-run", "-a", "-s", "-screen 0 1280x1024x24", "/usr/bin/optrack", "gui"),
            *("--config", str(config), "--screenshot", str(shot), "--quit-after", "30"),
        ]

    env = clean_env(QT_QPA_PLATFORM="xcb", HOME=str(home), XDG_CACHE_HOME=str(home / "cache"))
    figures = watch_tracks(command, env, timeout_s=180, to_end=True, need_tracks=False)
    image = QImage(str(shot))
    assert not image.isNull() and image.width() >= 640 and image.height() >= 400
    colours = {image.pixel(x, y) for x in range(0, image.width(), 7) for y in range(0, 400, 7)}
    assert len(colours) > 20, "the window's screenshot is nearly one colour"
    first = figures["first_tracks_s"]
    return {"gui_first_tracks_s": None if first is None else round(first, 1)}


def test_the_debian_package_installs_runs_and_goes(wheel: Path, tmp_path: Path) -> None:
    started = time.perf_counter()
    deb = build_deb()
    build_s = time.perf_counter() - started
    check_contents(deb)
    try:
        install_s = apt("install", str(deb))
        try:
            version = run("/usr/bin/optrack", "--version").strip()
            assert version == f"optrack {optrack.__version__}"
            where = "import sys, ssl; print(sys.base_prefix)"
            assert run("/opt/optrack/bin/python", "-c", where).strip() == "/opt/optrack/python"
            if shutil.which("systemd-analyze"):
                check_units()
            figures = installed_figures(tmp_path, seconds=10)
            if shutil.which("xvfb-run"):
                figures.update(check_window(tmp_path))
        finally:
            remove_s = apt("remove", "optrack")
        assert not INSTALLED.exists() and not Path("/usr/bin/optrack").exists()
        assert Path("/etc/optrack/site.yaml").is_file()  # the operator's configuration stays
    finally:
        run("dpkg", "--purge", "optrack")
    assert not Path("/etc/optrack").exists()
    print(
        json.dumps(
            {
                "deb_mb": round(deb.stat().st_size / 1e6, 1),
                **figures,
                "build_s": round(build_s, 1),
                "install_s": round(install_s, 1),
                "remove_s": round(remove_s, 1),
            }
        )
    )
