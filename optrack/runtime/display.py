"""Is there a screen to open a window on? Checked before Qt starts, so that a
machine without a display gets one sentence instead of Qt's abort."""

from __future__ import annotations

import os
import sys
from collections.abc import Mapping
from pathlib import Path

HEADLESS_HINT = (
    "optrack: no display to open the window on ({reason}); on a machine without a screen, "
    "run the tracker with 'optrack run --headless' instead."
)


def display_problem(environ: Mapping[str, str] | None = None) -> str | None:
    """Why a window cannot be opened, or None when it can (as far as can be told)."""
    env = os.environ if environ is None else environ
    if not sys.platform.startswith("linux"):
        return None
    platform = env.get("QT_QPA_PLATFORM", "")
    if platform and not platform.startswith(("xcb", "wayland")):
        return None  # offscreen, vnc, eglfs...: Qt needs no X server
    if env.get("WAYLAND_DISPLAY") and not platform.startswith("xcb"):
        return None
    display = env.get("DISPLAY", "")
    if not display:
        return "DISPLAY is not set"
    host, _, number = display.partition(":")
    if host in ("", "unix"):
        socket = Path("/tmp/.X11-unix") / f"X{number.split('.')[0]}"
        if not socket.exists():
            return f"no X server is running on display {display}"
    return None
