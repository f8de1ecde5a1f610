"""The filter's fused hot loop (kernels.py) against the plain path it replaces."""

from __future__ import annotations

import numpy as np
import pytest

from optrack.skeleton.filter import PARTITION_FRAMES, PARTITION_PARTS
from optrack.skeleton.kernels import LANES, PartitionScorer
from optrack.skeleton.likelihood import log_likelihood_numpy, sorted_points
from optrack.skeleton.model import (
    PARTITIONS,
    PARTS,
    BodyShape,
    D,
    forward_kinematics,
    part_geometry,
    rest_state,
)
from tests.skeleton.clouds import seen_cloud

# The torso scored with the legs only (initialisation's first search).
_TORSO_AND_LEGS = np.array([k for k, p in enumerate(PARTS) if not p.partition.endswith("arm")])


def _case(partition: str, seed: int, count: int):
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
    particles = estimate + rng.normal(0.0, 0.2, (count, D))
    expected = rng.uniform(0.0, 20.0, (len(PARTS), 2))
    baseline = None if partition == "torso" else rng.uniform(0.0, 1.0, len(points))
    return shape, estimate, points, particles, expected, baseline


def _plain(shape, estimate, points, particles, dims, parts, expected, baseline, consts):
    states = np.broadcast_to(estimate, particles.shape).copy()
    states[:, list(dims)] = particles[:, list(dims)]
    geometry = part_geometry(*forward_kinematics(states, shape), shape, parts)
    return log_likelihood_numpy(points, geometry, expected, *consts, baseline)


@pytest.mark.parametrize(
    ("partition", "seed", "count", "threads"),
    [(name, s, 300, 1 + s % 2) for name in PARTITIONS for s in (1, 2)]
    + [("torso", 3, LANES - 5, 1), ("right_leg", 4, 2 * LANES + 1, 2)],
)
def test_fused_score_equals_kinematics_geometry_and_the_numpy_likelihood(
    partition, seed, count, threads
):
    shape, estimate, points, particles, expected, baseline = _case(partition, seed, count)
    dims, parts = PARTITIONS[partition], PARTITION_PARTS[partition]
    consts = (0.15, 0.6, 0.5)
    scorer = PartitionScorer(
        estimate, dims, PARTITION_FRAMES[partition], parts, shape,
        sorted_points(points, baseline), expected[parts], consts, threads=threads,
    )  # fmt: skip
    fast = scorer(particles)
    np.testing.assert_array_equal(scorer(particles[::-1]), fast[::-1])  # made once, reused
    plain = _plain(
        shape, estimate, points, particles, dims, parts, expected[parts], baseline, consts
    )
    assert fast.shape == (count,)
    np.testing.assert_allclose(fast, plain, atol=2e-4)
    assert np.ptp(plain) > 0.05  # the particles differ: a wrong pose would show


def test_fused_score_of_a_subset_of_parts():
    shape, estimate, points, particles, expected, _ = _case("torso", 5, 100)
    parts, consts = _TORSO_AND_LEGS, (0.2, 0.5, 0.3)
    fast = PartitionScorer(
        estimate, PARTITIONS["torso"], PARTITION_FRAMES["torso"], parts, shape,
        sorted_points(points, None), expected[parts], consts,
    )(particles)  # fmt: skip
    plain = _plain(shape, estimate, points, particles, PARTITIONS["torso"], parts,
                   expected[parts], None, consts)  # fmt: skip
    np.testing.assert_allclose(fast, plain, atol=2e-4)
