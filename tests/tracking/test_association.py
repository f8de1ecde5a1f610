"""Association pieces: measurement (eq. 5-6), gate, cost, assignment, reach."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from optrack.tracking import TRACKING_PARAMS, Tracker
from optrack.tracking.association import (
    UNMEASURED_VARIANCE,
    assign,
    association_cost,
    gate_value,
    mahalanobis,
    measurement_noise,
    measurements,
    weak_revival,
    within_reach,
)
from optrack.types import Detection, DetectionBatch


def test_gate_is_the_chi_square_quantile_of_the_probability_with_4_dof() -> None:
    assert gate_value(0.99) == chi2.ppf(0.99, 4)
    assert gate_value(0.99) == pytest.approx(13.2767, abs=1e-4)
    tracker = Tracker(TRACKING_PARAMS.create({"gate_probability": 0.95}))
    assert tracker.gate == chi2.ppf(0.95, 4)


def test_gate_follows_a_live_parameter_change() -> None:
    tracker = Tracker()
    tracker.params.gate_probability = 0.999
    tracker.update(DetectionBatch(sensor_id="a", stamp=0.0))
    assert tracker.gate == chi2.ppf(0.999, 4)


def test_velocity_is_the_one_the_track_would_have_if_it_took_the_detection() -> None:
    positions = np.array([[2.0, 1.0], [0.0, 0.0]])
    reference = np.array([[1.0, 1.0]])  # where the track was 0.5 s before
    zp = np.array([[1.4, 1.0, 0.8, 0.0]])
    z = measurements(positions, reference, np.array([0.5]), zp)
    np.testing.assert_allclose(z[0, 0], [2.0, 1.0, 2.0, 0.0])
    np.testing.assert_allclose(z[0, 1], [0.0, 0.0, -2.0, -2.0])


def test_a_velocity_that_cannot_be_measured_adds_nothing_to_d2() -> None:
    positions = np.array([[1.3, 1.0]])
    zp = np.array([[1.0, 1.0, 0.7, 0.2]])
    z = measurements(positions, np.zeros((1, 2)), np.array([np.nan]), zp)
    np.testing.assert_allclose(z[0, 0, 2:], zp[0, 2:])
    R = measurement_noise(np.array([0.01]), np.array([np.nan]))
    assert R[0, 0, 2, 2] == UNMEASURED_VARIANCE
    S = np.diag([0.02, 0.02, 1.0, 1.0])[None, None] + R
    d2, _ = mahalanobis(z - zp[:, None], S)
    assert d2[0, 0] == pytest.approx(0.3**2 / (0.02 + 0.01))


def test_velocity_noise_is_two_positions_over_the_baseline() -> None:
    R = measurement_noise(np.array([0.01, 0.04]), np.array([0.2]))
    np.testing.assert_allclose(np.diag(R[0, 1]), [0.04, 0.04, 2.0, 2.0])


def test_d2_is_the_squared_mahalanobis_distance() -> None:
    S = np.diag([0.04, 0.01, 1.0, 4.0])[None]
    z_tilde = np.array([[0.2, 0.1, 1.0, 2.0]])
    d2, logdet = mahalanobis(z_tilde, S)
    assert d2[0] == pytest.approx(1 + 1 + 1 + 1)
    assert logdet[0] == pytest.approx(np.log(0.04 * 0.01 * 1.0 * 4.0))


def test_a_confident_detection_costs_less() -> None:
    d2 = np.array([[2.0, 2.0]])
    cost = association_cost(d2, np.zeros_like(d2), np.array([2.0, -1.0]), 0.25, -0.25)
    assert cost[0, 0] < cost[0, 1]


def test_assignment_takes_the_cheapest_allowed_pairs_and_never_a_forbidden_one() -> None:
    cost = np.array([[1.0, 0.1, 5.0], [0.2, 3.0, 9.0]])
    allowed = np.array([[True, True, False], [True, True, False]])
    assert sorted(assign(cost, allowed)) == [(0, 1), (1, 0)]
    allowed = np.array([[False, False, False], [False, False, True]])
    assert assign(cost, allowed) == [(1, 2)]
    assert assign(cost, np.zeros_like(allowed)) == []


def test_assignment_prefers_matching_more_pairs_over_a_cheaper_single_pair() -> None:
    # As OpenPTrack's 1e6 entries: a track is never left out to save cost.
    cost = np.array([[0.0, 1.0], [0.5, 100.0]])
    allowed = np.array([[True, True], [True, False]])
    assert sorted(assign(cost, allowed)) == [(0, 1), (1, 0)]


def test_reach_grows_with_the_time_a_track_was_unseen() -> None:
    positions = np.array([[3.0, 0.0]])
    last_seen = np.zeros((2, 2))
    inside = within_reach(positions, last_seen, np.array([0.1, 1.5]), 2.0, 0.5)
    assert inside.tolist() == [[False], [True]]


def _detection(x: float, y: float, confidence: float = 1.0) -> Detection:
    return Detection(x=x, y=y, z=0.9, height=1.7, confidence=confidence)


def test_a_detection_inside_the_chi_square_gate_but_outside_openptracks_is_associated() -> None:
    """OpenPTrack's gate of ~1 (the probability passed as the distance) would start a
    second track here; the chi-square gate keeps one."""
    tracker = Tracker()
    for k in range(10):
        tracker.update(DetectionBatch("a", k / 30, detections=[_detection(0.0, 0.0)]))
    track = tracker.tracks[0]
    sigma = np.sqrt(track.P[0, 0] + 30 * 0.06**2 / 12)
    step = 2.0 * sigma  # d2 of about 4 on x alone: over 1, under 13.28
    tracker.update(DetectionBatch("a", 10 / 30, detections=[_detection(step, 0.0)]))
    assert len(tracker.tracks) == 1
    assert tracker.tracks[0].detections == 11


def test_a_lost_track_with_a_wide_covariance_does_not_take_a_sharply_predicted_detection() -> None:
    tracker = Tracker(TRACKING_PARAMS.create({"appearance": "off"}))
    for k in range(60):  # two people, one stops being seen at 0.5 s
        people = [_detection(0.0, 0.0)] + ([_detection(1.0, 0.0)] if k < 15 else [])
        tracker.update(DetectionBatch("a", k / 30, detections=people))
    still, lost = sorted(tracker.tracks, key=lambda tr: tr.x[0])
    # the still person shows up a little towards where the lost one was; the lost
    # track's d2 is smaller (its S is wide), its likelihood is not
    tracker.update(DetectionBatch("a", 2.0, detections=[_detection(0.15, 0.0)]))
    assert still.last_detection == 2.0
    assert lost.last_detection < 0.5


def test_weak_revival_needs_a_flag_a_recent_loss_and_the_predicted_place() -> None:
    positions = np.array([[0.0, 0.0], [0.0, 0.3], [2.0, 0.0]])
    hidden = np.array([True, False, True])
    predicted = np.array([[0.0, 0.1], [2.0, 0.2]])
    unseen = np.array([0.3, 0.9])
    got = weak_revival(positions, hidden, predicted, unseen, window=0.5, radius=0.5)
    # track 0 (lost 0.3 s): the flagged detection beside it; the unflagged one does not count
    # track 1 (lost 0.9 s): too long ago, even for the flagged detection on its prediction
    assert got.tolist() == [[True, False, False], [False, False, False]]
    assert not weak_revival(positions, hidden, predicted, unseen, 0.0, 0.5).any()
    assert weak_revival(positions, hidden, predicted, unseen, 1.0, 0.5).tolist()[1] == [
        False,
        False,
        True,
    ]
