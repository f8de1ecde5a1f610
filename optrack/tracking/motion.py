"""Motion model: an Unscented Kalman Filter on the ground-plane state [x, y, vx, vy].

Constant velocity (Munaro 2012 section 5.1; OpenPTrack section 6). The
sigma points and their weights are filterpy's ``MerweScaledSigmaPoints``;
``predict`` and ``update`` are filterpy's ``UnscentedKalmanFilter`` steps
written over a stack of tracks at once, so that one detection batch costs a
handful of array operations however many people are tracked
(tests/tracking/test_motion.py checks every step against filterpy's own
filter). Names follow filterpy: ``x``, ``P``, ``Q``, ``R``, ``S``, ``K``.

The measurement is ``z = [x, y, vx, vy]``: a detection's position and the
velocity the track would have if it took the detection (paper eq. 5-6).
"""

from __future__ import annotations

import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints

from optrack.detection.params import DETECTION_PARAMS
from optrack.params import Params

__all__ = ["DIM_X", "DIM_Z", "ConstantVelocityUKF", "position_variance", "process_noise"]

DIM_X = 4  # [x, y, vx, vy]
DIM_Z = 4  # [x, y, vx, vy]

# The detector's voxel size, for detections that do not carry theirs (older recordings).
DEFAULT_VOXEL_SIZE = float(DETECTION_PARAMS["voxel_size"].default)


def process_noise(dt: np.ndarray, spectral_density: float) -> np.ndarray:
    """Q of continuous white-noise acceleration over ``|dt|`` for [x, y, vx, vy], (N, 4, 4).

    filterpy's ``Q_continuous_white_noise(2, dt, q, block_size=2, order_by_dim=False)``
    for every dt at once; continuous noise composes exactly over steps, so a track
    predicted in one long step or many short ones ends with the same P.
    """
    dt = np.abs(np.asarray(dt, dtype=np.float64))
    q = spectral_density
    Q = np.zeros((dt.size, DIM_X, DIM_X))
    for axis in (0, 1):
        p, v = axis, axis + 2
        Q[:, p, p] = q * dt**3 / 3.0
        Q[:, p, v] = Q[:, v, p] = q * dt**2 / 2.0
        Q[:, v, v] = q * dt
    return Q


def position_variance(distance: np.ndarray, params: Params, voxel_size: float) -> np.ndarray:
    """Variance (m^2) of a detection's ground position, per axis, at ``distance`` from its sensor.

    Voxel quantisation (uniform over a voxel: voxel_size^2 / 12, weighted as
    OpenPTrack's position_variance_weight) plus the sensor's depth error
    (standard deviation k * distance^2, Khoshelham and Elberink 2012).
    """
    quantisation = params.position_variance_weight * voxel_size**2 / 12.0
    depth_std = params.depth_error_coefficient * np.asarray(distance, dtype=np.float64) ** 2
    return quantisation + depth_std**2


class ConstantVelocityUKF:
    """The UKF steps for a stack of N tracks (states ``x`` (N, 4), covariances ``P`` (N, 4, 4))."""

    def __init__(self, params: Params) -> None:
        self.points = MerweScaledSigmaPoints(
            DIM_X, alpha=params.ukf_alpha, beta=params.ukf_beta, kappa=params.ukf_kappa
        )
        self.Wm = np.asarray(self.points.Wm, dtype=np.float64)
        self.Wc = np.asarray(self.points.Wc, dtype=np.float64)
        n = DIM_X
        lambda_ = self.points.alpha**2 * (n + self.points.kappa) - n
        self._scale = lambda_ + n
        # OpenPTrack's acceleration variance is per frame of its nominal rate.
        self.spectral_density = params.acceleration_variance / params.acceleration_rate

    # ------------------------------------------------------------------ pieces
    def sigma_points(self, x: np.ndarray, P: np.ndarray) -> np.ndarray:
        """Merwe's 2n+1 sigma points of every track, (N, 9, 4) (filterpy's order)."""
        L = np.linalg.cholesky(self._scale * P)  # lower: columns are filterpy's rows of U
        U = np.swapaxes(L, 1, 2)
        centre = x[:, None, :]
        return np.concatenate([centre, centre + U, centre - U], axis=1)

    @staticmethod
    def fx(sigmas: np.ndarray, dt: np.ndarray) -> np.ndarray:
        """Constant-velocity transition of sigma points (N, k, 4) over dt (N,)."""
        out = sigmas.copy()
        out[..., 0:2] += dt[:, None, None] * sigmas[..., 2:4]
        return out

    @staticmethod
    def hx(sigmas: np.ndarray) -> np.ndarray:
        """The measurement [x, y, vx, vy] is the state itself."""
        return sigmas

    def _moments(self, sigmas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unscented transform: weighted mean and covariance of sigma points (N, k, 4)."""
        mean = self.Wm @ sigmas
        d = sigmas - mean[:, None, :]
        return mean, self._cross(d, d)

    def _cross(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """sum_k Wc[k] a[:, k]^T b[:, k], (N, 4, 4)."""
        return np.swapaxes(a * self.Wc[None, :, None], 1, 2) @ b

    # ------------------------------------------------------------------- steps
    def predict(
        self, x: np.ndarray, P: np.ndarray, dt: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Prior after dt seconds (negative dt retrodicts; Q always grows with |dt|)."""
        dt = np.asarray(dt, dtype=np.float64)
        sigmas_f = self.fx(self.sigma_points(x, P), dt)
        x_prior, P_prior = self._moments(sigmas_f)
        return x_prior, P_prior + process_noise(dt, self.spectral_density)

    def innovation(
        self, x_prior: np.ndarray, P_prior: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Predicted measurement ``zp``, its covariance without R, and ``Pxz``.

        As filterpy: the prior's sigma points are redrawn and passed through hx.
        """
        sigmas_f = self.sigma_points(x_prior, P_prior)
        sigmas_h = self.hx(sigmas_f)
        zp, S0 = self._moments(sigmas_h)
        dx = sigmas_f - x_prior[:, None, :]
        dz = sigmas_h - zp[:, None, :]
        return zp, S0, self._cross(dx, dz)

    @staticmethod
    def update(
        x_prior: np.ndarray,
        P_prior: np.ndarray,
        zp: np.ndarray,
        S: np.ndarray,
        Pxz: np.ndarray,
        z: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Posterior: K = Pxz S^-1, x = x + K (z - zp), P = P - K S K^T."""
        SI = np.linalg.inv(S)
        K = Pxz @ SI
        y = z - zp
        x = x_prior + np.einsum("nij,nj->ni", K, y)
        P = P_prior - K @ S @ np.swapaxes(K, 1, 2)
        return x, 0.5 * (P + np.swapaxes(P, 1, 2))
