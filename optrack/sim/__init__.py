"""The simulated venue: walking people, RGB-D sensor models, checkerboards, ground truth.

A scenario (YAML, see :mod:`optrack.sim.scenario`) describes a venue, its
sensors and its people; :class:`~optrack.sim.world.Simulation` brings it to
life deterministically for a seed and renders each sensor's frames by ray
casting (:mod:`optrack.sim.render`) through a sensor model with real noise
(:mod:`optrack.sim.models`). ``optrack sim`` writes it to a recording;
:class:`optrack.sim.sensor.SimulatedSensor` streams one sensor live.
"""

from optrack.lazy import lazy_exports

# Imported on first use, so that a light module of this package (its cli.py, for
# `optrack --help`) loads nothing heavy.
_HOMES = {
    "MODELS": "optrack.sim.models",
    "SensorModel": "optrack.sim.models",
    "make_model": "optrack.sim.models",
    "Scenario": "optrack.sim.scenario",
    "ScenarioError": "optrack.sim.scenario",
    "builtin_scenarios": "optrack.sim.scenario",
    "load_scenario": "optrack.sim.scenario",
    "SimSensor": "optrack.sim.world",
    "Simulation": "optrack.sim.world",
    "WorldState": "optrack.sim.world",
}


__getattr__ = lazy_exports(__name__, _HOMES)

__all__ = [
    "MODELS",
    "Scenario",
    "ScenarioError",
    "SensorModel",
    "SimSensor",
    "Simulation",
    "WorldState",
    "builtin_scenarios",
    "load_scenario",
    "make_model",
]
