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
* :func:`assign` solves the assignment with scipy's ``linear_sum_assignment``.

The tracker's cost and gate are swappable, as norfair's distance function and
threshold: a :data:`Cost` maps the batch's :class:`Candidates` (every
(track, detection) pair with what the motion model says of it) to an (N, M)
cost, a :data:`Gate` to the (N, M) pairs allowed; :func:`associate` returns
the pairs of least total cost. The defaults, :func:`likelihood_cost` and
:func:`chi_square_gate`, are the ones above. The life-cycle then forbids what
its rules forbid (:meth:`~optrack.tracking.lifecycle.LifecyclePolicy.revival_barred`),
whichever the gate.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.stats import chi2

from optrack.tracking.motion import DIM_Z
from optrack.types import Detection

if TYPE_CHECKING:
    from optrack.tracking.lifecycle import TrackState

__all__ = [
    "UNMEASURED_VARIANCE",
    "Candidates",
    "Cost",
    "Gate",
    "assign",
    "associate",
    "association_cost",
    "chi_square_gate",
    "extrapolate_late",
    "gate_value",
    "mahalanobis",
    "measurement_noise",
    "measurements",
    "likelihood_cost",
    "reach",
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


@dataclasses.dataclass(slots=True)
class Candidates:
    """Every (track, detection) pair of one batch, as the cost and the gate see it.

    N tracks, M detections; arrays are indexed [track, detection]. A cost or a gate
    reads them and changes none.
    """

    t: float  # the batch's stamp
    tracks: Sequence[TrackState]  # (N,) read only
    detections: Sequence[Detection]  # (M,)
    positions: np.ndarray  # (M, 2) the detections on the ground
    confidence: np.ndarray  # (M,) the detector's confidence
    predicted: np.ndarray  # (N, 4) each track's state [x, y, vx, vy] predicted to t
    d2: np.ndarray  # (N, M) squared Mahalanobis distance of z = [x, y, vx, vy]
    logdet: np.ndarray  # (N, M) ln|S|
    last_seen: np.ndarray  # (N, 2) where each track was detected closest before t
    unseen: np.ndarray  # (N,) and how long before t
    chi_square: float  # the d2 quantile of gate_probability (the default gate's bound)
    settings: Any  # the tracking parameters (attribute access)

    def distance(self) -> np.ndarray:
        """(N, M) ground distance from each track's predicted position to each detection."""
        return np.linalg.norm(self.positions[None, :, :] - self.predicted[:, None, 0:2], axis=2)


#: an association cost: (N, M) floats from the candidates; lower is a better pair
Cost = Callable[[Candidates], np.ndarray]
#: an association gate: (N, M) booleans from the candidates; only True pairs may be made
Gate = Callable[[Candidates], np.ndarray]


def likelihood_cost(candidates: Candidates) -> np.ndarray:
    """The default cost: :func:`association_cost` with ``motion_weight`` and ``detector_weight``."""
    s = candidates.settings
    return association_cost(
        candidates.d2, candidates.logdet, candidates.confidence, s.motion_weight, s.detector_weight
    )


def chi_square_gate(candidates: Candidates) -> np.ndarray:
    """The default gate: ``d2`` within the chi-square quantile of ``gate_probability``, and
    the detection within the track's reach (:func:`within_reach`)."""
    c, s = candidates, candidates.settings
    return (c.d2 <= c.chi_square) & within_reach(
        c.positions, c.last_seen, c.unseen, s.max_speed, s.min_reach
    )


def associate(candidates: Candidates, cost: Cost, allowed: np.ndarray) -> list[tuple[int, int]]:
    """Pairs (track, detection) of least total ``cost`` among the ``allowed`` ones."""
    matrix = np.asarray(cost(candidates), dtype=np.float64)
    if matrix.shape != allowed.shape:
        raise ValueError(
            f"the association cost gave an array of shape {matrix.shape} for "
            f"{allowed.shape[0]} tracks and {allowed.shape[1]} detections"
        )
    return assign(matrix, allowed)
