"""Association pieces: measurement (eq. 5-6), gate, cost, assignment, reach."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from optrack.tracking import TRACKING_PARAMS, Tracker
from optrack.tracking.association import (
    UNMEASURED_VARIANCE,
    Candidates,
    assign,
    associate,
    association_cost,
    chi_square_gate,
    gate_value,
    likelihood_cost,
    mahalanobis,
    measurement_noise,
    measurements,
    within_reach,
)
from optrack.tracking.lifecycle import weak_revival
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


def _candidates(positions, predicted, confidence, d2, tracks=(), **settings) -> Candidates:
    positions = np.asarray(positions, dtype=float)
    predicted = np.asarray(predicted, dtype=float)
    n, m = len(predicted), len(positions)
    d2 = np.asarray(d2, dtype=float)
    return Candidates(
        t=1.0,
        tracks=tracks,
        detections=[_detection(x, y, c) for (x, y), c in zip(positions, confidence, strict=True)],
        positions=positions,
        confidence=np.asarray(confidence, dtype=float),
        predicted=np.hstack([predicted, np.zeros((n, 2))]),
        d2=d2,
        logdet=np.zeros((n, m)),
        last_seen=predicted,
        unseen=np.zeros(n),
        chi_square=gate_value(0.99),
        settings=TRACKING_PARAMS.create(settings),
    )


def test_the_default_cost_and_gate_are_the_likelihood_and_the_chi_square_gate_with_reach() -> None:
    c = _candidates(
        [[0.0, 0.0], [0.6, 0.0], [3.0, 0.0]],
        [[0.0, 0.0], [1.0, 0.0]],
        [1.0, -1.0, 0.5],
        [[0.5, 12.0, 20.0], [14.0, 3.0, 1.0]],
    )
    np.testing.assert_array_equal(
        likelihood_cost(c), association_cost(c.d2, c.logdet, c.confidence, 0.25, -0.25)
    )
    # d2 within 13.28 and within min_reach (0.5 m) of where the track was last seen (just
    # now): (0, 1) passes the d2 bound but not the reach, (1, 2) the other way round
    assert chi_square_gate(c).tolist() == [[True, False, False], [False, True, False]]
    tracker = Tracker()
    assert (tracker.cost, tracker.gate_rule) == (likelihood_cost, chi_square_gate)


def test_association_returns_the_pairs_of_least_custom_cost() -> None:
    c = _candidates([[0.0, 0.0], [1.0, 0.0]], [[0.1, 0.0], [0.9, 0.0]], [1.0, 1.0], np.ones((2, 2)))
    allowed = np.ones((2, 2), dtype=bool)
    assert sorted(associate(c, lambda c: c.distance(), allowed)) == [(0, 0), (1, 1)]
    assert sorted(associate(c, lambda c: -c.distance(), allowed)) == [(0, 1), (1, 0)]
    with pytest.raises(ValueError, match="shape"):
        associate(c, lambda c: np.zeros((2, 3)), allowed)


def _still(tracker: Tracker, frames: int = 30) -> None:
    for k in range(frames):
        tracker.update(DetectionBatch("a", k / 30, detections=[_detection(0.0, 0.0)]))


def test_a_custom_cost_changes_which_detection_a_track_takes() -> None:
    """Someone stands still; two detections come, the nearer a little less confident. The
    likelihood cost gives the track the nearer one (the other starts a track); a cost that
    only asks for confidence, the other."""
    batch = DetectionBatch(
        "a", 1.0, detections=[_detection(0.0, 0.0, 1.0), _detection(0.1, 0.0, 1.2)]
    )
    started_at = {}
    for name, cost in (
        ("default", None),
        ("most confident", lambda c: -np.broadcast_to(c.confidence, c.d2.shape)),
    ):
        tracker = Tracker() if cost is None else Tracker(cost=cost)
        _still(tracker)
        tracker.update(batch)
        (_, new) = tracker.tracks
        started_at[name] = float(new.x[0])
    assert started_at == {"default": 0.1, "most confident": 0.0}


def test_a_custom_gate_lets_a_track_take_a_detection_the_chi_square_gate_refuses() -> None:
    """norfair's way: a Euclidean distance threshold instead of the Mahalanobis gate. A
    person standing still shows up 0.45 m away in one frame: outside the chi-square gate of
    a track that predicts them sharply (a second track starts), inside a 1 m threshold."""
    jump = DetectionBatch("a", 1.0, detections=[_detection(0.45, 0.0)])
    default, euclidean = Tracker(), Tracker(gate=lambda c: c.distance() <= 1.0)
    for tracker in (default, euclidean):
        _still(tracker)
        tracker.update(jump)
    assert default.next_id == 3 and default.tracks[0].last_detection < 1.0
    assert euclidean.next_id == 2 and euclidean.tracks[0].last_detection == 1.0
