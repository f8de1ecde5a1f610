"""A single-sensor scene for people at the image's edge (the detector's edge bench).

:func:`edge_scenario` draws, from a seed, one sensor on a wall of an empty
room (its height, tilt, yaw and place along the wall drawn) and people who
walk back and forth across the left or right border of its image, each at
its own distance, so that they are seen from fully to not at all, passing
through every visible fraction in between. Nothing in the room hides them:
what is missing of a person is outside the image (or behind another person).
"""

from __future__ import annotations

import math

import numpy as np

from optrack.sim.models import MODELS
from optrack.sim.scenario import PeopleSpec, Scenario, SensorPose, SensorsSpec, VenueSpec

__all__ = ["EDGE_ROOM", "edge_scenario"]

#: The room (length along the sensor's view, width), metres.
EDGE_ROOM = (10.0, 9.0)
#: Margin kept between routes and the walls, metres.
WALL_MARGIN = 0.5
#: How far inside and beyond the image's border (at the person's distance) a route runs.
INSIDE, BEYOND = 1.2, 0.9


def edge_scenario(
    seed: int, people: int = 3, model: str = "kinect2", seconds: float = 10.0
) -> Scenario:
    """The edge scene for ``seed``: one ``model`` sensor, ``people`` people crossing the
    borders of its image at distances between 2.5 m and 5.5 m."""
    rng = np.random.default_rng(seed)
    length, width = EDGE_ROOM
    height = float(rng.uniform(2.2, 2.8))
    tilt = math.radians(float(rng.uniform(12.0, 22.0)))
    yaw = math.radians(float(rng.uniform(-10.0, 10.0)))
    at = np.array([-length / 2 + 0.3, float(rng.uniform(-1.0, 1.0))])
    forward = np.array([math.cos(yaw), math.sin(yaw)])
    right = np.array([forward[1], -forward[0]])  # the image's +x on the floor
    look = at + forward * (height / math.tan(tilt))
    intrinsics = MODELS[model]().intrinsics
    half_fov = math.atan2(intrinsics.width / 2.0, intrinsics.fx)
    distances = np.sort(rng.uniform(2.5, 5.5, people))
    sides = rng.permutation(np.resize([1.0, -1.0], people))
    routes = []
    for distance, side in zip(distances, sides, strict=True):
        edge = distance * math.tan(half_fov)
        ends = [at + forward * distance + right * side * (edge + s) for s in (-INSIDE, BEYOND)]
        half = np.array([length / 2, width / 2]) - WALL_MARGIN
        routes.append([tuple(float(v) for v in np.clip(p, -half, half)) for p in ends])
    return Scenario(
        name=f"edge-{seed}",
        description="people crossing the borders of one sensor's image",
        seconds=seconds,
        venue=VenueSpec(size=(length, width)),
        sensors=SensorsSpec(
            count=1,
            model=model,  # type: ignore[arg-type]
            poses=[
                SensorPose(
                    at=(float(at[0]), float(at[1]), height),
                    look_at=(float(look[0]), float(look[1]), 0.0),
                )
            ],
        ),
        people=PeopleSpec(count=people, routes=routes),  # type: ignore[arg-type]
    )
