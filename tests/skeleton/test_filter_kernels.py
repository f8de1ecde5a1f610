"""The filter's numba helpers against the plain numpy they replace, to the bit."""

from __future__ import annotations

import numpy as np
import pytest

from optrack.skeleton.filter import (
    _random_walk,
    _resample_layer,
    _take_and_diffuse,
    _weights,
    exp_nonpositive,
    systematic_resample,
)
from optrack.skeleton.kernels import limb_points, limb_points_numpy, nearest_areas
from optrack.skeleton.likelihood import associate
from optrack.skeleton.model import (
    LIMITS,
    PARTS,
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


def test_the_weights_exp_equals_numpys():
    """The annealing weights' exp (a loop that vectorises) against numpy's, over the
    range it is used on: 0 exactly 1, under -700 held at exp(-700), positive as 0."""
    rng = np.random.default_rng(5)
    x = np.concatenate(
        [
            [0.0, -0.0, -1e-300, -np.log(2.0), -0.5 * np.log(2.0), -700.0],
            -rng.exponential(3.0, 2000),
        ]
    )
    x = np.concatenate([x, -rng.uniform(0.0, 700.0, 2000)])
    out = np.empty_like(x)
    exp_nonpositive(x, out)
    np.testing.assert_allclose(out, np.exp(x), rtol=4e-16, atol=0.0)
    assert out[0] == 1.0 and out[1] == 1.0
    beyond = np.array([-701.0, -1e6, 3.0])
    exp_nonpositive(beyond, out[:3])
    np.testing.assert_array_equal(out[:3], [np.exp(-700.0), np.exp(-700.0), 1.0])


@pytest.mark.parametrize("diffuse", [True, False])
def test_take_and_diffuse_equals_numpy(diffuse):
    """The normals numba's Generator draws in the loop are numpy's standard_normal's, in
    its order, and the stream goes on from the same place."""
    rng = np.random.default_rng(3)
    particles = rng.normal(0.0, 1.5, (300, D))
    idx = np.arange(12, 16)
    chosen = np.sort(rng.integers(0, 300, 300))
    sd = rng.uniform(0.05, 0.5, len(idx))
    stream, reference = np.random.default_rng(11), np.random.default_rng(11)
    expected = particles.copy()
    expected[:, idx] = expected[np.ix_(chosen, idx)]
    if diffuse:
        moved = expected[:, idx] + reference.standard_normal((300, len(idx))) * sd
        expected[:, idx] = np.clip(moved, LIMITS[idx, 0], LIMITS[idx, 1])
    _take_and_diffuse(particles, idx, chosen, stream, diffuse, sd, *LIMITS[idx].T)
    np.testing.assert_array_equal(particles, expected)
    assert not np.array_equal(particles[:, :12], expected[np.ix_(chosen, range(12))])
    assert stream.random() == reference.random()


def test_a_layers_resampling_draws_numpys_numbers_in_order():
    """_resample_layer: u for the systematic resampling, then the diffusion's normals,
    from the filter's stream, as the filter drew them with numpy."""
    rng = np.random.default_rng(8)
    particles = rng.normal(0.0, 0.3, (400, D))
    ll = -rng.exponential(2.0, 400)
    idx = np.arange(0, 12)
    sd = rng.uniform(0.01, 0.1, len(idx))
    low, high = LIMITS[idx].T
    stream, reference = np.random.default_rng(21), np.random.default_rng(21)
    expected = particles.copy()
    chosen = systematic_resample(_weights(ll, 0.5), reference)
    moved = expected[np.ix_(chosen, idx)] + reference.standard_normal((400, len(idx))) * sd
    expected[:, idx] = np.clip(moved, low, high)
    _resample_layer(particles, idx, ll, 0.5, stream, True, sd, low, high)
    np.testing.assert_array_equal(particles, expected)
    assert stream.random() == reference.random()


def test_the_random_walk_equals_numpy():
    rng = np.random.default_rng(4)
    particles = np.clip(rng.normal(0.0, 1.0, (500, D)), LIMITS[:, 0], LIMITS[:, 1])
    drift = rng.normal(0.0, 0.05, D)
    step = rng.uniform(0.01, 0.5, D)
    stream, reference = np.random.default_rng(13), np.random.default_rng(13)
    noise = reference.standard_normal(particles.shape)
    expected = np.clip((particles + drift) + noise * step, LIMITS[:, 0], LIMITS[:, 1])
    assert np.any(expected == LIMITS[:, 0]) and np.any(expected == LIMITS[:, 1])  # clipped
    _random_walk(particles, drift, step, LIMITS[:, 0], LIMITS[:, 1], stream)
    np.testing.assert_array_equal(particles, expected)
    assert stream.random() == reference.random()


@pytest.mark.parametrize(("partition", "gate"), [("left_arm", 0.35), ("right_leg", 0.0)])
def test_limb_points_equal_numpy(partition, gate):
    rng = np.random.default_rng(4)
    shape = BodyShape.from_height(1.7)
    state = rest_state(shape, 0.3, -0.2, 1.0)
    state[3:] += rng.normal(0.0, 0.2, D - 3)
    points = np.concatenate([seen_cloud(state, shape, rng), rng.uniform(-2, 2, (50, 3))])
    pts, rot = forward_kinematics(state, shape)
    geometry = part_geometry(pts[None], rot[None], shape)[0]
    fixed = np.array([part.partition != partition for part in PARTS])
    own = np.flatnonzero(~fixed)
    args = (points, geometry, fixed, own, 0.6, gate, pts[4], 0.9)
    baseline, near = limb_points(*args)
    reference = limb_points_numpy(*args)
    np.testing.assert_array_equal(baseline, reference[0])
    np.testing.assert_array_equal(near, reference[1])
    assert 0 < near.sum() < len(points) and 0 < np.sum(baseline < 0.6) < len(points)


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
