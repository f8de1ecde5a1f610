"""Without a display the GUI prints one sentence pointing at the headless mode."""

import os
import subprocess
import sys

from optrack.runtime.display import display_problem


def test_display_problems_are_found_before_qt_starts():
    assert display_problem({}) == "DISPLAY is not set"
    assert "no X server" in display_problem({"DISPLAY": ":4242"})
    assert display_problem({"QT_QPA_PLATFORM": "offscreen"}) is None
    assert display_problem({"WAYLAND_DISPLAY": "wayland-0"}) is None
    assert display_problem({"DISPLAY": "remotehost:0"}) is None  # cannot be checked; let Qt try


def test_gui_without_display_prints_the_headless_hint():
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM")
    }
    result = subprocess.run(
        [sys.executable, "-m", "optrack.cli", "gui"],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
    )
    assert result.returncode == 1
    assert result.stdout == ""
    assert result.stderr.count("\n") == 1
    assert "optrack run --headless" in result.stderr and "DISPLAY is not set" in result.stderr
