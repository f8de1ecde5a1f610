from __future__ import annotations

import numpy as np
import pytest

from optrack.calibration.quality import calibration_errors
from optrack.calibration.refinement import (
    REFINEMENT_PARAMS,
    RefinementError,
    Trajectory,
    alignment_error,
    refine_from_trajectories,
)
from optrack.calibration.synthetic import perturb_poses, synthetic_walk
from optrack.geometry import transform_points


def _trajectories(network, perturbed, seed, **walk):
    truth, intrinsics = network
    walk.setdefault("noise_m", 0.012)  # about the simulated detector's (1.3-1.5 cm off the truth)
    _, _, detections = synthetic_walk(truth, intrinsics, seconds=45, seed=seed, **walk)
    return {
        sid: Trajectory(t, transform_points(perturbed[sid], xyz))
        for sid, (t, xyz) in detections.items()
    }


@pytest.mark.parametrize("seed", [0, 1])
def test_a_10_cm_2_degree_perturbation_is_undone_from_one_walking_person(network, seed):
    truth, _ = network
    perturbed = perturb_poses(truth, 0.10, 2.0, seed=seed)
    trajectories = _trajectories(network, perturbed, seed)
    result = refine_from_trajectories(trajectories)
    assert result.skipped == []
    assert result.error_before_m > 0.1
    assert result.error_after_m <= 0.03
    assert result.error_before_m / result.error_after_m >= 4
    refined = {sid: result.corrections[sid] @ perturbed[sid] for sid in result.corrections}
    before = calibration_errors(perturbed, truth)
    after = calibration_errors(refined, truth)
    assert after.max_position_error_m < 0.01 < before.max_position_error_m
    assert after.max_rotation_error_deg < 0.15 < before.max_rotation_error_deg


def test_heading_only_corrections_leave_every_camera_tilt_alone(network):
    truth, _ = network
    perturbed = perturb_poses(truth, 0.10, 2.0, seed=3)
    params = REFINEMENT_PARAMS.create({"dof": "heading"})
    result = refine_from_trajectories(_trajectories(network, perturbed, 3), params)
    assert result.error_after_m <= 0.03
    for correction in result.corrections.values():
        np.testing.assert_allclose(correction[2, :3], [0.0, 0.0, 1.0], atol=1e-12)


def test_a_calibration_that_is_already_right_stays_right(network):
    truth, _ = network
    trajectories = _trajectories(network, truth, 4)
    result = refine_from_trajectories(trajectories)
    refined = {sid: result.corrections[sid] @ truth[sid] for sid in result.corrections}
    errors = calibration_errors(refined, truth)
    assert errors.max_position_error_m < 0.01 and errors.max_rotation_error_deg < 0.15
    assert result.error_after_m <= result.error_before_m + 0.002


def test_corrections_keep_the_network_where_it_was_on_the_floor_plan(network):
    truth, _ = network
    perturbed = perturb_poses(truth, 0.10, 2.0, seed=5)
    result = refine_from_trajectories(_trajectories(network, perturbed, 5))
    moved = np.mean([c[:2, 3] for c in result.corrections.values()], axis=0)
    assert np.linalg.norm(moved) < 0.05


def test_one_sensor_alone_cannot_be_refined(network):
    truth, _ = network
    trajectories = _trajectories(network, truth, 6)
    only = dict(list(trajectories.items())[:1])
    with pytest.raises(RefinementError, match="at least two sensors"):
        refine_from_trajectories(only)


def test_sensors_with_too_few_detections_are_left_alone_and_listed(network):
    truth, _ = network
    trajectories = _trajectories(network, truth, 7)
    short = sorted(trajectories)[0]
    trajectories[short] = Trajectory(trajectories[short].t[:5], trajectories[short].xyz[:5])
    result = refine_from_trajectories(trajectories, REFINEMENT_PARAMS.create())
    assert result.skipped == [short] and short not in result.corrections


def test_alignment_error_is_the_mean_distance_between_sensors_at_the_same_time():
    t = np.arange(0.0, 4.0, 0.1)
    path = np.column_stack([t, np.zeros_like(t), np.ones_like(t)])  # walking at 1 m/s
    same = {"a": Trajectory(t, path), "b": Trajectory(t, path)}
    assert alignment_error(same) == pytest.approx(0.0)
    # Another sensor's frames fall between: interpolated, the same person at the same time.
    later = t[:-1] + 0.037
    between = {"a": Trajectory(t, path), "b": Trajectory(later, path[:-1] + [0.037, 0.0, 0.0])}
    assert alignment_error(between) == pytest.approx(0.0, abs=1e-9)
    shifted = {"a": Trajectory(t, path), "b": Trajectory(t, path + [0.0, 0.05, 0.02])}
    assert alignment_error(shifted) == pytest.approx(0.05)
    assert alignment_error(shifted, planar=False) == pytest.approx(np.hypot(0.05, 0.02))


def test_the_walkers_trajectory_leaves_out_detections_below_the_confidence_floor():
    """A body partly hidden or cut off by the image's border (its centroid off its axis)
    and false detections come with low confidence: below calibration_refinement's
    min_confidence they are not part of the live walk's trajectory, nor of its count."""
    from optrack.calibration.refinement import usable_detections, walker_trajectory
    from optrack.types import Detection

    floor = REFINEMENT_PARAMS.defaults()["min_confidence"]

    def seen(x, confidence):
        return Detection(x, 0.0, 0.8, 1.7, confidence, camera_xyz=(x, 0.0, 0.8))

    frames = [
        (0.0, [seen(0.0, 1.2)]),
        (0.1, [seen(3.0, floor - 0.5)]),  # a false detection, 3 m off
        (0.2, [seen(0.2, floor + 0.1), seen(2.0, floor - 1.0)]),
        (0.3, [Detection(0.0, 0.0, 0.8, 1.7, 2.0)]),  # no camera-frame centroid
    ]
    trajectory, crowded = walker_trajectory(frames, np.eye(4), min_confidence=None)
    assert trajectory.t.tolist() == [0.0, 0.2]
    assert np.allclose(trajectory.xyz[:, 0], [0.0, 0.2]) and crowded == 0
    assert [len(usable_detections(d)) for _, d in frames] == [1, 0, 1, 0]
    # A recording's refinement (optrack calibrate refine) keeps every detection.
    everything, crowded = walker_trajectory(frames, np.eye(4))
    assert everything.t.tolist() == [0.0, 0.1, 0.2] and crowded == 1
