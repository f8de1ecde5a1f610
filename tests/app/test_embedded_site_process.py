"""The embedded site's process: its output reaches the window line by line (no display)."""

import sys

from app.embedded_site import EmbeddedSite

SITE = r"""
import sys, time
for n in (10, 50, 100):
    sys.stderr.write(f"\rvenue mixed [{n:3d}%]")
    sys.stderr.flush()
    time.sleep(0.05)
sys.stderr.write("\noptrack run: site 'local' on tcp/127.0.0.1:7447\n")
sys.stderr.write("optrack run: cannot host the local site; stop the other one.\n")
sys.exit(3)
"""


def test_site_output_becomes_progress_lines_and_an_exit_sentence(qtbot):
    site = EmbeddedSite(command=[sys.executable, "-c", SITE])
    lines, progress = [], []
    site.line.connect(lines.append)
    site.progress.connect(progress.append)
    with qtbot.waitSignal(site.ended, timeout=20000) as ended:
        site.start()
    assert ended.args == [3, "optrack run: cannot host the local site; stop the other one."]
    assert lines == [
        "venue mixed [100%]",
        "optrack run: site 'local' on tcp/127.0.0.1:7447",
        "optrack run: cannot host the local site; stop the other one.",
    ]
    assert progress and progress[-1].startswith("venue mixed [")
    assert not site.running


def test_stopping_a_site_ends_its_process(qtbot):
    site = EmbeddedSite(command=[sys.executable, "-c", "import time; time.sleep(60)"])
    site.start()
    qtbot.waitUntil(lambda: site.running, timeout=10000)
    site.stop(timeout_s=5.0)
    assert not site.running


def test_the_site_is_optrack_run_headless_with_the_configuration():
    site = EmbeddedSite("/tmp/site.yaml")
    assert site.command == [
        sys.executable,
        "-m",
        "optrack.cli",
        "run",
        "--headless",
        "--config",
        "/tmp/site.yaml",
    ]
