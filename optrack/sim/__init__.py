"""The simulated venue: walking people, RGB-D sensor models, checkerboards, ground truth.

A scenario (YAML, see :mod:`optrack.sim.scenario`) describes a venue, its
sensors and its people; :class:`~optrack.sim.world.Simulation` brings it to
life deterministically for a seed and renders each sensor's frames by ray
casting (:mod:`optrack.sim.render`) through a sensor model with real noise
(:mod:`optrack.sim.models`). ``optrack sim`` writes it to a recording;
:class:`optrack.sim.sensor.SimulatedSensor` streams one sensor live.
"""

from optrack.sim.models import MODELS, SensorModel, make_model
from optrack.sim.scenario import Scenario, ScenarioError, builtin_scenarios, load_scenario
from optrack.sim.world import SimSensor, Simulation, WorldState

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
