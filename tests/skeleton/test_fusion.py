"""One person's cloud from every sensor (optrack/skeleton/fusion.py): on rendered frames of
the mocap scenario, the crop holds that person's pixels and nobody else's, the fused cloud
lies on their true bones; time alignment, decimation and the image rectangle by hand."""

from __future__ import annotations

import numpy as np
import pytest

from optrack.geometry import backproject_points, make_pose, transform_points
from optrack.skeleton.fusion import (
    FUSION_PARAMS,
    decimate,
    nearest_frames,
    person_cloud,
    person_mask,
    person_roi,
)
from optrack.skeleton.joints import PARENT
from optrack.types import Intrinsics


@pytest.fixture(scope="module")
def scene():
    """Two performers (procedural walk and wave) before three Kinect v2, at t = 0.5 s."""
    from optrack.sim import Simulation

    sim = Simulation("mocap", people=2, sensors=3, seconds=1.0, clips=["walk", "wave"], seed=0)
    state = sim.snapshot(0.5)
    return sim, state, sim.truth(state)


def _bone_distance(points: np.ndarray, joints: dict) -> np.ndarray:
    """Each point's distance to the nearest bone (joint to parent) of a truth skeleton."""
    best = np.full(len(points), np.inf)
    for joint, parent in PARENT.items():
        if parent is None:
            continue
        a, b = np.asarray(joints[parent]), np.asarray(joints[joint])
        axis = b - a
        s = np.clip((points - a) @ axis / max(axis @ axis, 1e-12), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(points - (a + s[:, None] * axis), axis=1))
    return best


def test_the_crop_holds_the_persons_pixels_and_not_the_others(scene):
    sim, state, truth = scene
    params = FUSION_PARAMS.create()
    xy = np.array([(p.x, p.y) for p in truth.people])
    for k, sensor in enumerate(sim.sensors):
        frame = sim.frame(k, 15, state, noise=False)
        owner_image = sim.renderer(k, ("depth",)).render(state.geometry).labels
        points, pixels = backproject_points(frame.depth_m(), frame.intrinsics)
        world = transform_points(sensor.world_T_camera, points)
        owner = owner_image[pixels[:, 0], pixels[:, 1]]
        for i, person in enumerate(truth.people):
            mask = person_mask(world, xy[i], person.height, params, np.delete(xy, i, axis=0))
            assert np.all(owner[mask] == i)  # not the floor, the walls or the other person
            own = owner == i
            assert np.count_nonzero(mask & own) >= 0.98 * np.count_nonzero(own)
            alone = person_mask(world, xy[i], person.height, params)  # nobody else about
            assert np.all(alone[mask]) and np.count_nonzero(alone) >= np.count_nonzero(mask)


def test_the_fused_cloud_lies_on_the_persons_bones(scene):
    sim, state, truth = scene
    params = FUSION_PARAMS.create()
    frames = {s.id: sim.frame(k, 15, state) for k, s in enumerate(sim.sensors)}
    poses = {s.id: s.world_T_camera for s in sim.sensors}
    xy = np.array([(p.x, p.y) for p in truth.people])
    rng = np.random.default_rng(0)
    for i, person in enumerate(truth.people):
        others = np.delete(xy, i, axis=0)
        cloud = person_cloud(frames, poses, xy[i], person.height, params, rng, others)
        assert len(cloud) == params.points
        near = _bone_distance(cloud, person.joints)
        assert np.percentile(near, 95) < 0.25  # on the body (the trunk is ~0.15 m round)
        other = truth.people[1 - i]
        assert np.min(_bone_distance(cloud, other.joints)) > 0.3


def test_the_image_rectangle_holds_every_pixel_of_the_person(scene):
    sim, state, truth = scene
    params = FUSION_PARAMS.create()
    shares = []
    for k, sensor in enumerate(sim.sensors):
        labels = sim.renderer(k, ("depth",)).render(state.geometry).labels
        for i, person in enumerate(truth.people):
            rows, cols = np.nonzero(labels == i)
            roi = person_roi(
                sensor.model.intrinsics,
                labels.shape,
                sensor.world_T_camera,
                (person.x, person.y),
                person.height,
                params,
            )
            assert roi is not None
            u0, v0, u1, v1 = roi
            assert u0 <= cols.min() and cols.max() < u1 and v0 <= rows.min() and rows.max() < v1
            shares.append((u1 - u0) * (v1 - v0) / labels.size)
    assert max(shares) < 1.0 and min(shares) < 0.25


def test_the_image_rectangle_behind_and_beside_the_camera():
    k = Intrinsics(fx=100.0, fy=100.0, cx=50.0, cy=40.0, width=100, height=80)
    params = FUSION_PARAMS.create({"radius": 0.5})
    # camera at the origin looking along world +x (z forward = world x)
    pose = make_pose(np.array([[0, 0, 1], [-1, 0, 0], [0, -1, 0]], dtype=float), [0, 0, 1])
    roi = person_roi(k, (80, 100), pose, (5.0, 0.0), 1.0, params)
    assert roi is not None and 0 < roi[0] < 50 < roi[2] < 100
    assert person_roi(k, (80, 100), pose, (0.2, 0.0), 1.0, params) == (0, 0, 100, 80)
    assert person_roi(k, (80, 100), pose, (5.0, 20.0), 1.0, params) is None


def test_nearest_frames_within_half_a_period():
    stamps = {"a": np.array([0.0, 1 / 30, 2 / 30]), "b": np.array([0.01, 0.045])}
    periods = {"a": 1 / 30, "b": 1 / 30}
    assert nearest_frames(stamps, 0.04, periods) == {"a": 1, "b": 1}
    assert nearest_frames(stamps, 0.0, periods) == {"a": 0, "b": 0}
    assert nearest_frames(stamps, 0.075, periods) == {"a": 2}  # b's last is 30 ms away
    assert nearest_frames(stamps, 0.2, periods) == {}


def test_decimate_keeps_voxel_means_then_a_subset():
    rng = np.random.default_rng(0)
    points = np.array(
        [[0.01, 0.01, 0.01], [0.03, 0.03, 0.03], [0.51, 0.51, 0.51], [0.53, 0.53, 0.53]]
    )
    out = decimate(points, 0.1, 10, rng)
    assert sorted(map(tuple, np.round(out, 6))) == [(0.02, 0.02, 0.02), (0.52, 0.52, 0.52)]
    assert len(decimate(points, 0.0, 10, rng)) == 4
    subset = decimate(points, 0.0, 3, rng)
    assert len(subset) == 3 and len({tuple(p) for p in subset}) == 3
    assert decimate(np.empty((0, 3)), 0.02, 10, rng).shape == (0, 3)
