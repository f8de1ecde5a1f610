"""The filter's fused hot loop (score.py) against the plain path it replaces."""

from __future__ import annotations

import numpy as np
import pytest

from optrack.skeleton.filter import PARTITION_FRAMES, PARTITION_PARTS
from optrack.skeleton.likelihood import log_likelihood_numpy, sorted_points
from optrack.skeleton.model import (
    PARTITIONS,
    BodyShape,
    D,
    forward_kinematics,
    part_geometry,
    rest_state,
)
from optrack.skeleton.score import score_particles
from tests.skeleton.clouds import seen_cloud


@pytest.mark.parametrize(("partition", "seed"), [(name, s) for name in PARTITIONS for s in (1, 2)])
def test_fused_score_equals_kinematics_geometry_and_the_numpy_likelihood(partition, seed):
    rng = np.random.default_rng(seed)
    shape = BodyShape.from_height(rng.uniform(1.5, 1.95))
    estimate = rest_state(shape, *rng.uniform(-2, 2, 2), rng.uniform(-3, 3))
    estimate[3:] += rng.normal(0.0, 0.2, D - 3)
    points = np.concatenate(
        [
            seen_cloud(estimate, shape, rng, points=int(rng.integers(100, 600))),
            rng.uniform([-3, -3, 0], [3, 3, 2], (20, 3)),
        ]
    )
    particles = estimate + rng.normal(0.0, 0.2, (300, D))
    dims, parts = PARTITIONS[partition], PARTITION_PARTS[partition]
    expected = rng.uniform(0.0, 20.0, (len(parts), 2))
    baseline = None if partition == "torso" else rng.uniform(0.0, 1.0, len(points))
    cloud = sorted_points(points, baseline)
    fast = score_particles(
        particles, estimate, dims, PARTITION_FRAMES[partition], parts, shape, cloud,
        expected, (0.15, 0.6, 0.5), threads=2,
    )  # fmt: skip
    states = np.broadcast_to(estimate, particles.shape).copy()
    states[:, list(dims)] = particles[:, list(dims)]
    geometry = part_geometry(*forward_kinematics(states, shape), shape, parts)
    plain = log_likelihood_numpy(points, geometry, expected, 0.15, 0.6, 0.5, baseline)
    np.testing.assert_allclose(fast, plain, atol=2e-4)
