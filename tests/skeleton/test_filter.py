"""The annealed particle filter: its pieces, and recovering a known pose from its cloud."""

from __future__ import annotations

import numpy as np
import pytest

from optrack.params import REGISTRY
from optrack.skeleton.filter import (
    SkeletonFilter,
    annealing_exponent,
    motion_spread,
    systematic_resample,
)
from optrack.skeleton.joints import JOINTS
from optrack.skeleton.model import BodyShape, D, forward_kinematics, rest_state
from optrack.skeleton.params import SKELETON_PARAMS
from tests.skeleton.clouds import seen_cloud


def test_every_knob_is_in_the_registered_schema_with_help():
    assert REGISTRY["skeleton"] is SKELETON_PARAMS
    assert SKELETON_PARAMS["particles"].default == 2000
    for param in SKELETON_PARAMS:
        assert param.help and param.min is not None and param.max is not None


def test_annealing_exponent_keeps_the_survival_rate():
    rng = np.random.default_rng(0)
    ll = rng.normal(0.0, 3.0, 1000)
    for rate in (0.2, 0.5, 0.8):
        beta = annealing_exponent(ll, rate)
        w = np.exp(beta * (ll - ll.max()))
        assert w.sum() ** 2 / np.sum(w * w) == pytest.approx(rate * 1000, rel=0.01)


def _bisected_exponent(ll: np.ndarray, rate: float) -> float:
    """The reference: plain bisection in log10(beta), 60 halvings of 14 decades."""
    centred = ll - ll.max()
    low, high = -6.0, 8.0
    for _ in range(60):
        mid = 0.5 * (low + high)
        w = np.exp(10.0**mid * centred)
        low, high = (mid, high) if w.sum() ** 2 / np.sum(w * w) > rate * len(ll) else (low, mid)
    return 10.0**low


@pytest.mark.parametrize("seed", range(6))
def test_annealing_exponent_is_the_bisected_one(seed):
    # Spreads from a flat to a peaked likelihood, and ties at the top (the ESS cannot go
    # below the number of tied maxima): Newton's steps land where bisection does.
    rng = np.random.default_rng(seed)
    spread = 10.0 ** rng.uniform(-2, 3)
    ll = rng.normal(0.0, spread, 2000)
    if seed % 2:
        ll[:40] = ll.max()
    for rate in (0.05, 0.2, 0.5, 0.8):
        assert annealing_exponent(ll, rate) == pytest.approx(_bisected_exponent(ll, rate), rel=1e-4)


def test_systematic_resampling_follows_the_weights():
    weights = np.array([0.5, 0.25, 0.25, 0.0])
    counts = np.bincount(
        systematic_resample(weights, np.random.default_rng(1)).repeat(1), minlength=4
    )
    assert list(counts) == [2, 1, 1, 0]


def test_motion_spread_grows_with_time_up_to_max_dt():
    params = SKELETON_PARAMS.create({"agility_arms_rad": 6.0, "max_dt": 0.1})
    assert motion_spread(params, 1 / 30)[12] == pytest.approx(6.0 / 30)
    assert motion_spread(params, 5.0)[12] == pytest.approx(0.6)


def _pose(shape: BodyShape) -> np.ndarray:
    truth = rest_state(shape, 1.0, -0.5, 2.3)
    truth[6], truth[8] = 0.15, -0.2  # bent forward a little, turned
    truth[12], truth[13], truth[15] = 0.9, 0.3, 1.3  # left arm forward, elbow bent
    truth[17], truth[19] = 1.0, 0.4  # right arm out to the side
    truth[20], truth[23] = 0.6, 0.9  # left leg lifted, knee bent
    truth[24], truth[27] = -0.1, 0.1
    return truth


@pytest.mark.parametrize(("sensors", "worst"), [(2, 0.12), (3, 0.10)])
def test_filter_recovers_a_known_pose_from_its_own_cloud(sensors, worst):
    rng = np.random.default_rng(sensors)
    shape = BodyShape.from_height(1.75)
    truth = _pose(shape)
    joints = forward_kinematics(truth, shape)[0][: len(JOINTS)]
    start = truth.copy()
    start[:3] += [0.05, -0.04, 0.03]
    start[3:] += rng.normal(0.0, 0.15, D - 3)
    filt = SkeletonFilter(shape, SKELETON_PARAMS.create(), seed=0)
    filt.reset(start)
    for _ in range(10):
        estimate = filt.step(seen_cloud(truth, shape, rng, sensors=sensors), 1 / 30)
    error = np.linalg.norm(forward_kinematics(estimate, shape)[0][: len(JOINTS)] - joints, axis=1)
    assert error.mean() < 0.04, error.round(3)
    assert error.max() < worst, error.round(3)  # the head, the least constrained, is worst


def test_a_snapshot_restores_the_filter_exactly_random_numbers_included():
    shape = BodyShape.from_height(1.75)
    truth = rest_state(shape, 0.2, -0.4, 0.5)
    rng = np.random.default_rng(2)
    filt = SkeletonFilter(shape, SKELETON_PARAMS.create({"particles": 300}), seed=3)
    filt.reset(truth, 0.05)
    filt.step(seen_cloud(truth, shape, rng), 1 / 30)
    saved = filt.snapshot()
    estimate, particles = filt.estimate.copy(), filt.particles.copy()
    limbs, draw = filt.limb_velocity.copy(), filt.rng.random()
    filt.restore(saved)
    assert filt.rng.random() == draw  # the same stream: the draw comes again
    filt.restore(saved)
    moved = rest_state(shape, 0.4, -0.4, 0.9)
    filt.step(seen_cloud(moved, shape, rng), 1 / 30)  # changes all of it
    assert not np.array_equal(filt.estimate, estimate)
    filt.restore(saved)
    np.testing.assert_array_equal(filt.estimate, estimate)
    np.testing.assert_array_equal(filt.particles, particles)
    np.testing.assert_array_equal(filt.limb_velocity, limbs)
    assert filt.rng.random() == draw
    filt.estimate[0] += 1.0  # the snapshot holds copies: changing the filter leaves it
    filt.restore(saved)
    assert filt.estimate[0] == estimate[0]
