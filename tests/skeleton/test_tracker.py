"""Initialisation from a standing pose, the tracker's states, and the shape estimate."""

from __future__ import annotations

import numpy as np
import pytest

from optrack.skeleton import tracker as tracker_module
from optrack.skeleton.filter import SkeletonFilter
from optrack.skeleton.init import (
    body_axis,
    facing_candidates,
    height_from_cloud,
    initialise,
    initialise_both_ways,
)
from optrack.skeleton.joints import JOINTS
from optrack.skeleton.model import BodyShape, forward_kinematics, rest_state
from optrack.skeleton.params import SKELETON_PARAMS
from optrack.skeleton.shape import estimate_shape
from optrack.skeleton.tracker import SkeletonTracker
from tests.skeleton.clouds import seen_cloud

SHAPE = BodyShape.from_height(1.75)


def standing(rng: np.random.Generator, heading: float) -> np.ndarray:
    """A standing pose: arms anywhere in half their range, legs nearly straight."""
    state = rest_state(SHAPE, 0.4, -0.3, heading)
    state[12:20] = rng.uniform([-0.3, -0.2, -0.6, 0.0] * 2, [1.5, 1.4, 0.6, 1.4] * 2)
    state[20:28] = rng.uniform([-0.1, -0.1, -0.2, 0.0] * 2, [0.2, 0.2, 0.2, 0.2] * 2)
    return state


def joint_errors(state: np.ndarray, truth: np.ndarray) -> np.ndarray:
    a = forward_kinematics(state, SHAPE)[0][: len(JOINTS)]
    return np.linalg.norm(a - forward_kinematics(truth, SHAPE)[0][: len(JOINTS)], axis=1)


def test_height_and_heading_from_the_cloud():
    rng = np.random.default_rng(0)
    truth = rest_state(SHAPE, 0.0, 0.0, 0.7)
    cloud = seen_cloud(truth, SHAPE, rng, noise=0.0)
    assert height_from_cloud(cloud) == pytest.approx(1.75, abs=0.06)
    headings, sure = facing_candidates(cloud, SHAPE)
    gap = np.angle(np.exp(1j * (np.array(headings) - 0.7)))
    assert sure and abs(gap[0]) < 0.15 and abs(gap[1]) > np.pi - 0.15  # the feet tell front


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_initialisation_finds_a_standing_pose_from_nothing(seed):
    rng = np.random.default_rng(seed)
    truth = standing(rng, rng.uniform(-np.pi, np.pi))
    filt = SkeletonFilter(SHAPE, SKELETON_PARAMS.create(), seed=seed)
    state = initialise(filt, seen_cloud(truth, SHAPE, rng))
    error = joint_errors(state, truth)
    assert error.mean() < 0.06, error.round(3)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_initialisation_finds_the_body_axis_where_the_chest_band_misleads(seed):
    # Both arms raised forward, level with the chest: the chest band is widest along the
    # heading, not across it (as a runner's swinging arms make it).
    rng = np.random.default_rng(seed)
    heading = rng.uniform(-np.pi, np.pi)
    truth = rest_state(SHAPE, 0.2, 0.1, heading)
    truth[12], truth[16] = 1.4, 1.4
    cloud = seen_cloud(truth, SHAPE, rng)
    (guess, _), _ = facing_candidates(cloud, SHAPE)

    def axis_gap(angle: float) -> float:  # radians from the heading's axis, 0..pi/2
        return abs(float(np.angle(np.exp(2j * (angle - heading))))) / 2

    assert axis_gap(guess) > np.pi / 4  # the chest band alone is misled
    filt = SkeletonFilter(SHAPE, SKELETON_PARAMS.create(), seed=seed)
    assert axis_gap(body_axis(filt, cloud)) < 0.15
    state = initialise(SkeletonFilter(SHAPE, SKELETON_PARAMS.create(), seed=seed), cloud)
    assert abs(np.angle(np.exp(1j * (state[3] - heading)))) < 0.3  # facing the right way
    assert joint_errors(state, truth).mean() < 0.06


def test_initialisation_says_how_clearly_its_heading_won():
    rng = np.random.default_rng(5)
    truth = standing(rng, 0.4)
    cloud = seen_cloud(truth, SHAPE, rng)
    state = initialise(SkeletonFilter(SHAPE, SKELETON_PARAMS.create(), seed=5), cloud)
    same, margin = initialise_both_ways(
        SkeletonFilter(SHAPE, SKELETON_PARAMS.create(), seed=5), cloud
    )
    np.testing.assert_array_equal(same, state)
    # Seen from all around, the body facing backwards explains the cloud far worse.
    assert margin > tracker_module._TURN_DOUBT


def test_a_clear_start_skips_the_turned_round_tries_and_loses_nothing(monkeypatch):
    """After a start whose heading won clearly, the body is not tried turned round; where
    the tries would have been made they are refused, so the skeleton is the same frame by
    frame, to the bit."""
    rng = np.random.default_rng(6)
    truth = standing(rng, -1.2)
    clouds = [seen_cloud(truth, SHAPE, rng) for _ in range(14)]
    tries = []
    real = tracker_module.turn_around

    def counted(filt, points, margin):
        tries.append(real(filt, points, margin))
        return tries[-1]

    monkeypatch.setattr(tracker_module, "turn_around", counted)

    def run(doubt: float) -> list[np.ndarray]:
        monkeypatch.setattr(tracker_module, "_TURN_DOUBT", doubt)
        tracker = SkeletonTracker(SKELETON_PARAMS.create(), SHAPE, seed=3)
        return [tracker.update(cloud, t / 30).joints for t, cloud in enumerate(clouds)]

    always = run(np.inf)
    assert tries == [False, False]  # tried twice in its first half second, refused
    default = run(0.2)
    assert len(tries) == 2  # not tried
    for a, b in zip(always, default, strict=True):
        np.testing.assert_array_equal(a, b)


def test_tracker_initialises_tracks_loses_and_starts_again():
    rng = np.random.default_rng(4)
    truth = standing(rng, 1.0)
    tracker = SkeletonTracker(SKELETON_PARAMS.create({"lost_frames": 3}), SHAPE, seed=0)
    states = [tracker.update(seen_cloud(truth, SHAPE, rng), t / 30).state for t in range(4)]
    assert states[0] in ("initialising", "tracking") and states[-1] == "tracking"
    estimate = tracker.update(seen_cloud(truth, SHAPE, rng), 4 / 30)
    assert estimate.joints.shape == (len(JOINTS), 3) and estimate.explained > 0.7
    assert joint_errors(estimate.pose, truth).mean() < 0.06
    assert np.all((estimate.confidence > 0) & (estimate.confidence <= 1))
    # The person leaves (no points): a few misses, then lost.
    gone = [tracker.update(np.zeros((0, 3)), (5 + t) / 30).state for t in range(3)]
    assert gone == ["tracking", "tracking", "lost"]
    assert not np.any(tracker.update(np.zeros((0, 3)), 9 / 30).confidence)
    # Back again, elsewhere: initialised from scratch.
    moved = truth.copy()
    moved[0] += 1.5
    back = tracker.update(seen_cloud(moved, SHAPE, rng), 10 / 30)
    assert back.state in ("initialising", "tracking")
    assert np.linalg.norm(back.joints[0] - forward_kinematics(moved, SHAPE)[0][0]) < 0.1


def test_a_cloud_of_the_same_instant_or_older_is_not_a_new_frame():
    rng = np.random.default_rng(6)
    truth = standing(rng, -0.5)
    tracker = SkeletonTracker(SKELETON_PARAMS.create({"particles": 500}), SHAPE, seed=1)
    for t in range(3):
        last = tracker.update(seen_cloud(truth, SHAPE, rng), t / 30)
    particles = tracker.filter.particles.copy()
    # A second sensor's cloud of the same frame, then a late one: the estimate stays.
    moved = truth.copy()
    moved[0] += 0.3
    for stamp in (2 / 30, 1 / 30):
        again = tracker.update(seen_cloud(moved, SHAPE, rng), stamp)
        assert again is last
    np.testing.assert_array_equal(tracker.filter.particles, particles)
    # The next instant is a frame again: the pelvis follows the cloud.
    later = tracker.update(seen_cloud(moved, SHAPE, rng), 3 / 30)
    assert later.stamp == 3 / 30
    assert later.joints[0][0] - last.joints[0][0] > 0.15


def test_a_hidden_wrist_gets_a_lower_confidence():
    rng = np.random.default_rng(6)
    truth = rest_state(SHAPE, 0.0, 0.0, 0.4)
    truth[13], truth[17] = 0.3, 0.3  # arms a little away from the body
    tracker = SkeletonTracker(seed=0, shape=SHAPE)
    for t in range(3):
        estimate = tracker.update(seen_cloud(truth, SHAPE, rng), t / 30)
    assert joint_errors(estimate.pose, truth).max() < 0.1
    wrist = forward_kinematics(truth, SHAPE)[0][JOINTS.index("left_wrist")]
    cloud = seen_cloud(truth, SHAPE, rng)
    estimate = tracker.update(cloud[np.linalg.norm(cloud - wrist, axis=1) > 0.2], 3 / 30)
    confidence = dict(zip(JOINTS, estimate.confidence, strict=True))
    assert confidence["left_wrist"] < 0.5 * confidence["right_wrist"]


def test_shape_estimate_moves_towards_the_persons_own_body():
    rng = np.random.default_rng(7)
    truth_shape = SHAPE.scaled(arms=1.12, limb_radius=1.25)
    poses = [standing(rng, 0.5), standing(rng, 2.0)]
    clouds = [seen_cloud(p, truth_shape, rng) for p in poses]
    params = SKELETON_PARAMS.create()
    estimate, _ = estimate_shape(clouds, poses, SHAPE, params)
    arms = estimate.upper_arm / SHAPE.upper_arm
    radius = estimate.radii[3][0] / SHAPE.radii[3][0]
    assert arms == pytest.approx(1.12, abs=0.03)
    assert abs(radius - 1.25) < abs(1.0 - 1.25) / 2  # more than half way to the thicker limbs
    assert estimate.thigh / SHAPE.thigh == pytest.approx(1.0, abs=0.05)  # the rest as it was
    assert estimate.lower_trunk / SHAPE.lower_trunk == pytest.approx(1.0, abs=0.05)


# Seeds 0-9, not chosen for passing. Every seed must track the body and estimate its
# limbs' radii; the arms' length, which the likelihood barely bounds (a straight arm
# too long pays little; one tracked on the average body pulls it short), is found within
# 4 % in all 10 (2026-11-26, initialisation searching each limb twice: 1.08-1.15 times
# SHAPE's for a true 1.12; 7 of 10 with one search, the misses 1.02-1.06): the test asks
# for 8, and says what each seed found.
def test_tracker_estimates_the_persons_body_from_its_first_frames():
    own = SHAPE.scaled(arms=1.12, limb_radius=1.25)
    # The whole estimate in the update that keeps the last frame (the default spreads it).
    params = SKELETON_PARAMS.create({"shape_seconds": 0.1, "shape_frames": 3, "shape_steps": 1000})
    arms = {}
    for seed in range(10):
        rng = np.random.default_rng(seed)
        truth = standing(rng, 0.8)
        tracker = SkeletonTracker(params, seed=0)
        estimated = []
        for t in range(7):
            estimate = tracker.update(seen_cloud(truth, own, rng), t / 30)
            estimated.append(tracker.shape_estimated)
        assert estimated == [False] * 4 + [True] * 3  # from frames 0, 2 and 4 (0.1 s)
        assert estimate.state == "tracking"
        average = BodyShape.from_height(tracker.shape.height)
        assert tracker.shape.radii[3][0] / average.radii[3][0] > 1.1, seed
        # Half a second on: a start facing backwards (the two headings scored within 0.02
        # for seed 5) is turned round in the first second (turn_around, after 0.25 s).
        for t in range(7, 16):
            estimate = tracker.update(seen_cloud(truth, own, rng), t / 30)
        joints = forward_kinematics(truth, own)[0][: len(JOINTS)]
        assert np.linalg.norm(estimate.joints - joints, axis=1).mean() < 0.05, seed
        arms[seed] = tracker.shape.upper_arm / SHAPE.upper_arm  # the person's own: 1.12
    # Over tracker seeds 0-2 these ten scenes gave 5-10 arms of ten within 4 % and
    # medians 1.11-1.13, whatever the arms' collision margin (0 or 0.3): one run of
    # ten is a sample, so the test asks for half of them and a median within 3 %.
    found = [seed for seed, ratio in arms.items() if abs(ratio - 1.12) <= 0.04 * 1.12]
    assert len(found) >= 5, {seed: round(ratio, 3) for seed, ratio in arms.items()}
    assert abs(np.median(list(arms.values())) - 1.12) <= 0.03 * 1.12  # not the height's 1.0


def test_a_given_body_is_kept_and_no_estimate_runs_when_switched_off():
    rng = np.random.default_rng(9)
    truth = standing(rng, 0.3)
    given = SkeletonTracker(SKELETON_PARAMS.create({"shape_seconds": 0.1}), SHAPE, seed=0)
    off = SkeletonTracker(SKELETON_PARAMS.create({"shape_seconds": 0.0}), seed=0)
    for t in range(6):
        given.update(seen_cloud(truth, SHAPE, rng), t / 30)
        off.update(seen_cloud(truth, SHAPE, rng), t / 30)
    assert given.shape is SHAPE
    assert not off.shape_estimated and off.shape == BodyShape.from_height(off.shape.height)
