"""Data association: measurements, Mahalanobis gate, cost, global nearest neighbour.

Each piece is a pure function over arrays for N tracks and M detections, so
the tracker loop reads top to bottom and each piece is tested on its own.

* :func:`measurements` builds ``z = [x, y, vx, vy]`` for every pair: the
  velocity is the one the track would have if it took the detection
  (OpenPTrack paper eq. 5-6).
* :func:`gate_value` is the chi-square quantile of the gate probability with
  4 degrees of freedom (about 13.28 for 0.99). OpenPTrack's tracker passes
  the probability itself, so its gate is about 1: a known defect not copied.
* :func:`within_reach` is a second, physical gate: nobody walks faster than
  ``max_speed``, so a track can only take a detection within ``min_reach +
  max_speed * time unseen`` of where it was last detected. Without it the
  constant-velocity covariance of a track lost for a second or two (with
  OpenPTrack's acceleration variance) spans the whole room.
* :func:`association_cost` adds the weighted motion term and the weighted
  detection confidence (OpenPTrack ``createDistanceMatrix``). The motion term
  is the Gaussian negative log-likelihood ``d2 + ln|S|`` rather than ``d2``
  alone, so that a long-lost track, whose wide ``S`` makes every ``d2`` small,
  cannot take a detection from a track that predicts it sharply.
* :func:`weak_revival` says which weak detections may still take a track that
  went missing moments ago: those the detector flags partly hidden, where the
  track predicts the person.
* :func:`assign` solves the assignment with scipy's ``linear_sum_assignment``.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.stats import chi2

from optrack.tracking.motion import DIM_Z

__all__ = [
    "UNMEASURED_VARIANCE",
    "assign",
    "association_cost",
    "extrapolate_late",
    "gate_value",
    "mahalanobis",
    "measurement_noise",
    "measurements",
    "reach",
    "weak_revival",
    "within_reach",
]

#: Variance given to a velocity that cannot be measured yet (a newborn track
#: with no position old enough): it makes that part of z carry no information.
UNMEASURED_VARIANCE = 1.0e6


def gate_value(probability: float, dof: int = DIM_Z) -> float:
    """Squared Mahalanobis distance inside which ``probability`` of true detections fall."""
    return float(chi2.ppf(probability, dof))


def measurements(
    positions: np.ndarray, reference: np.ndarray, baseline: np.ndarray, zp: np.ndarray
) -> np.ndarray:
    """``z`` for every (track, detection) pair, (N, M, 4) (paper eq. 5-6).

    ``positions`` (M, 2): detections on the ground. ``reference`` (N, 2): each
    track's filtered position ``baseline`` (N,) seconds before the batch; where
    the baseline is NaN (no position old enough) the velocity is not measured
    and the prediction's own velocity ``zp[:, 2:4]`` stands in.
    """
    n, m = len(reference), len(positions)
    z = np.empty((n, m, DIM_Z))
    z[:, :, 0:2] = positions[None, :, :]
    measured = np.isfinite(baseline)
    safe = np.where(measured, baseline, 1.0)
    velocity = (positions[None, :, :] - reference[:, None, :]) / safe[:, None, None]
    z[:, :, 2:4] = np.where(measured[:, None, None], velocity, zp[:, None, 2:4])
    return z


def extrapolate_late(
    z: np.ndarray,
    R: np.ndarray,
    lag: np.ndarray,
    x: np.ndarray,
    P: np.ndarray,
    spectral_density: float,
) -> None:
    """Carry detections ``lag`` (N,) seconds forward to each track's time, in place.

    A late batch's position is moved along the track's velocity ``x[:, 2:4]``;
    its variance grows by the velocity's uncertainty over the lag and by the
    process noise (an out-of-sequence measurement handled by extrapolation).
    """
    z[:, :, 0:2] += lag[:, None, None] * x[:, None, 2:4]
    for axis in (0, 1):
        extra = lag**2 * P[:, axis + 2, axis + 2] + spectral_density * lag**3 / 3.0
        R[:, :, axis, axis] += extra[:, None]


def measurement_noise(
    position_var: np.ndarray, baseline: np.ndarray, spectral_density: float = 0.0
) -> np.ndarray:
    """Diagonal R for every pair, (N, M, 4, 4).

    Position: the detection's variance. Velocity: a difference of two
    positions over the baseline, ``2 * var / baseline^2``, plus how far the
    mean velocity over the baseline strays from the velocity at its end under
    white-noise acceleration, ``q * baseline / 3``.
    """
    n, m = len(baseline), len(position_var)
    R = np.zeros((n, m, DIM_Z, DIM_Z))
    measured = np.isfinite(baseline)
    safe = np.where(measured, baseline, 1.0)
    velocity_var = np.where(
        measured[:, None],
        2.0 * position_var[None, :] / safe[:, None] ** 2 + spectral_density * safe[:, None] / 3.0,
        UNMEASURED_VARIANCE,
    )
    for axis in (0, 1):
        R[:, :, axis, axis] = position_var[None, :]
        R[:, :, axis + 2, axis + 2] = velocity_var
    return R


def mahalanobis(z_tilde: np.ndarray, S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Squared Mahalanobis distance ``d2 = z_tilde^T S^-1 z_tilde`` and ``ln|S|`` per pair."""
    solved = np.linalg.solve(S, z_tilde[..., None])[..., 0]
    d2 = np.einsum("...i,...i->...", z_tilde, solved)
    _, logdet = np.linalg.slogdet(S)
    return d2, logdet


def association_cost(
    d2: np.ndarray,
    logdet: np.ndarray,
    confidence: np.ndarray,
    motion_weight: float,
    detector_weight: float,
) -> np.ndarray:
    """Cost of each pair: motion_weight * (d2 + ln|S|) + detector_weight * confidence."""
    return motion_weight * (d2 + logdet) + detector_weight * confidence[None, :]


def assign(cost: np.ndarray, allowed: np.ndarray) -> list[tuple[int, int]]:
    """Pairs (track, detection) of least total cost among the allowed pairs.

    Pairs outside ``allowed`` (the gate) cost more than any set of allowed
    pairs together, so the solver first takes as many allowed pairs as it can
    (as OpenPTrack's 1e6 entries) and never returns a forbidden one.
    """
    if cost.size == 0 or not allowed.any():
        return []
    finite = np.abs(cost[allowed])
    forbidden = (finite.max() + 1.0) * (min(cost.shape) + 1)
    rows, cols = linear_sum_assignment(np.where(allowed, cost, forbidden))
    return [(int(i), int(j)) for i, j in zip(rows, cols, strict=True) if allowed[i, j]]


def reach(unseen: np.ndarray, max_speed: float, min_reach: float) -> np.ndarray:
    """How far (m) a person can be from where they were last detected ``unseen`` seconds ago."""
    return min_reach + max_speed * np.maximum(unseen, 0.0)


def within_reach(
    positions: np.ndarray,
    last_seen: np.ndarray,
    unseen: np.ndarray,
    max_speed: float,
    min_reach: float,
) -> np.ndarray:
    """(N, M) pairs whose detection is within each track's reach of where it was last seen."""
    distance = np.linalg.norm(positions[None, :, :] - last_seen[:, None, :], axis=2)
    return distance <= reach(unseen, max_speed, min_reach)[:, None]


def weak_revival(
    positions: np.ndarray,
    hidden: np.ndarray,
    predicted: np.ndarray,
    unseen: np.ndarray,
    window: float,
    radius: float,
) -> np.ndarray:
    """(N, M) pairs where a detection too weak to start a track may still take a missing one.

    Someone who steps out from behind another person or piece of furniture is
    detected weakly at first, and the detector says why (``hidden`` (M,): flagged
    occluded or partly outside the image). Such a detection may take a track lost
    for at most ``window`` seconds (``unseen`` (N,)) that predicts the person
    within ``radius`` of it (``predicted`` (N, 2)). Anything else weak still cannot
    revive a lost track: furniture's weak false alarms would keep it alive.
    """
    if window <= 0:
        return np.zeros((len(predicted), len(positions)), dtype=bool)
    distance = np.linalg.norm(positions[None, :, :] - predicted[:, None, :], axis=2)
    return (unseen <= window)[:, None] & hidden[None, :] & (distance <= radius)
