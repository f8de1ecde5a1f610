"""The live venue closes its loop: at the end of each loop everyone is back where they
started, at rest, facing the same way, so the next loop takes up without a jump."""

from __future__ import annotations

import pytest

from optrack.sim.sensor import SimulatedSensor
from optrack.sim.venue_loop import ClosingLoop, close_loop, loop_seam
from optrack.sim.world import Simulation


@pytest.mark.parametrize("seed", [0, 3])
def test_a_closed_loop_ends_as_it_began(seed: int) -> None:
    open_seam = loop_seam(Simulation("mixed", seed=seed, seconds=40.0))
    assert open_seam["position_m"] > 0.5  # people walk: a loop left open jumps

    seam = loop_seam(close_loop(Simulation("mixed", seed=seed, seconds=40.0)))
    assert seam["position_m"] < 1e-6
    assert seam["heading_deg"] < 0.5
    assert seam["amplitude"] < 0.01  # the walk has faded out, as at the start
    assert seam["speed_m_s"] == 0.0
    assert seam["missing"] == 0  # whoever came in later has left


def test_a_looping_live_sensor_plays_a_closed_loop() -> None:
    sensor = SimulatedSensor.from_uri("sim://mixed/1?seed=2&seconds=60&start=1000&loop=true")
    assert all(isinstance(p.behaviour, ClosingLoop) for p in sensor.simulation.crowd.people)
    plain = SimulatedSensor.from_uri("sim://mixed/1?seed=2&seconds=60&start=1000")
    assert not any(isinstance(p.behaviour, ClosingLoop) for p in plain.simulation.crowd.people)
