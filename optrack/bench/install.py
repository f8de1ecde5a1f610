"""``optrack bench install``: the Debian package on this computer, measured.

Builds ``dist/optrack_<version>_<arch>.deb`` with ``make package`` (or reuses the one
there), installs it with ``apt-get`` (root), starts ``optrack run --headless`` from
``/usr/bin`` with an empty cache (to its end, then again to its first UDP datagram with
tracks, timed), then purges the package again. Figures: ``deb_mb``, ``installed_mb``
(``/opt/optrack``), ``first_tracks_s``, and the source checkout's ``.venv`` beside them.

The package's own test (tests/packaging/test_deb.py) uses the same steps. A benchmark
sits below the runtime: the site is a subprocess, watched through its UDP output.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import optrack
from optrack.bench.common import info
from optrack.bench.site_process import free_port
from optrack.errors import UserError

__all__ = [
    "INSTALLED",
    "apt",
    "clean_env",
    "deb_path",
    "dir_mb",
    "install_bench",
    "installed_figures",
    "watch_tracks",
]

#: Where the package puts the application (its own Python environment).
INSTALLED = Path("/opt/optrack")
_PATH = "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"


def clean_env(**extra: str) -> dict[str, str]:
    """The environment for an installed copy: nothing that points at a checkout or venv."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env.update(PATH=_PATH, DEBIAN_FRONTEND="noninteractive", **extra)
    return env


def _run(args: Sequence[str], timeout_s: float = 900.0, **kwargs: Any) -> str:
    """Runs ``args``; its stdout. A failure raises with the end of its stderr."""
    kwargs.setdefault("env", clean_env())
    done = subprocess.run(
        list(args), capture_output=True, text=True, timeout=timeout_s, check=False, **kwargs
    )
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(args)} exited {done.returncode}: {done.stderr[-3000:]}")
    return done.stdout


def apt(*args: str) -> float:
    """``apt-get -y -q ARGS`` as root; the seconds it took."""
    started = time.perf_counter()
    _run(["apt-get", "-y", "-q", *args])
    return time.perf_counter() - started


def dir_mb(path: Path) -> int:
    """The disk space under ``path`` in MB (``du -sm``)."""
    return int(_run(["du", "-sm", str(path)]).split()[0])


def deb_path(repo: Path) -> Path:
    """``dist/optrack_<version>_<arch>.deb`` of the checkout ``repo``."""
    arch = _run(["dpkg", "--print-architecture"]).strip()
    return repo / "dist" / f"optrack_{optrack.__version__}_{arch}.deb"


def _stop(proc: subprocess.Popen[bytes]) -> None:
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(30)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


def _has_tracks(data: bytes) -> bool:
    try:
        return bool(json.loads(data).get("tracks"))
    except (ValueError, AttributeError):
        return False


def watch_tracks(
    command: Sequence[str] | Callable[[str], list[str]],
    env: Mapping[str, str],
    timeout_s: float = 60.0,
    to_end: bool = False,
    need_tracks: bool = True,
) -> dict[str, float | None]:
    """Starts ``command`` and times its first UDP datagram with a track: an ``optrack run``
    without ``--udp`` (this adds one), or a function of the ``HOST:PORT`` to send to that
    gives the command. The run is stopped there, or with ``to_end`` waited for (it must
    exit 0 within ``timeout_s``; without ``need_tracks``, with or without tracks).
    Figures: ``first_tracks_s`` (None: no tracks) and, with ``to_end``, ``run_s``
    (start to exit)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock, tempfile.TemporaryFile() as err:
        sock.bind(("127.0.0.1", 0))
        sock.settimeout(0.2)
        address = f"127.0.0.1:{sock.getsockname()[1]}"
        argv = command(address) if callable(command) else [*command, "--udp", address]
        started = time.perf_counter()
        proc = subprocess.Popen(
            argv, env=dict(env), stdout=subprocess.DEVNULL, stderr=err, start_new_session=True
        )
        first = None
        try:
            while time.perf_counter() - started < timeout_s:
                if proc.poll() is not None and (first is None or to_end):
                    break
                try:
                    data = sock.recv(65536)
                except TimeoutError:
                    continue
                if first is None and _has_tracks(data):
                    first = time.perf_counter() - started
                    if not to_end:
                        return {"first_tracks_s": first}
            code = proc.poll()
            ended = time.perf_counter() - started
        finally:
            _stop(proc)
        err.seek(0)
        if (first is None and need_tracks) or (to_end and code != 0):
            tail = err.read().decode(errors="replace")[-2000:]
            raise RuntimeError(
                f"{' '.join(argv)}: first tracks {first}, exit {code} in {timeout_s:g} s: {tail}"
            )
        return {"first_tracks_s": first, "run_s": ended}


def installed_figures(home: Path, seconds: float = 10.0) -> dict[str, float]:
    """The installed copy, with an empty cache and ``home`` as its user's folder:
    ``optrack run --headless --seconds S`` run to its end (``run_s``), then a run of
    its own stopped at its first tracks (``first_tracks_s``: on a loaded computer they
    may come after S seconds); the size of ``/opt/optrack``."""
    config = home / "site.yaml"  # a port of its own: other sites may run on this computer
    config.write_text(f"bus:\n  local_port: {free_port()}\n")
    env = clean_env(XDG_CACHE_HOME=str(home / "cache"), HOME=str(home))
    command = ["/usr/bin/optrack", "run", "--headless", "--config", str(config)]
    started = time.perf_counter()
    _run([*command, "--seconds", f"{seconds:g}"], timeout_s=120 + 4 * seconds, env=env)
    run_s = time.perf_counter() - started
    first = watch_tracks([*command, "--seconds", "120"], env, timeout_s=120)["first_tracks_s"]
    return {
        "installed_mb": dir_mb(INSTALLED),
        "first_tracks_s": round(first, 1),
        "run_s": round(run_s, 1),
    }


def _checkout() -> Path:
    repo = Path(optrack.__file__).resolve().parents[1]
    if not (repo / "packaging" / "build-deb.sh").is_file():
        raise UserError(
            "optrack bench install builds the Debian package from a source checkout; "
            "run it from one (make bench BENCH=install)."
        )
    return repo


def _preconditions() -> None:
    if os.geteuid() != 0 or shutil.which("apt-get") is None:
        raise UserError(
            "optrack bench install installs and removes the Debian package: run it as root "
            "on Debian or Ubuntu."
        )
    status = subprocess.run(
        ["dpkg-query", "-W", "-f=${Status}", "optrack"], capture_output=True, text=True
    ).stdout
    if status.endswith(" installed"):
        raise UserError(
            "The optrack package is installed on this computer and this bench would remove "
            "it: remove it first (sudo apt remove optrack)."
        )


def install_bench() -> dict[str, Any]:
    """Build (or reuse) the package, install it, measure the installed copy, purge it."""
    repo = _checkout()
    _preconditions()
    deb = deb_path(repo)
    if not deb.is_file():
        info("optrack bench install: building the package (make package)...")
        _run(["nice", "-n", "19", "make", "-s", "package"], timeout_s=1800, cwd=repo)
    info(f"optrack bench install: installing {deb.name}...")
    install_s = apt("install", str(deb))
    try:
        with tempfile.TemporaryDirectory(prefix="optrack-bench-install-") as home:
            figures = installed_figures(Path(home))
    finally:
        remove_s = apt("purge", "optrack")
    venv = repo / ".venv"
    venv_mb = dir_mb(venv) if venv.is_dir() else None
    return {
        "deb": deb.name,
        "deb_mb": round(deb.stat().st_size / 1e6, 1),
        **figures,
        "venv_mb": venv_mb,
        "installed_vs_venv": round(figures["installed_mb"] / venv_mb, 2) if venv_mb else None,
        "install_s": round(install_s, 1),
        "remove_s": round(remove_s, 1),
        "left_behind": INSTALLED.exists(),
    }
