"""The embedded venue starts at once: each detector node renders its sensor live, all
on one clock, forwards, looping; nothing is rendered first and nothing is cached."""

from __future__ import annotations

import time
import urllib.parse

from optrack.runtime.config import load_node_config
from optrack.runtime.site import Site
from optrack.runtime.venue import LIVE_LOOP_S, venue_uris
from optrack.sim.sensor import SimulatedSensor
from optrack.sim.venue_loop import LOOP_CLOSE


def test_the_site_without_sensors_plays_the_live_venue_at_once(tmp_path, monkeypatch, capfd):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    site = Site(load_node_config(None, {"site": {"name": "live"}}))
    started = time.perf_counter()
    uris = site.sensor_uris()
    assert time.perf_counter() - started < 5.0  # no rendering before the start
    assert not (tmp_path / "cache").exists()  # nothing cached
    assert "rendering" not in capfd.readouterr().err
    assert site.status().state == "running"
    assert [urllib.parse.urlsplit(u).netloc for u in uris] == ["mixed"] * 3
    queries = [dict(urllib.parse.parse_qsl(urllib.parse.urlsplit(u).query)) for u in uris]
    assert [q["id"] for q in queries] == ["kinect2_0", "kinect2_1", "kinect2_2"]
    assert len({q["start"] for q in queries}) == 1  # one clock for every sensor
    assert all(q["loop"] == "true" and float(q["seconds"]) == LIVE_LOOP_S for q in queries)
    assert LIVE_LOOP_S % LOOP_CLOSE["sway_period_s"] == 0  # a standing person's sway goes on


def test_the_venue_uris_open_as_live_sensors_of_one_venue() -> None:
    start = time.time()
    uris = venue_uris("mixed", 4, start=start)
    sensors = [SimulatedSensor.from_uri(u) for u in uris]
    assert [s.info.id for s in sensors] == ["kinect2_0", "kinect2_1", "kinect2_2"]
    assert all(s.loop and s.real_time and s.start_time == start for s in sensors)
    assert len({s.simulation.seed for s in sensors}) == 1


def test_the_venue_ids_are_the_simulated_sensors_ids(tmp_path) -> None:
    from optrack.sim.world import Simulation

    scenario = tmp_path / "two_models.yaml"
    scenario.write_text(
        "venue: {size: [6.0, 5.0]}\nsensors: {count: 3, models: [kinect1, sr4500]}\n"
    )
    uris = venue_uris(str(scenario), 0)
    ids = [dict(urllib.parse.parse_qsl(urllib.parse.urlsplit(u).query))["id"] for u in uris]
    assert ids == [s.id for s in Simulation(str(scenario), seed=0).sensors]
    assert ids == ["kinect1_0", "sr4500_1", "kinect1_2"]
