"""The simulator's joint truth and the tracker's model name the same points: with the
person's own bone lengths, the model's forward kinematics reaches the truth of real CMU
motion (retargeted onto a varied simulated body) to millimetres, so the markers'
errors that `optrack eval --skeleton` reports hold no offset of convention."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.optimize import least_squares

from optrack.sim.articulated import ArticulatedPose, matrices
from optrack.sim.articulated import forward_kinematics as sim_kinematics
from optrack.sim.body import BodyShape as SimShape
from optrack.sim.mocap import load_motion
from optrack.skeleton.joints import JOINTS
from optrack.skeleton.model import LIMITS, BodyShape, forward_kinematics, rest_state

J = {name: i for i, name in enumerate(JOINTS)}
BONES = {
    "lower_trunk": ("pelvis", "spine"),
    "upper_trunk": ("spine", "neck"),
    "head": ("neck", "head"),
    "shoulder_half_width": ("neck", "left_shoulder"),
    "hip_half_width": ("pelvis", "left_hip"),
    "upper_arm": ("left_shoulder", "left_elbow"),
    "forearm": ("left_elbow", "left_wrist"),
    "thigh": ("left_hip", "left_knee"),
    "shin": ("left_knee", "left_ankle"),
}


def _truth(clip: str, taus: np.ndarray) -> tuple[np.ndarray, float]:
    """The simulator's joints (F, len(JOINTS), 3) of a varied body playing ``clip``."""
    motion = load_motion(clip)
    shape = SimShape.varied(1.72, np.random.default_rng(4), 0.05, 0.12)
    local, hips = motion.sample(taus)
    pose = ArticulatedPose(hips * shape.leg_length / motion.leg_length, matrices(local))
    offsets = np.broadcast_to(shape.offsets, (len(taus), *shape.offsets.shape))
    return sim_kinematics(offsets, pose)[0][:, : len(JOINTS)], shape.height


def _fit(truth: np.ndarray, shape: BodyShape, start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The model pose nearest one frame's truth joints: (pose, each joint's residual)."""
    low = np.where(np.isinf(LIMITS[:, 0]), -1e6, LIMITS[:, 0])
    high = np.where(np.isinf(LIMITS[:, 1]), 1e6, LIMITS[:, 1])

    def residual(state: np.ndarray) -> np.ndarray:
        return (forward_kinematics(state, shape)[0][: len(JOINTS)] - truth).ravel()

    best = None
    for yaw in np.linspace(-np.pi, np.pi, 6, endpoint=False):
        guess = start.copy()
        guess[3] += yaw
        fit = least_squares(residual, np.clip(guess, low, high), bounds=(low, high), diff_step=1e-3)
        if best is None or fit.cost < best.cost:
            best = fit
    return best.x, np.linalg.norm(best.fun.reshape(-1, 3), axis=1)


@pytest.mark.parametrize(
    "clip", ["cmu_16_27_walk_turn_left.bvh", "cmu_13_30_jumping_jacks_excerpt.bvh"]
)
def test_the_model_reaches_the_simulators_joint_truth(shared_data, clip):
    taus = np.array([0.2, 0.5, 0.8])
    truth, height = _truth(str(shared_data / "mocap" / clip), taus)
    lengths = {
        name: float(np.linalg.norm(truth[0, J[b]] - truth[0, J[a]]))
        for name, (a, b) in BONES.items()
    }
    shape = dataclasses.replace(BodyShape.from_height(height), **lengths)
    for frame in truth:
        start = rest_state(shape, *frame[J["pelvis"], :2])
        start[2] = frame[J["pelvis"], 2]
        _, error = _fit(frame, shape, start)
        assert error.mean() < 0.01, dict(zip(JOINTS, error.round(3), strict=True))
        assert error.max() < 0.03, dict(zip(JOINTS, error.round(3), strict=True))
