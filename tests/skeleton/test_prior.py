"""The arms' collision prior (optrack/skeleton/prior.py) against known poses and eq. 7."""

from __future__ import annotations

import numpy as np
import pytest

from optrack.skeleton.filter import SkeletonFilter
from optrack.skeleton.init import pose_log_likelihood
from optrack.skeleton.likelihood import set_threads, signed_distance
from optrack.skeleton.model import (
    PART_INDEX,
    POINTS,
    BodyShape,
    forward_kinematics,
    part_geometry,
    rest_state,
)
from optrack.skeleton.params import SKELETON_PARAMS
from optrack.skeleton.prior import ArmCollision, arm_collision_cost

SHAPE = BodyShape.from_height(1.75)
PARAMS = SKELETON_PARAMS.create()
LEFT_ARM = slice(12, 16)


def reference_cost(state: np.ndarray, side: str, params=PARAMS) -> float:
    """The prior by its definition: eq. 7's signed distance of the elbow, the forearm's
    middle and the wrist to the trunk's and the head's parts (plain numpy); against the
    head, the forearm's thickness (its radius in the head's radii) counts as depth."""
    pts, rot = forward_kinematics(state, SHAPE)
    body = [PART_INDEX[name] for name in ("lower_trunk", "upper_trunk", "head")]
    every = part_geometry(pts[None], rot[None], SHAPE)[0].astype(np.float64)
    geometry = every[None, body]
    thickness = every[PART_INDEX[f"{side}_forearm"], 14] / every[PART_INDEX["head"], 14]
    margins = float(params.collision_margin) - np.array([0.0, 0.0, thickness])
    elbow, wrist = pts[POINTS.index(f"{side}_elbow")], pts[POINTS.index(f"{side}_wrist")]
    tested = np.array([elbow, (elbow + wrist) / 2, wrist])
    d = signed_distance(tested, geometry)[0][0]  # (3 points, 3 parts)
    depth = np.maximum(-d - margins, 0.0).max(axis=1)
    return float(params.collision_weight) * float(depth.sum())


def test_arms_at_the_side_in_front_and_raised_cost_nothing():
    for arm in ([0.0, 0.1, 0.0, 0.3], [0.3, 0.0, 0.6, 1.5], [0.0, 3.0, 0.0, 0.0]):
        state = rest_state(SHAPE)
        state[12:16] = state[16:20] = arm  # hanging; a hand on the belly; raised sideways
        assert arm_collision_cost(state, SHAPE, PARAMS) == 0.0


def test_an_arm_folded_into_the_head_or_through_the_chest_costs():
    state = rest_state(SHAPE)
    state[LEFT_ARM] = [3.0, -0.5, -1.3, 2.5]  # the walk's failure: up, folded behind the head
    into_head = arm_collision_cost(state, SHAPE, PARAMS)
    state[LEFT_ARM] = [0.0, -0.5, 1.2, 0.5]  # drawn in across the body, through the hips
    through_hips = arm_collision_cost(state, SHAPE, PARAMS)
    assert into_head > 0.5 and through_hips > 0.5
    assert arm_collision_cost(state, SHAPE, SKELETON_PARAMS.create({"collision_weight": 0})) == 0


def test_an_arm_folded_at_the_heads_side_pays_for_its_thickness():
    # The walk's arm put on the head with two sensors (traced): its axis hardly enters
    # the head, its surface does.
    state = rest_state(SHAPE)
    state[16:20] = [3.02, -0.46, -1.47, 1.82]
    folded = arm_collision_cost(state, SHAPE, PARAMS)
    thin = BodyShape.from_height(1.75).scaled(limb_radius=0.5)
    assert folded > 1.5
    assert arm_collision_cost(state, thin, PARAMS) < folded - 0.5
    assert folded == pytest.approx(reference_cost(state, "right"), abs=1e-4)


@pytest.mark.parametrize("seed", [0, 1])
def test_the_kernel_matches_the_definition_on_random_arms(seed):
    rng = np.random.default_rng(seed)
    estimate = rest_state(SHAPE, 0.3, -0.2, 0.7)
    estimate[6:9] = rng.uniform(-0.3, 0.3, 3)  # a bent spine
    particles = np.tile(estimate, (300, 1))
    particles[:, LEFT_ARM] = rng.uniform([-1.0, -0.6, -1.5, 0.0], [3.1, 3.0, 1.5, 2.6], (300, 4))
    prior = ArmCollision(estimate, "left_arm", SHAPE, PARAMS)
    set_threads(1)
    costs = prior(particles)
    expected = [reference_cost(state, "left") for state in particles]
    assert np.count_nonzero(costs) > 3  # some of them do pass through the body
    np.testing.assert_allclose(costs, expected, atol=1e-4)
    # Threads share the particles (ten groups of 32, the last short): the same numbers.
    set_threads(2)
    np.testing.assert_array_equal(prior(particles), costs)
    set_threads(1)
    # The torso and the legs have no prior.
    assert not ArmCollision(estimate, "torso", SHAPE, PARAMS).active
    assert not np.any(ArmCollision(estimate, "left_leg", SHAPE, PARAMS)(particles))


def test_the_full_body_score_pays_the_prior():
    state = rest_state(SHAPE)
    state[LEFT_ARM] = [3.0, -0.5, -1.3, 2.5]
    filt = SkeletonFilter(SHAPE, PARAMS, seed=0)
    off = SkeletonFilter(SHAPE, SKELETON_PARAMS.create({"collision_weight": 0}), seed=0)
    points = forward_kinematics(rest_state(SHAPE), SHAPE)[0]
    gap = pose_log_likelihood(off, points, state) - pose_log_likelihood(filt, points, state)
    assert gap == pytest.approx(arm_collision_cost(state, SHAPE, PARAMS))
