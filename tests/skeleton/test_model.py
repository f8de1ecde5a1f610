"""The body model: forward kinematics against hand-computed poses, shapes, limits."""

from __future__ import annotations

import numpy as np
import pytest

from optrack.skeleton.joints import JOINTS, PARENT
from optrack.skeleton.likelihood import signed_distance
from optrack.skeleton.model import (
    DOFS,
    LIMITS,
    PARTITIONS,
    POINTS,
    BodyShape,
    D,
    forward_kinematics,
    part_geometry,
    rest_state,
    surface_points,
)

H = 1.0  # a person 1 m tall: lengths are Winter's fractions themselves
SHAPE = BodyShape.from_height(H)
J = {name: i for i, name in enumerate(POINTS)}


def joints_at(**angles: float) -> np.ndarray:
    state = rest_state(SHAPE)
    for name, value in angles.items():
        state[DOFS.index(name)] = value
    return forward_kinematics(state, SHAPE)[0]


def test_state_has_root_and_22_joint_angles():
    assert D == 28
    assert DOFS[:6] == ("root_x", "root_y", "root_z", "root_yaw", "root_pitch", "root_roll")
    assert sum(len(dims) for dims in PARTITIONS.values()) == D
    assert [len(PARTITIONS[n]) for n in ("left_arm", "right_arm", "left_leg", "right_leg")] == [
        4, 4, 4, 4,
    ]  # fmt: skip
    assert len(PARTITIONS["torso"]) - 6 == 6  # R6 after the root's 6
    assert LIMITS.shape == (D, 2) and np.all(LIMITS[:, 0] < LIMITS[:, 1])
    assert POINTS[: len(JOINTS)] == JOINTS and set(PARENT) == set(JOINTS)


def test_rest_pose_matches_winters_fractions():
    p = joints_at()
    np.testing.assert_allclose(p[J["pelvis"]], [0, 0, 0.530], atol=1e-9)
    np.testing.assert_allclose(p[J["neck"]], [0, 0, 0.818], atol=1e-9)
    np.testing.assert_allclose(p[J["spine"]], [0, 0, (0.530 + 0.818) / 2], atol=1e-9)
    np.testing.assert_allclose(p[J["head"]], [0, 0, 0.935], atol=1e-9)
    np.testing.assert_allclose(p[J["left_shoulder"]], [0, 0.1036, 0.818], atol=1e-9)
    np.testing.assert_allclose(p[J["right_wrist"]], [0, -0.1036, 0.818 - 0.186 - 0.146], atol=1e-9)
    np.testing.assert_allclose(p[J["left_knee"]], [0, 0.0525250, 0.285], atol=1e-7)
    np.testing.assert_allclose(p[J["right_ankle"]], [0, -0.0525250, 0.039], atol=1e-7)


def test_heading_turns_the_whole_body_about_z():
    state = rest_state(SHAPE, x=2.0, y=-1.0, yaw=np.pi / 2)  # facing +y: left is -x
    p = forward_kinematics(state, SHAPE)[0]
    np.testing.assert_allclose(p[J["left_shoulder"]], [2.0 - 0.1036, -1.0, 0.818], atol=1e-7)
    np.testing.assert_allclose(p[J["left_toe"]], [2.0 - 0.052525, -1.0 + 0.11, 0.019], atol=1e-6)


def test_shoulder_flexion_raises_the_arm_forward_and_the_elbow_bends_it_forward():
    p = joints_at(left_shoulder_flex=np.pi / 2)
    shoulder = p[J["left_shoulder"]]
    np.testing.assert_allclose(p[J["left_elbow"]], shoulder + [0.186, 0, 0], atol=1e-6)
    np.testing.assert_allclose(p[J["left_wrist"]], shoulder + [0.332, 0, 0], atol=1e-6)
    p = joints_at(right_elbow_flex=np.pi / 2)
    np.testing.assert_allclose(p[J["right_wrist"]], p[J["right_elbow"]] + [0.146, 0, 0], atol=1e-6)


def test_abduction_raises_either_arm_outwards():
    p = joints_at(left_shoulder_abduction=np.pi / 2, right_shoulder_abduction=np.pi / 2)
    np.testing.assert_allclose(p[J["left_elbow"]] - p[J["left_shoulder"]], [0, 0.186, 0], atol=1e-6)
    np.testing.assert_allclose(
        p[J["right_elbow"]] - p[J["right_shoulder"]], [0, -0.186, 0], atol=1e-6
    )


def test_knee_bends_backwards_and_the_hip_forwards():
    p = joints_at(left_knee_flex=np.pi / 2)
    np.testing.assert_allclose(p[J["left_ankle"]], p[J["left_knee"]] + [-0.246, 0, 0], atol=1e-6)
    p = joints_at(right_hip_flex=np.pi / 2)
    np.testing.assert_allclose(p[J["right_knee"]], p[J["right_hip"]] + [0.245, 0, 0], atol=1e-6)


def test_spine_flexion_bends_the_chest_forward_and_carries_the_arms():
    p = joints_at(spine_flex=np.pi / 2)
    spine = p[J["spine"]]
    np.testing.assert_allclose(p[J["neck"]], spine + [0.144, 0, 0], atol=1e-6)
    np.testing.assert_allclose(p[J["left_shoulder"]], spine + [0.144, 0.1036, 0], atol=1e-6)
    # The arm still hangs along the chest's own "down", now backwards.
    np.testing.assert_allclose(
        p[J["left_elbow"]], p[J["left_shoulder"]] + [-0.186, 0, 0], atol=1e-6
    )


def test_turning_the_head_does_not_move_the_shoulders():
    p0, p1 = joints_at(), joints_at(neck_twist=1.0, neck_flex=0.5)
    np.testing.assert_allclose(p1[J["left_shoulder"]], p0[J["left_shoulder"]], atol=1e-9)
    assert np.linalg.norm(p1[J["head"]] - p0[J["head"]]) > 0.05


def test_many_states_at_once_and_a_limb_alone_match_one_by_one():
    rng = np.random.default_rng(3)
    states = rest_state(SHAPE) + rng.normal(0.0, 0.4, (50, D))
    points, frames = forward_kinematics(states, SHAPE)
    for i in (0, 17, 49):
        one_points, one_frames = forward_kinematics(states[i], SHAPE)
        np.testing.assert_allclose(points[i], one_points, atol=1e-6)
        np.testing.assert_allclose(frames[i], one_frames, atol=1e-6)
    base = forward_kinematics(states[0], SHAPE)
    limb = states[:1].repeat(50, axis=0)
    limb[:, 16:20] = states[:, 16:20]
    partial, _ = forward_kinematics(limb, SHAPE, ("right_shoulder", "right_elbow"), base)
    np.testing.assert_allclose(partial, forward_kinematics(limb, SHAPE)[0], atol=1e-6)


def test_from_height_scales_and_scaled_changes_only_its_proportions():
    tall = BodyShape.from_height(2.0)
    assert tall.upper_arm == pytest.approx(2 * SHAPE.upper_arm)
    assert tall.standing_pelvis_height == pytest.approx(2 * 0.530)
    long_arms = SHAPE.scaled(arms=1.1, limb_radius=1.2)
    assert long_arms.forearm == pytest.approx(1.1 * SHAPE.forearm)
    assert long_arms.thigh == SHAPE.thigh
    assert long_arms.radii[3][0] == pytest.approx(1.2 * SHAPE.radii[3][0])
    assert long_arms.radii[0] == SHAPE.radii[0]  # the trunk keeps its radius


def test_surface_points_lie_on_the_parts_and_normals_point_out():
    state = rest_state(SHAPE)
    state[12], state[15], state[23] = 0.6, 1.1, 0.7
    rng = np.random.default_rng(0)
    points, normals = surface_points(state, SHAPE, 2000, rng)
    pts, rot = forward_kinematics(state, SHAPE)
    geometry = part_geometry(pts[None], rot[None], SHAPE)
    d, _ = signed_distance(points, geometry)
    assert np.abs(d[0]).min(axis=1).max() < 1e-5
    d_out, _ = signed_distance(points + 0.005 * normals, geometry)
    d_in, _ = signed_distance(points - 0.005 * normals, geometry)
    own = np.argmin(np.abs(d[0]), axis=1)
    rows = np.arange(len(points))
    assert np.all(d_out[0, rows, own] > 0) and np.all(d_in[0, rows, own] < 0)
    assert points[:, 2].max() == pytest.approx(H, abs=0.01)  # the top of the head
