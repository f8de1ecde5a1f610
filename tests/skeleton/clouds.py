"""Synthetic clouds of the body model, seen from a few directions (tests only).

Points are spread over the model's surface at a known pose; a point is kept
if its outward normal faces at least one of the sensors (self-occlusion by
other parts is not modelled), then a random subset is kept and Gaussian noise
added: a stand-in for a fused, down-sampled person cloud.
"""

from __future__ import annotations

import numpy as np

from optrack.skeleton.model import BodyShape, surface_points


def seen_cloud(
    state: np.ndarray,
    shape: BodyShape,
    rng: np.random.Generator,
    points: int = 500,
    sensors: int = 3,
    noise: float = 0.01,
    distance: float = 3.0,
) -> np.ndarray:
    """(<= points, 3) world points of the body at ``state`` seen by ``sensors`` sensors
    evenly around it at ``distance`` metres, 2.5 m high (looking down, as mounted)."""
    surface, normal = surface_points(state, shape, 20 * points, rng)
    angles = np.arange(sensors) * 2.0 * np.pi / sensors + 0.3
    centres = np.stack(
        [
            state[0] + distance * np.cos(angles),
            state[1] + distance * np.sin(angles),
            np.full(sensors, 2.5),
        ],
        axis=1,
    )
    seen = np.zeros(len(surface), dtype=bool)
    for centre in centres:
        seen |= np.sum(normal * (centre - surface), axis=1) > 0.0
    kept = surface[seen]
    kept = kept[rng.choice(len(kept), min(points, len(kept)), replace=False)]
    return kept + rng.normal(0.0, noise, kept.shape)
