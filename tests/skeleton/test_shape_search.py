"""The body's estimate in steps (ShapeSearch): the same body as all at once, two
partitions of one frame's refit per step, and the tracker spreading it over its updates."""

from __future__ import annotations

import numpy as np

from optrack.skeleton.model import PARTITIONS
from optrack.skeleton.params import SKELETON_PARAMS
from optrack.skeleton.shape import _PER_STEP, _STEPS, PROPORTIONS, ShapeSearch, estimate_shape
from optrack.skeleton.tracker import SkeletonTracker
from tests.skeleton.clouds import seen_cloud
from tests.skeleton.test_tracker import SHAPE, standing


def test_search_in_steps_finds_the_body_estimate_shape_finds():
    rng = np.random.default_rng(11)
    own = SHAPE.scaled(arms=1.1)
    poses = [standing(rng, 0.5), standing(rng, 1.5)]
    clouds = [seen_cloud(p, own, rng) for p in poses]
    params = SKELETON_PARAMS.create({"particles": 300})
    whole, refit = estimate_shape(clouds, poses, SHAPE, params, seed=3)
    search = ShapeSearch(clouds, poses, SHAPE, params, seed=3)
    steps = 0
    while not search.advance():
        steps += 1
    # Every factor of each pass (the current one scored again: a refit of the four limbs),
    # then each pass's refit of the whole pose to the body found; _PER_STEP partitions of
    # one frame's refit per step.
    limbs, whole_pose = -(-4 // _PER_STEP), -(-len(PARTITIONS) // _PER_STEP)
    refits = len(PROPORTIONS) * sum(len(s) for s in _STEPS) * limbs + len(_STEPS) * whole_pose
    assert steps == refits * len(clouds)
    assert search.shape == whole
    assert all(np.array_equal(a, b) for a, b in zip(search.poses, refit, strict=True))


def test_tracker_spreads_the_estimate_over_its_updates():
    rng = np.random.default_rng(12)
    truth = standing(rng, 0.4)
    params = SKELETON_PARAMS.create(
        {"shape_seconds": 0.1, "shape_frames": 2, "shape_steps": 30, "particles": 300}
    )
    tracker = SkeletonTracker(params, seed=0)
    done = []
    for t in range(12):
        tracker.update(seen_cloud(truth, SHAPE, rng), t / 30)
        done.append(tracker.shape_estimated)
    # Frames 0 and 3 kept (0.1 s apart); (48 candidates x 2 steps + 2 whole refits x 3
    # steps) x 2 frames = 204 steps, 30 per update from frame 3 on: done in the update of
    # frame 9.
    assert done == [False] * 9 + [True] * 3
