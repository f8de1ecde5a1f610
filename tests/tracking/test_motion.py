"""The batched UKF is filterpy's UKF, step for step."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.common import Q_continuous_white_noise
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

from optrack.tracking import TRACKING_PARAMS
from optrack.tracking.motion import ConstantVelocityUKF, position_variance, process_noise


def _filterpy_ukf(x: np.ndarray, P: np.ndarray, params) -> UnscentedKalmanFilter:
    def fx(state: np.ndarray, dt: float) -> np.ndarray:
        return np.array([state[0] + dt * state[2], state[1] + dt * state[3], state[2], state[3]])

    points = MerweScaledSigmaPoints(
        4, alpha=params.ukf_alpha, beta=params.ukf_beta, kappa=params.ukf_kappa
    )
    ukf = UnscentedKalmanFilter(dim_x=4, dim_z=4, dt=1.0, hx=lambda s: s, fx=fx, points=points)
    ukf.x, ukf.P = x.copy(), P.copy()
    return ukf


def test_process_noise_is_filterpys_continuous_white_noise() -> None:
    for dt in (0.01, 1 / 30, 0.5, 2.0):
        expected = Q_continuous_white_noise(2, dt, 3.3, block_size=2, order_by_dim=False)
        np.testing.assert_allclose(process_noise(np.array([dt]), 3.3)[0], expected, rtol=1e-12)


def test_process_noise_composes_over_steps() -> None:
    """Predicting once over 1 s or thirty times over 1/30 s ends with the same covariance."""
    ukf = ConstantVelocityUKF(TRACKING_PARAMS.create())
    x = np.array([[1.0, 2.0, 0.5, -0.3]])
    P = np.diag([0.01, 0.02, 0.3, 0.4])[None]
    x1, P1 = ukf.predict(x, P, np.array([1.0]))
    xs, Ps = x, P
    for _ in range(30):
        xs, Ps = ukf.predict(xs, Ps, np.array([1 / 30]))
    np.testing.assert_allclose(xs, x1, atol=1e-9)
    np.testing.assert_allclose(Ps, P1, rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize("settings", [{}, {"ukf_alpha": 0.3, "ukf_kappa": -1.0}])
def test_predict_and_update_equal_filterpys_ukf_for_a_stack_of_tracks(settings) -> None:
    params = TRACKING_PARAMS.create(settings)
    ours = ConstantVelocityUKF(params)
    rng = np.random.default_rng(3)
    n = 5
    x = rng.normal(0, 1, size=(n, 4))
    A = rng.normal(0, 0.3, size=(n, 4, 4))
    P = A @ np.swapaxes(A, 1, 2) + 0.05 * np.eye(4)
    reference = [_filterpy_ukf(x[i], P[i], params) for i in range(n)]
    for _ in range(6):
        dt = rng.uniform(0.005, 0.2, size=n)
        z = x[:, :4] + rng.normal(0, 0.1, size=(n, 4))
        R = np.stack([np.diag(rng.uniform(0.005, 0.5, size=4)) for _ in range(n)])
        ukf_q = process_noise(dt, ours.spectral_density)
        x_prior, P_prior = ours.predict(x, P, dt)
        zp, S0, Pxz = ours.innovation(x_prior, P_prior)
        x, P = ours.update(x_prior, P_prior, zp, S0 + R, Pxz, z)
        for i, ukf in enumerate(reference):
            ukf.Q = ukf_q[i]
            ukf.predict(dt=dt[i])
            np.testing.assert_allclose(x_prior[i], ukf.x, atol=1e-10)
            np.testing.assert_allclose(P_prior[i], ukf.P, atol=1e-10)
            ukf.update(z[i], R=R[i])
            np.testing.assert_allclose(x[i], ukf.x, atol=1e-9)
            np.testing.assert_allclose(P[i], ukf.P, atol=1e-9)


def test_sigma_points_are_filterpys() -> None:
    params = TRACKING_PARAMS.create({"ukf_alpha": 0.5})
    ours = ConstantVelocityUKF(params)
    x = np.array([0.5, -1.0, 0.2, 0.1])
    P = np.array([[0.2, 0.05, 0, 0], [0.05, 0.3, 0, 0.01], [0, 0, 1.0, 0.2], [0, 0.01, 0.2, 0.5]])
    np.testing.assert_allclose(
        ours.sigma_points(x[None], P[None])[0], ours.points.sigma_points(x, P), atol=1e-12
    )


def test_position_variance_is_voxel_quantisation_plus_distance_squared_depth_error() -> None:
    params = TRACKING_PARAMS.create()
    near, far = position_variance(np.array([0.0, 5.0]), params, 0.06)
    assert near == pytest.approx(30 * 0.06**2 / 12)  # OpenPTrack: weight 30, voxel 6 cm
    assert far == pytest.approx(near + (0.0015 * 25) ** 2)
    coarse, _ = position_variance(np.array([0.0, 5.0]), params, 0.12)
    assert coarse == pytest.approx(4 * near)


def test_the_detectors_voxel_size_reaches_the_tracker() -> None:
    """voxel_size has one home, the detector's schema: each batch carries it, and the
    tracker trusts detections from a coarser voxel grid less."""
    from optrack.detection.params import DETECTION_PARAMS
    from optrack.tracking import Tracker
    from optrack.tracking.motion import DEFAULT_VOXEL_SIZE
    from optrack.types import Detection, DetectionBatch

    assert "voxel_size" not in TRACKING_PARAMS.defaults()
    assert DEFAULT_VOXEL_SIZE == DETECTION_PARAMS.defaults()["voxel_size"]

    def settled_variance(voxel_size: float) -> float:
        tracker = Tracker()
        for k in range(30):
            detection = Detection(x=1.0 + 0.03 * k, y=2.0, z=0.9, height=1.7, confidence=2.0)
            batch = DetectionBatch("s", 0.033 * k, k, detections=[detection], voxel_size=voxel_size)
            tracker.update(batch)
        (track,) = tracker.tracks
        return float(track.P[0, 0])

    fine, unknown, coarse = settled_variance(0.03), settled_variance(0.0), settled_variance(0.2)
    assert fine < unknown < coarse
    assert unknown == pytest.approx(settled_variance(DEFAULT_VOXEL_SIZE))
