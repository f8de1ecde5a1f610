"""The filter's numba helpers against the plain numpy they replace, to the bit."""

from __future__ import annotations

import numpy as np
import pytest

from optrack.skeleton.filter import _take_and_diffuse, systematic_resample
from optrack.skeleton.kernels import nearest_areas, part_distances, segment_distances
from optrack.skeleton.likelihood import associate, signed_distance
from optrack.skeleton.model import (
    LIMITS,
    BodyShape,
    D,
    forward_kinematics,
    part_geometry,
    rest_state,
)
from tests.skeleton.clouds import seen_cloud


@pytest.mark.parametrize("seed", range(4))
def test_systematic_resampling_equals_numpys_searchsorted(seed):
    rng = np.random.default_rng(seed)
    weights = rng.exponential(size=500) ** (1 + seed)
    weights[rng.random(500) < 0.3] = 0.0
    weights /= weights.sum()
    fast = systematic_resample(weights, np.random.default_rng(seed))
    positions = (np.random.default_rng(seed).random() + np.arange(500)) / 500
    cumulative = np.cumsum(weights)
    cumulative[-1] = 1.0
    np.testing.assert_array_equal(fast, np.searchsorted(cumulative, positions))


@pytest.mark.parametrize("diffuse", [True, False])
def test_take_and_diffuse_equals_numpy(diffuse):
    rng = np.random.default_rng(3)
    particles = rng.normal(0.0, 1.5, (300, D))
    idx = np.arange(12, 16)
    chosen = np.sort(rng.integers(0, 300, 300))
    noise = rng.normal(size=(300 if diffuse else 0, len(idx)))
    sd = rng.uniform(0.05, 0.5, len(idx))
    expected = particles.copy()
    expected[:, idx] = expected[np.ix_(chosen, idx)]
    if diffuse:
        moved = expected[:, idx] + noise * sd
        expected[:, idx] = np.clip(moved, LIMITS[idx, 0], LIMITS[idx, 1])
    _take_and_diffuse(particles, idx, chosen, noise, sd, *LIMITS[idx].T)
    np.testing.assert_array_equal(particles, expected)
    assert not np.array_equal(particles[:, :12], expected[np.ix_(chosen, range(12))])


def test_distances_of_one_pose_equal_numpy():
    rng = np.random.default_rng(4)
    shape = BodyShape.from_height(1.7)
    state = rest_state(shape, 0.3, -0.2, 1.0)
    state[3:] += rng.normal(0.0, 0.2, D - 3)
    points = np.concatenate([seen_cloud(state, shape, rng), rng.uniform(-2, 2, (50, 3))])
    geometry = part_geometry(*forward_kinematics(state[None], shape), shape)
    np.testing.assert_array_equal(
        part_distances(points, geometry[0]), np.abs(signed_distance(points, geometry)[0][0])
    )
    g = geometry[0].astype(np.float64)
    v = points[:, None, :] - g[None, :, 0:3]
    s = np.clip(np.sum(v * g[None, :, 3:6], axis=2), g[:, 12], g[:, 13])
    segment = np.linalg.norm(v - s[..., None] * g[None, :, 3:6], axis=2)
    np.testing.assert_allclose(segment_distances(points, geometry[0]), segment, atol=1e-12)


@pytest.mark.parametrize("alpha", [0.3, 0.6, 1.5])
def test_nearest_areas_equal_the_associated_ones(alpha):
    rng = np.random.default_rng(5)
    shape = BodyShape.from_height(1.8)
    state = rest_state(shape, -0.4, 0.6, -2.0)
    state[3:] += rng.normal(0.0, 0.3, D - 3)
    points = np.concatenate([seen_cloud(state, shape, rng), rng.uniform(-2, 2, (80, 3))])
    geometry = part_geometry(*forward_kinematics(state[None], shape), shape)
    area = nearest_areas(points, geometry[0], alpha)
    np.testing.assert_array_equal(area, associate(points, geometry, alpha)[1][0])
    assert 0 < np.sum(area < 0) < len(points) and len(np.unique(area)) > 20
