"""A live simulated sensor with loop=true starts its venue again at the end, forwards, on
the clock's next loop (the embedded venue of optrack run)."""

from __future__ import annotations

import numpy as np
import pytest

from optrack.sensors.base import SensorError
from optrack.sim.sensor import SimulatedSensor


class FakeClock:
    """Wall clock the test moves: sleep() advances it."""

    def __init__(self, now: float) -> None:
        self.now = now

    def time(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        self.now += seconds


def test_a_looping_sensor_starts_again_forwards_on_the_next_loop() -> None:
    clock = FakeClock(1000.0)
    uri = "sim://mixed/0?seed=3&seconds=0.2&start=1000&loop=true&noise=false"
    sensor = SimulatedSensor.from_uri(uri)
    sensor._clock = clock  # a URI has no clock: the test's own
    plain = SimulatedSensor.from_uri(uri.replace("&loop=true", ""))
    plain._clock = clock
    stamps, depths = [], []
    for _ in range(14):  # 30 fps: 6 frames a loop of 0.2 s
        frame = sensor.read()
        assert frame is not None
        stamps.append(frame.timestamp)
        depths.append(frame.depth)
    assert all(b > a for a, b in zip(stamps, stamps[1:], strict=False))  # forwards only
    per_loop = sensor.simulation.frame_count(0)
    assert 0 < per_loop < 14
    # The second loop is the first again, one loop later on the clock.
    assert stamps[per_loop] == pytest.approx(stamps[0] + 0.2)
    assert np.array_equal(depths[per_loop], depths[0])
    clock.now = 1000.0
    assert sum(1 for _ in iter(plain.read, None)) == per_loop  # without loop it ends


def test_loop_needs_real_time() -> None:
    with pytest.raises(SensorError, match="real time"):
        SimulatedSensor.from_uri("sim://mixed/0?realtime=false&loop=true")
