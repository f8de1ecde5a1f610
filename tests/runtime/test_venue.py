"""The embedded venue's first rendering: progress on stderr and in the site status, then
the cache reused; the sensors play it back and forth."""

from __future__ import annotations

import threading
import time

from optrack.net.bus import Bus
from optrack.net.config import BUS_PARAMS
from optrack.net.messages import StatusMessage
from optrack.runtime.config import load_node_config
from optrack.runtime.process import setup_logging
from optrack.runtime.site import Site

from .conftest import free_port


def test_the_first_run_shows_the_venue_rendering_on_stderr_and_in_the_site_status(
    tmp_path, monkeypatch, capfd
):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    setup_logging("optrack run")  # as the command does: one line per message on stderr
    port = free_port()
    config = load_node_config(
        None, {"bus": {"local_port": port}, "site": {"name": "render", "venue_seconds": 1.0}}
    )
    site = Site(config)
    site.host()
    observer = Bus("render", "gui", BUS_PARAMS.create({"local_port": port}))
    seen: list[StatusMessage] = []
    lock = threading.Lock()

    def on_status(message: StatusMessage, key: str) -> None:
        with lock:
            seen.append(message)

    try:
        observer.subscribe(observer.keys.status("site"), StatusMessage, on_status)
        uris = site.sensor_uris()
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline:  # the bus delivers asynchronously
            site.publish_status()
            time.sleep(0.2)
            with lock:
                if seen and seen[-1].state != "rendering":
                    break
        observer.close()
    finally:
        site.stop()
    rendering = [m for m in seen if m.state == "rendering"]
    assert rendering, [m.state for m in seen]
    done = [int(m.values["venue.frames_done"]) for m in rendering]
    total = int(rendering[-1].values["venue.frames_total"])
    assert done == sorted(done) and done[-1] == total == 90  # 3 sensors x 30 Hz x 1 s
    assert float(rendering[-1].values["venue.frames_per_s"]) > 0
    assert seen[-1].state != "rendering" and "venue.frames_done" not in seen[-1].values
    err = capfd.readouterr().err
    assert "rendering the venue 'mixed' once" in err and "90/90 frames" in err
    assert len(uris) == 3 and all("loop=bounce" in u for u in uris)
    # The second run reuses the cache: nothing rendered.
    again = Site(load_node_config(None, {"site": {"venue_seconds": 1.0}}))
    assert again.sensor_uris() == uris
    assert "rendering the venue" not in capfd.readouterr().err
