"""The likelihood (eq. 7-9): distances by hand, association, and numba against numpy."""

from __future__ import annotations

import numpy as np
import pytest

from optrack.skeleton.likelihood import (
    associate,
    log_likelihood,
    log_likelihood_numpy,
    signed_distance,
    sorted_points,
    sorted_points_numpy,
)
from optrack.skeleton.model import (
    PARTS,
    BodyShape,
    D,
    G,
    forward_kinematics,
    part_geometry,
    rest_state,
)
from tests.skeleton.clouds import seen_cloud


def cylinder(r0=0.1, dr=0.0, aspect=1.0, length=1.0, s0=0.0, s1=1.0, z=0.0) -> np.ndarray:
    """One part by hand: from (0, 0, z) up the z axis, forward radius along x."""
    g = np.zeros((1, 1, G), dtype=np.float32)
    g[0, 0, 0:3] = (0.0, 0.0, z)
    g[0, 0, 3:6] = (0.0, 0.0, 1.0)
    g[0, 0, 6:9] = (1.0, 0.0, 0.0)
    g[0, 0, 9:12] = (0.0, 1.0 / aspect, 0.0)
    g[0, 0, 12:17] = (s0 * length, s1 * length, r0, dr, 1.0 / length)
    return g


@pytest.mark.parametrize(
    ("point", "expected"),
    [
        ((0.1, 0.0, 0.5), 0.0),  # on the surface
        ((0.2, 0.0, 0.5), 1.0),  # one radius outside
        ((0.0, 0.0, 0.5), -1.0),  # on the axis
        ((0.05, 0.0, 0.3), -0.5),  # halfway in
        ((0.0, 0.0, 1.05), -0.5),  # past the end, inside the cap
        ((0.0, 0.0, 1.1), 0.0),  # the cap's tip
    ],
)
def test_signed_scaled_distance_of_eq_7(point, expected):
    d, _ = signed_distance(np.array([point]), cylinder())
    assert d[0, 0, 0] == pytest.approx(expected, abs=1e-6)


def test_radius_varies_along_the_part_and_the_side_radius_follows_the_aspect():
    tapered = cylinder(r0=0.1, dr=0.1)  # 0.1 m at the start, 0.2 m at the end
    d, _ = signed_distance(np.array([[0.15, 0.0, 0.5], [0.2, 0.0, 1.0], [0.2, 0, 1.5]]), tapered)
    # Past the end the radius stays at its end value: the cap of radius 0.2 m.
    np.testing.assert_allclose(d[0, :, 0], [0.0, 0.0, np.hypot(0.2, 0.5) / 0.2 - 1], atol=1e-6)
    wide = cylinder(r0=0.1, aspect=1.5)  # 0.15 m to the side
    d, _ = signed_distance(np.array([[0.0, 0.15, 0.5], [0.0, 0.3, 0.5]]), wide)
    np.testing.assert_allclose(d[0, :, 0], [0.0, 1.0], atol=1e-6)


def test_extended_cylinder_starts_before_its_joint():
    extended = cylinder(s0=-0.2)
    d, half = signed_distance(np.array([[0.1, 0.0, -0.1], [0.1, 0.0, 0.9]]), extended)
    np.testing.assert_allclose(d[0, :, 0], [0.0, 0.0], atol=1e-6)
    assert list(half[0, :, 0]) == [0, 1]  # near the start joint, near the end joint


def test_association_takes_the_nearest_part_within_alpha_else_clutter():
    two = np.concatenate([cylinder(), cylinder(z=2.0)], axis=1)  # parts 0 and 1
    points = np.array([[0.11, 0, 0.2], [0.0, 0.12, 2.9], [3.0, 0, 0.5]])
    best, area = associate(points, two, alpha=0.5)
    np.testing.assert_allclose(best[0], [0.1, 0.2, 0.5], atol=1e-5)
    assert list(area[0]) == [0, 3, -1]  # part 0 near its start, part 1 near its end, clutter
    # A baseline (parts already fixed) that explains a point better takes it.
    best, area = associate(points, two, alpha=0.5, baseline=np.array([0.05, 0.5, 0.5]))
    assert list(area[0]) == [-1, 3, -1] and best[0, 0] == pytest.approx(0.05)


def test_eq_9_by_hand():
    points = np.array([[0.11, 0, 0.2], [0.0, 0.0, 0.5], [3.0, 0, 0.5]])  # d: 0.1, -1, far
    sigma, alpha = 0.2, 0.5
    expected = np.array([[1.0, 2.0]])  # the start half should hold 1 point, the end half 2
    ll = log_likelihood_numpy(points, cylinder(), expected, sigma, alpha, support_weight=0.3)
    data = (0.1**2 + 0.5**2 + 0.5**2) / (2 * sigma**2) / 3
    support = 0.3 * (0.0 + 1.0)  # start half: 1 of 1; end half: 0 of 2
    assert ll[0] == pytest.approx(-data - support, abs=1e-6)
    fast = log_likelihood(points, cylinder(), expected, sigma, alpha, support_weight=0.3)
    assert fast[0] == pytest.approx(ll[0], abs=1e-5)


def _random_case(seed: int):
    rng = np.random.default_rng(seed)
    shape = BodyShape.from_height(rng.uniform(1.5, 1.95))
    truth = rest_state(shape, *rng.uniform(-2, 2, 2), rng.uniform(-3, 3))
    surface = seen_cloud(truth, shape, rng, points=int(rng.integers(100, 600)), noise=0.02)
    clutter = rng.uniform([-3, -3, 0], [3, 3, 2], (30, 3))
    points = np.concatenate([surface, clutter])
    states = truth + rng.normal(0.0, 0.15, (64, D))
    pts, rot = forward_kinematics(states, shape)
    parts = np.sort(rng.choice(len(PARTS), int(rng.integers(1, len(PARTS) + 1)), replace=False))
    expected = rng.uniform(0.0, 20.0, (len(parts), 2))
    baseline = rng.uniform(0.0, 1.0, len(points)) if seed % 2 else None
    return points, part_geometry(pts, rot, shape, parts), expected, baseline


@pytest.mark.parametrize("seed", range(6))
def test_numba_fast_path_equals_the_numpy_reference(seed):
    points, geometry, expected, baseline = _random_case(seed)
    args = (points, geometry, expected, 0.15, 0.6, 0.7, baseline)
    np.testing.assert_allclose(log_likelihood(*args), log_likelihood_numpy(*args), atol=2e-4)


@pytest.mark.parametrize("seed", range(4))
def test_the_compiled_sorted_cloud_is_numpys_to_the_bit(seed):
    """The kernels' view of a cloud (sorted along its widest axis, its slices' starts, the
    baseline in that order) is the numpy reference's: ties (points on a 1 cm grid) keep
    their order, and a cloud of 0, 1 or 2 points has its slices too."""
    rng = np.random.default_rng(seed)
    for count in (0, 1, 2, 37, 500):
        points = rng.normal(size=(count, 3)) * rng.uniform(0.1, 0.6, 3) + [1.0, -2.0, 0.9]
        if seed % 2:
            points = np.round(points, 2)
        baseline = rng.uniform(0.0, 1.0, count) if count % 2 else None
        fast, plain = sorted_points(points, baseline), sorted_points_numpy(points, baseline)
        assert int(fast[3]) == int(plain[3])  # the axis
        for got, want in zip(fast[:3] + fast[4:], plain[:3] + plain[4:], strict=True):
            assert got.dtype == want.dtype
            np.testing.assert_array_equal(got, want)


def test_the_true_pose_is_the_most_likely():
    rng = np.random.default_rng(5)
    shape = BodyShape.from_height(1.8)
    truth = rest_state(shape, 0.5, 0.5, 1.0)
    truth[12], truth[15], truth[20], truth[23] = 0.7, 1.0, 0.4, 0.6
    points = seen_cloud(truth, shape, rng)
    states = np.concatenate([truth[None], truth + rng.normal(0.0, 0.1, (200, D))])
    pts, rot = forward_kinematics(states, shape)
    expected = np.full((len(PARTS), 2), 3.0)
    ll = log_likelihood(points, part_geometry(pts, rot, shape), expected, 0.15, 0.6, 0.5)
    assert np.argmax(ll) == 0


def test_a_part_without_data_pays_the_support_term():
    # A limb lifted into empty space: its points are gone, so it loses its support.
    shape = BodyShape.from_height(1.75)
    rng = np.random.default_rng(2)
    down = rest_state(shape)
    up = down.copy()
    up[13] = 1.5  # the left arm straight out sideways
    points = seen_cloud(down, shape, rng)
    pts, rot = forward_kinematics(np.stack([down, up]), shape)
    geometry = part_geometry(pts, rot, shape)
    expected = np.full((len(PARTS), 2), 4.0)
    with_support = log_likelihood(points, geometry, expected, 0.15, 0.6, 0.5)
    without = log_likelihood(points, geometry, expected, 0.15, 0.6, 0.0)
    assert with_support[0] > with_support[1]
    assert (with_support[1] - without[1]) < (with_support[0] - without[0])
