"""Clock sync: NTP's on-wire estimates, the minimum-delay filter, and a real node whose
clock runs 250 ms ahead."""

from __future__ import annotations

import logging
import re
import time

import pytest

from optrack.net.bus import Bus
from optrack.net.clock import CLOCK_PARAMS, ClockServer, ClockSync, Sample, local_clock


def test_offset_and_delay_follow_rfc5905():
    # Node clock 100 ms behind the tracker; 10 ms each way; tracker replies 1 ms later.
    sample = Sample(t0=0.000, t1=0.110, t2=0.111, t3=0.021)
    assert sample.theta == pytest.approx(0.100)
    assert sample.delta == pytest.approx(0.020)


def test_asymmetric_path_error_is_within_half_the_delay():
    # True offset 0; 2 ms out, 18 ms back: theta is off by (18 - 2) / 2 = 8 ms <= delta / 2.
    sample = Sample(t0=0.0, t1=0.002, t2=0.002, t3=0.020)
    assert abs(sample.theta) == pytest.approx(0.008)
    assert abs(sample.theta) <= sample.delta / 2


class StubBus:
    """A bus whose clock replies come with chosen delays (the filter under test)."""

    def __init__(self, delays: list[float], offset: float) -> None:
        self.delays = list(delays)
        self.offset = offset
        self.keys = type("K", (), {"clock": "optrack/test/clock"})()
        self.now = 100.0

    def clock(self) -> float:
        return self.now

    def query(self, key, request, cls, timeout):
        from optrack.net.messages import ClockReply

        delay = self.delays.pop(0)
        # All the delay on the way out: theta is off by delay / 2.
        t1 = request.t0 + self.offset + delay
        self.now += delay
        return [ClockReply(t0=request.t0, t1=t1, t2=t1)]


def test_the_sample_of_minimum_delay_gives_the_offset():
    bus = StubBus([0.040, 0.002, 0.030, 0.010], offset=0.5)
    sync = ClockSync(bus, CLOCK_PARAMS.create({"burst": 4}), clock=bus.clock)  # type: ignore[arg-type]
    estimate = sync.measure()
    assert estimate is not None
    assert estimate.offset_s == pytest.approx(0.5 + 0.001)
    assert estimate.uncertainty_s == pytest.approx(0.001)
    assert estimate.samples == 4


def test_a_node_with_a_250ms_skew_estimates_its_offset_within_2ms(hub, bus_params):
    ClockServer(hub)
    node = Bus("test", "cam0", bus_params)
    try:
        params = CLOCK_PARAMS.create({"skew_s": 0.25})
        sync = ClockSync(node, params)
        time.sleep(0.2)
        estimate = sync.measure()
        assert estimate is not None
        assert estimate.offset_s == pytest.approx(-0.25, abs=0.002)
        assert estimate.uncertainty_s < 0.002
        # Stamps in tracker time land where the tracker's own clock is.
        assert sync.now() == pytest.approx(time.time(), abs=0.003)
    finally:
        node.close()


def test_offset_above_10ms_is_warned_once(hub, bus_params, caplog):
    ClockServer(hub)
    node = Bus("test", "cam0", bus_params)
    try:
        sync = ClockSync(node, CLOCK_PARAMS.create({"skew_s": -0.05, "burst": 2}))
        time.sleep(0.2)
        with caplog.at_level(logging.WARNING, logger="optrack.net.clock"):
            sync.measure()
            sync.measure()
        warnings = [r.getMessage() for r in caplog.records]
        assert len(warnings) == 1
        said = re.search(r"([\d.]+) ms behind the tracker's", warnings[0])
        assert said is not None, warnings[0]
        assert float(said.group(1)) == pytest.approx(50.0, abs=2.0)  # a busy computer: +-2 ms
        assert "NTP" in warnings[0]
    finally:
        node.close()


def test_without_a_tracker_the_node_stays_unsynchronised_and_does_not_wait_long(hub, make_client):
    node = make_client("cam0")
    sync = ClockSync(node, CLOCK_PARAMS.create({"timeout_s": 0.2, "burst": 8}))
    started = time.monotonic()
    assert sync.measure() is None
    assert time.monotonic() - started < 1.0
    assert sync.offset_s == 0.0
    assert sync.failures == 1


def test_background_sync_keeps_measuring(hub, bus_params):
    server = ClockServer(hub)
    node = Bus("test", "cam0", bus_params)
    try:
        sync = ClockSync(node, CLOCK_PARAMS.create({"period_s": 0.1, "burst": 2}))
        sync.start()
        deadline = time.monotonic() + 3.0
        while server.requests < 6 and time.monotonic() < deadline:
            time.sleep(0.02)
        sync.stop()
        assert server.requests >= 6
        assert sync.estimate is not None
    finally:
        node.close()


def test_local_clock_adds_the_configured_skew():
    clock = local_clock(CLOCK_PARAMS.create({"skew_s": 0.25}))
    assert clock() - time.time() == pytest.approx(0.25, abs=0.01)
    assert local_clock(CLOCK_PARAMS.create()) is time.time
