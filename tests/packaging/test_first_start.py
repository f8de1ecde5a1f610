"""First start in seconds: `optrack run --headless` with an empty cache sends its first
UDP datagram with tracks within 10 s (the embedded venue renders live: nothing first)."""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import pytest

from optrack.bench.install import clean_env, watch_tracks
from tests.conftest import free_port

pytestmark = pytest.mark.slow


def test_first_tracks_within_10_s_with_an_empty_cache(tmp_path: Path) -> None:
    optrack = shutil.which("optrack", path=str(Path(sys.executable).parent))
    assert optrack is not None
    config = tmp_path / "site.yaml"
    config.write_text(f"bus:\n  local_port: {free_port()}\n")
    env = clean_env(XDG_CACHE_HOME=str(tmp_path / "cache"), HOME=str(tmp_path))
    command = [optrack, "run", "--headless", "--seconds", "30", "--config", str(config)]
    first = watch_tracks(command, env, timeout_s=30)["first_tracks_s"]
    print(json.dumps({"first_tracks_s": round(first, 1)}))
    assert first <= 10.0
    assert not (tmp_path / "cache" / "optrack").exists()  # nothing cached


def test_the_window_gets_tracks_within_10_s_with_an_empty_cache(tmp_path: Path) -> None:
    """`optrack gui` (the embedded site it starts) sends its first tracks within 10 s of
    the command starting: what the window draws arrives on the same bus at the same time."""
    optrack = shutil.which("optrack", path=str(Path(sys.executable).parent))
    assert optrack is not None

    def command(udp: str) -> list[str]:
        config = tmp_path / "gui.yaml"
        config.write_text(f"bus:\n  local_port: {free_port()}\noutputs:\n  udp: {udp}\n")
        return [optrack, "gui", "--config", str(config), "--quit-after", "30"]

    env = clean_env(
        XDG_CACHE_HOME=str(tmp_path / "cache"), HOME=str(tmp_path), QT_QPA_PLATFORM="offscreen"
    )
    first = watch_tracks(command, env, timeout_s=30)["first_tracks_s"]
    print(json.dumps({"window_first_tracks_s": round(first, 1)}))
    assert first <= 10.0
    assert not (tmp_path / "cache" / "optrack").exists()  # nothing cached
