"""MDCA's annealed particle filter with partitioned sampling (§IV).

Each frame: every particle takes a Gaussian random-walk step (per-joint
agility times the time since the last frame); then the five partitions are
annealed in turn, torso first, then the left arm, right arm, left leg, right
leg. Annealing a partition (Deutscher's annealed particle filter) repeats
``layers`` times: weigh the particles by the likelihood of that partition's
parts raised to an exponent chosen so that ``survival_rate`` of them stay
effective, resample that partition's numbers, and diffuse them by a spread
shrinking by ``anneal_decay`` each layer. The weighted mean of the last layer
is the partition's estimate; the next partitions are scored with it fixed
(its parts explain the points they can, and a limb only competes for the rest).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from optrack.params import Params
from optrack.skeleton.kernels import (
    PartitionScorer,
    limb_points,
    nearest_areas,
)
from optrack.skeleton.likelihood import sorted_points
from optrack.skeleton.model import (
    FRAMES,
    LIMITS,
    PARTITIONS,
    PARTS,
    BodyShape,
    D,
    forward_kinematics,
    part_areas,
    part_geometry,
    part_reach,
)
from optrack.skeleton.params import SKELETON_PARAMS
from optrack.skeleton.prior import ArmCollision

__all__ = [
    "PARTITION_FRAMES",
    "PARTITION_PARTS",
    "SkeletonFilter",
    "annealing_exponent",
    "motion_spread",
    "systematic_resample",
]

# The parts each partition is scored on: the torso on the whole body (its limbs at their
# last estimate), so that the trunk cannot slide onto the legs' points; each limb on its
# own parts, the rest fixed.
PARTITION_PARTS: dict[str, np.ndarray] = {
    name: np.array([k for k, part in enumerate(PARTS) if name == "torso" or part.partition == name])
    for name in PARTITIONS
}
# The frames each limb's angles turn (the torso recomputes them all).
PARTITION_FRAMES: dict[str, tuple[str, ...]] = {
    "torso": FRAMES,
    "left_arm": ("left_shoulder", "left_elbow"),
    "right_arm": ("right_shoulder", "right_elbow"),
    "left_leg": ("left_hip", "left_knee"),
    "right_leg": ("right_hip", "right_knee"),
}
# The parts fixed while a partition is scored: every other partition's.
_OTHERS = {name: np.array([part.partition != name for part in PARTS]) for name in PARTITIONS}
_ROOT_JOINT = {"left_arm": 4, "right_arm": 7, "left_leg": 10, "right_leg": 13}
_YAW = 3
# The root numbers the motion model predicts by their velocity: where the person goes and
# turns (persistent); not the pelvis's height, which bobs (gait, jumps, squats).
_MOVING = [0, 1, _YAW]
_STILL = np.array([0.3, 0.3, 1.0])  # m/s, m/s, rad/s of velocity that momentum ignores
# The limbs' angles (both arms and both legs), whose velocity limb_momentum carries on
# (whole: a threshold like the root's, 2.5 rad/s, did worse on the bench, docs/skeleton.md).
_LIMBS = slice(PARTITIONS["left_arm"][0], D)


def motion_spread(params: Params, dt: float) -> np.ndarray:
    """Standard deviation of the random-walk step of each state number over ``dt`` s, (D,)."""
    dt = min(max(float(dt), 0.0), float(params.max_dt))
    spread = np.empty(D)
    spread[0:3] = params.agility_root_m
    spread[_YAW] = params.agility_heading_rad
    spread[4:6] = params.agility_root_rad
    spread[6:12] = params.agility_torso_rad
    spread[12:20] = params.agility_arms_rad
    spread[20:28] = params.agility_legs_rad
    return spread * dt


# exp(x) for x <= 0 in a loop that vectorises (numba's np.exp is one libm call a number):
# x = k ln 2 + r with |r| <= ln 2 / 2 (ln 2 in two parts, Cody and Waite), exp(r) by its
# Taylor series to r^12 (relative error under 3e-16), 2^k from a table.
_LN2_HI = 6.93147180369123816490e-01
_LN2_LO = 1.90821492927058770002e-10
_INV_LN2 = 1.44269504088896338700e00
_POW2 = 2.0 ** -np.arange(1011.0)  # 2^-k down to exp(-700)'s
_TAYLOR = tuple(1.0 / math.factorial(j) for j in range(13))


@numba.njit(cache=True, fastmath={"nnan", "ninf", "nsz", "contract"})
def exp_nonpositive(x: np.ndarray, out: np.ndarray) -> None:
    """out = exp(x) for x <= 0 (under -700: exp(-700), about 1e-304), to 3e-16 relative;
    exp(0) is exactly 1. Tested against numpy's exp."""
    c = _TAYLOR
    for i in range(x.shape[0]):
        v = max(min(x[i], 0.0), -700.0)
        k = np.floor(v * _INV_LN2 + 0.5)
        r = (v - k * _LN2_HI) - k * _LN2_LO
        p = c[12]
        for j in range(11, -1, -1):  # Horner
            p = p * r + c[j]
        out[i] = p * _POW2[np.int64(-k)]


@numba.njit(cache=True, fastmath=True)
def _ess_sums(centred: np.ndarray, beta: float, w: np.ndarray) -> tuple[float, float, float, float]:
    """The sums :func:`_exponent` needs at ``beta``: of w = exp(beta * value), w^2,
    value * w and 2 value * w^2 (``w``: scratch of the values' length)."""
    exp_nonpositive(beta * centred, w)
    s1, s2, d1, d2 = 0.0, 0.0, 0.0, 0.0
    for i in range(centred.shape[0]):
        value, wi = centred[i], w[i]
        s1 += wi
        s2 += wi * wi
        d1 += value * wi
        d2 += 2.0 * value * wi * wi
    return s1, s2, d1, d2


@numba.njit(cache=True, fastmath=True)
def _exponent(centred: np.ndarray, target: float) -> float:
    """Newton's method on log10(beta) for ESS(beta) = target, kept inside a bracket that
    each step narrows (bisection where Newton would leave it), from the Gaussian guess:
    a few passes over the weights instead of bisection's 16; to 1e-6 decades."""
    low, high = -6.0, 8.0  # log10 of beta; ESS falls as beta grows
    # Start where a Gaussian spread of log-weights would put it: ESS/N = exp(-(beta sd)^2).
    n = len(centred)
    sd = np.sqrt(max(np.var(centred), 1e-300))
    u = min(max(np.log10(np.sqrt(-np.log(min(max(target / n, 1e-9), 0.999))) / sd), low), high)
    w = np.empty(n)
    for _ in range(40):
        beta = 10.0**u
        s1, s2, d1, d2 = _ess_sums(centred, beta, w)
        excess = s1 * s1 / s2 - target
        if excess > 0.0:
            low = u
        else:
            high = u
        slope = (2.0 * s1 * d1 * s2 - s1 * s1 * d2) / (s2 * s2) * beta * np.log(10.0)
        step = -excess / slope if slope < 0.0 else 0.0
        if step == 0.0 or not low < u + step < high:
            step = 0.5 * (low + high) - u
        u += step
        if abs(step) < 1e-6 or high - low < 1e-6:
            break
    return 10.0**u


@numba.njit(cache=True, fastmath=True)
def _beta(centred: np.ndarray, survival_rate: float) -> float:
    """:func:`annealing_exponent` of log-weights whose largest is 0."""
    if not np.any(centred < -1e-12):
        return 1.0
    return _exponent(centred, survival_rate * centred.shape[0])


@numba.njit(cache=True, fastmath=True)
def _weights(log_weights: np.ndarray, survival_rate: float) -> np.ndarray:
    """Normalised weights exp(beta * log_weights), beta from :func:`annealing_exponent`."""
    centred = log_weights - log_weights.max()
    w = np.empty(centred.shape[0])
    exp_nonpositive(_beta(centred, survival_rate) * centred, w)
    return w / w.sum()


def annealing_exponent(log_weights: np.ndarray, survival_rate: float) -> float:
    """The exponent beta for which the weights exp(beta * log_weights) keep an effective
    sample size of ``survival_rate`` times the particle count."""
    centred = np.asarray(log_weights, dtype=np.float64) - np.max(log_weights)
    return float(_beta(centred, float(survival_rate)))


def systematic_resample(weights: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Indices of a systematic resampling of normalised weights: the particle whose
    cumulative weight first reaches each of n positions (u + i) / n, u uniform in [0, 1)."""
    return _systematic(np.asarray(weights, dtype=np.float64), rng.random())


@numba.njit(cache=True)
def _systematic(weights: np.ndarray, offset: float) -> np.ndarray:
    n = weights.shape[0]
    cumulative = np.cumsum(weights)
    cumulative[-1] = 1.0
    chosen = np.empty(n, dtype=np.int64)
    j = 0
    for i in range(n):  # the positions ascend: one pass (numpy's searchsorted, left side)
        position = (offset + i) / n
        while cumulative[j] < position:
            j += 1
        chosen[i] = j
    return chosen


@numba.njit(cache=True)
def _take_and_diffuse(particles, idx, chosen, rng, diffuse, sd, low, high):
    """In place: the columns ``idx`` of the particles ``chosen``, then (with ``diffuse``)
    plus a standard normal from ``rng`` times ``sd``, clipped to [low, high]. The
    normals are drawn row by row: numba's Generator gives the numbers numpy's
    ``rng.standard_normal((P, len(idx)))`` gives (tested), at a third of its cost."""
    taken = np.empty((chosen.shape[0], idx.shape[0]))
    for i in range(chosen.shape[0]):
        for j in range(idx.shape[0]):
            taken[i, j] = particles[chosen[i], idx[j]]
    for i in range(chosen.shape[0]):
        for j in range(idx.shape[0]):
            value = taken[i, j]
            if diffuse:
                value = min(max(value + rng.standard_normal() * sd[j], low[j]), high[j])
            particles[i, idx[j]] = value


@numba.njit(cache=True)
def _resample_layer(particles, idx, log_weights, survival_rate, rng, diffuse, sd, low, high):
    """One annealing layer after scoring, in place: weigh the particles (the exponent
    that keeps ``survival_rate`` of them effective), resample the columns ``idx``
    systematically (its u: ``rng.random()``, as :func:`systematic_resample` draws it)
    and diffuse them (:func:`_take_and_diffuse`)."""
    chosen = _systematic(_weights(log_weights, survival_rate), rng.random())
    _take_and_diffuse(particles, idx, chosen, rng, diffuse, sd, low, high)


@numba.njit(cache=True)
def _random_walk(particles, drift, step, low, high, rng):
    """In place: each particle plus ``drift`` plus a standard normal times ``step``, each
    number clipped to [low, high]; the normals drawn row by row (numpy's
    ``rng.standard_normal(particles.shape)``'s numbers, tested), the sums in numpy's
    order: (particle + drift) + normal * step."""
    for i in range(particles.shape[0]):
        for d in range(particles.shape[1]):
            value = (particles[i, d] + drift[d]) + rng.standard_normal() * step[d]
            particles[i, d] = min(max(value, low[d]), high[d])


def _weighted_mean(values: np.ndarray, weights: np.ndarray, dims: tuple[int, ...]) -> np.ndarray:
    mean = weights @ values
    if _YAW in dims:  # an angle without limits: the circular mean
        j = dims.index(_YAW)
        mean[j] = np.arctan2(weights @ np.sin(values[:, j]), weights @ np.cos(values[:, j]))
    return mean


class SkeletonFilter:
    """The particle set and the estimate of one person's pose (see the module docstring)."""

    def __init__(
        self, shape: BodyShape, params: Params | None = None, seed: int | None = None
    ) -> None:
        self.shape = shape
        self.params = params if params is not None else SKELETON_PARAMS.create()
        self.rng = np.random.default_rng(seed)
        self.estimate = np.zeros(D)
        self.particles = np.zeros((int(self.params.particles), D))
        self._areas = part_areas(shape)
        # How far each limb reaches from its root joint (m), bones and extensions.
        self._reach = {name: part_reach(shape, PARTITION_PARTS[name]) for name in _ROOT_JOINT}
        # The root's velocity (x, y in m/s, heading in rad/s), smoothed over frames.
        self.velocity = np.zeros(len(_MOVING))
        # The limbs' angular velocity (rad/s), smoothed over frames.
        self.limb_velocity = np.zeros(D - _LIMBS.start)
        # Each area's support at the estimate's last fit (K, 2); None before one.
        self.support: np.ndarray | None = None

    def reset(self, state: np.ndarray, spread: np.ndarray | float = 0.0) -> None:
        """Put every particle at ``state`` plus Gaussian noise of ``spread`` per number."""
        n = int(self.params.particles)
        self.estimate = np.asarray(state, dtype=np.float64).copy()
        noise = self.rng.normal(size=(n, D)) * np.broadcast_to(spread, (D,))
        self.particles = _clamp(self.estimate[None, :] + noise)
        self.limb_velocity[:] = 0.0  # a new pose: its limbs' motion is unknown

    def snapshot(self) -> tuple:
        """The filter as it is now, for :meth:`restore`: its estimate, particles, limbs'
        velocity and random stream (a try that is refused leaves no trace)."""
        return (
            self.estimate.copy(), self.particles.copy(), self.limb_velocity.copy(),
            self.rng.bit_generator.state,
        )  # fmt: skip

    def restore(self, snapshot: tuple) -> None:
        """Put the filter back as :meth:`snapshot` found it."""
        estimate, particles, limb_velocity, stream = snapshot
        self.estimate, self.particles = estimate.copy(), particles.copy()
        self.limb_velocity = limb_velocity.copy()
        self.rng.bit_generator.state = stream

    def stop_limb(self, dims: list[int]) -> None:
        """Forget the angular velocity of the limb numbers ``dims`` (a limb found anew)."""
        self.limb_velocity[np.asarray(dims) - _LIMBS.start] = 0.0

    def expected_support(self, n_points: int) -> np.ndarray:
        """Points each area of interest should hold, (K, 2)."""
        share = self._areas / self._areas.sum() * n_points * float(self.params.support_fraction)
        return np.repeat(share[:, None] / 2.0, 2, axis=1)

    def step(self, points: np.ndarray, dt: float) -> np.ndarray:
        """One frame: predict, then anneal each partition in turn; returns the estimate (D,)."""
        if len(self.particles) != int(self.params.particles):
            self.reset(self.estimate)
        spread = motion_spread(self.params, dt)
        spreads = {name: self._widened(spread, name) for name in PARTITIONS}
        step = np.concatenate([spreads[name][list(dims)] for name, dims in PARTITIONS.items()])
        dt = min(max(float(dt), 0.0), float(self.params.max_dt))
        drift = np.zeros(D)
        # Soft-thresholded: a standing person's estimate jitters by up to about 0.2 m/s and
        # 0.5 rad/s, and carrying that over would feed it back (the heading drifts).
        carried = np.sign(self.velocity) * np.maximum(np.abs(self.velocity) - _STILL, 0.0)
        drift[_MOVING] = carried * dt * float(self.params.momentum)
        drift[_LIMBS] = self.limb_velocity * dt * float(self.params.limb_momentum)
        _random_walk(self.particles, drift, step, LIMITS[:, 0], LIMITS[:, 1], self.rng)
        before = self.estimate.copy()
        for name in PARTITIONS:
            self.anneal(points, name, int(self.params.layers), spreads[name], gate=True)
        if dt > 0.0:  # the root's velocity, smoothed: half the last frame's, half before
            moved = self.estimate[_MOVING] - before[_MOVING]
            moved[-1] = np.angle(np.exp(1j * moved[-1]))
            self.velocity = 0.5 * self.velocity + 0.5 * moved / dt
            turned = (self.estimate[_LIMBS] - before[_LIMBS]) / dt
            self.limb_velocity = 0.5 * self.limb_velocity + 0.5 * turned
        return self.estimate.copy()

    def _widened(self, spread: np.ndarray, partition: str) -> np.ndarray:
        """``spread`` with a limb's numbers widened by up to ``1 + limb_search`` times where
        its areas of interest held few of their points at the last :meth:`fit` (a limb
        that lost its points searches further for them)."""
        if partition == "torso" or self.support is None:
            return spread
        held = float(np.mean(self.support[PARTITION_PARTS[partition]]))
        wider = spread.copy()
        dims = list(PARTITIONS[partition])
        wider[dims] *= 1.0 + float(self.params.limb_search) * (1.0 - held)
        return wider

    def anneal(
        self,
        points: np.ndarray,
        partition: str,
        layers: int,
        spread: np.ndarray,
        parts: np.ndarray | None = None,
        gate: bool = False,
    ) -> None:
        """Anneal one partition's numbers against ``points`` (N, 3), the partitions before it
        fixed at the estimate; sets its part of the estimate. ``parts`` overrides the parts
        it is scored on (initialisation scores the torso without the arms, yet unknown);
        with ``gate`` a limb is scored only on the points within ``limb_gate`` of where it
        was or that no part of the estimate explains (tracking), else on all within its
        reach (initialisation)."""
        p = self.params
        dims = PARTITIONS[partition]
        parts = PARTITION_PARTS[partition] if parts is None else np.asarray(parts)
        base = forward_kinematics(self.estimate, self.shape)
        scored, baseline = self._scored_points(points, partition, gate, base)
        shown = len(scored) if partition == "torso" else len(points)
        expected = self.expected_support(shown)[parts]
        idx = np.array(dims)
        consts = (float(p.sigma), float(p.alpha), float(p.support_weight))
        scorer = PartitionScorer(
            self.estimate, dims, PARTITION_FRAMES[partition], parts, self.shape,
            sorted_points(scored, baseline), expected, consts, int(p.threads), base,
        )  # fmt: skip
        low, high = LIMITS[idx].T
        collision = ArmCollision(self.estimate, partition, self.shape, p)
        for layer in range(layers):
            ll = scorer(self.particles)
            if collision.active and (layer == 0 or not gate):  # tracking: the first layer
                ll -= collision(self.particles)
            if layer == layers - 1:  # the estimate: the mean of the best few
                best = _weights(ll, float(p.estimate_survival))
                self.estimate[idx] = _weighted_mean(self.particles[:, idx], best, dims)
            diffuse = layer < layers - 1  # the last layer: no diffusion
            sd = spread[idx] * float(p.anneal_decay) ** (layer + 1)
            _resample_layer(
                self.particles, idx, ll, float(p.survival_rate), self.rng, diffuse, sd, low, high
            )
        if partition == "torso" and _YAW in dims:  # keep yaws next to their mean
            delta = self.particles[:, _YAW] - self.estimate[_YAW]
            self.particles[:, _YAW] = self.estimate[_YAW] + np.angle(np.exp(1j * delta))

    def _scored_points(self, points: np.ndarray, partition: str, gate: bool, base: tuple):
        """The points a partition is scored on and their baseline (None for the torso);
        ``base``: the estimate's forward kinematics."""
        p = self.params
        if partition == "torso":
            keep = int(p.torso_points)
            if len(points) > keep:
                points = points[self.rng.choice(len(points), keep, replace=False)]
            return points, None
        body = part_geometry(base[0][None], base[1][None], self.shape)[0]
        parts = PARTITION_PARTS[partition]
        # Every other partition's parts, at the estimate: a limb does not take the points
        # another limb holds (searched first, the left arm took the right arm's points).
        # Tracking: near where the limb was, or explained by no part of the estimate.
        gate_m = float(p.limb_gate) if gate else 0.0
        reach = 0.0 if gate else self._reach[partition] + float(p.reach_margin)
        baseline, near = limb_points(
            np.asarray(points, dtype=np.float64), body, _OTHERS[partition], parts,
            float(p.alpha), gate_m, base[0][_ROOT_JOINT[partition]], reach,
        )  # fmt: skip
        keep = near & (baseline > float(p.explained_skip))
        return points[keep], baseline[keep]

    def fit(self, points: np.ndarray, state: np.ndarray | None = None) -> tuple[float, np.ndarray]:
        """How well a pose (the estimate by default) explains ``points``: the share of points
        within alpha of a part, and the support of each area of interest, (K, 2), as a
        share of what it should hold (capped at 1)."""
        state = self.estimate if state is None else state
        pts, rot = forward_kinematics(state, self.shape)
        geometry = part_geometry(pts[None], rot[None], self.shape)[0]
        area = nearest_areas(
            np.asarray(points, dtype=np.float64), geometry, float(self.params.alpha)
        )
        counts = np.bincount(area[area >= 0], minlength=2 * len(PARTS)).reshape(-1, 2)
        expected = self.expected_support(len(points))
        support = np.minimum(1.0, counts / np.maximum(expected, 1e-9))
        if state is self.estimate:
            self.support = support
        return float(np.mean(area >= 0)) if len(area) else 0.0, support


def _clamp(state: np.ndarray) -> np.ndarray:
    return np.clip(state, LIMITS[:, 0], LIMITS[:, 1])
