"""Make the Recording dock's screenshots of docs/gui.md (run under Xvfb):

    QT_QPA_PLATFORM=xcb xvfb-run -a -s "-screen 0 1600x1000x24" \\
        .venv/bin/python docs/screenshots/make_recording_screenshots.py

The window opens the embedded venue's recording (File → Open recording…:
the embedded site restarted with the recording's sensors), so the real
detectors and tracker run on it; then the dock records every sensor into a
temporary folder while it plays. Pictures: the dock recording and playing
(recording-playing.png), and paused after one step, the recording stopped
(recording-paused.png).
"""

from __future__ import annotations

import shutil
import socket
import sys
import tempfile
import time
from pathlib import Path

import yaml

HERE = Path(__file__).resolve().parent
REPO = HERE.parent.parent
sys.path.insert(0, str(REPO))

VENUE = {"scenario": "mixed", "seed": 0, "venue_seconds": 4.0}  # as tests/app


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def main() -> int:
    from PySide6.QtWidgets import QApplication

    from app.main import configure_qt

    configure_qt()
    app = QApplication.instance() or QApplication([sys.argv[0]])
    from app.main_window import MainWindow
    from optrack.runtime.venue import venue_recording

    scratch = Path(tempfile.mkdtemp(prefix="optrack-shots-"))
    config = scratch / "site.yaml"
    config.write_text(
        yaml.safe_dump(
            {
                "bus": {"local_port": free_port()},
                "site": {**VENUE, "name": "shots", "report_s": 0.0},
                "outputs": {"udp": ""},
            }
        )
    )
    venue = venue_recording(VENUE["scenario"], VENUE["seed"], VENUE["venue_seconds"])

    def wait(predicate, seconds: float, what: str) -> None:
        deadline = time.monotonic() + seconds
        while not predicate():
            if time.monotonic() > deadline:
                raise SystemExit(
                    f"make_recording_screenshots: no {what} after {seconds:g} s "
                    f"(dock: {panel.record_state.text()} {panel.message.text()})"
                )
            app.processEvents()
            time.sleep(0.02)

    def pause(seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            app.processEvents()
            time.sleep(0.02)

    window = MainWindow()
    window.resize(1560, 940)
    window.recording_opener.config = str(config)
    window.show()
    panel = window.recording
    try:
        window.open_recording(str(venue))
        window.docks["Recording"].raise_()
        wait(lambda: window.tracks_table.model.rowCount() > 0, 120, "tracks")
        wait(lambda: len(panel.players) == 3, 30, "playing sensors")
        panel.folder.setText(str(scratch / "take-1"))
        panel.record_button.click()
        wait(lambda: panel.recording, 30, "recording")
        pause(4.0)
        wait(lambda: all(v.get("recording.frames") for v in panel._status.values()), 30, "frames")
        window.docks["Recording"].grab().save(str(HERE / "recording-playing.png"))
        panel.record_button.click()
        wait(lambda: panel.record_state.text().startswith("Recorded"), 30, "stop")
        panel.pause_button.click()
        wait(lambda: panel.step_button.isEnabled(), 30, "pause")
        panel.step_button.click()
        pause(2.5)
        window.docks["Recording"].grab().save(str(HERE / "recording-paused.png"))
    finally:
        window.close()
        shutil.rmtree(scratch, ignore_errors=True)
    print("wrote recording-playing.png and recording-paused.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
