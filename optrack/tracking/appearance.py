"""Appearance: an on-line boosted colour classifier per track (Munaro 2012 section 5.2-5.4).

Features are the histogram mass inside random boxes of a detection's colour
histogram (:class:`FeaturePool`). Each track learns, on line, a boosted
classifier (Grabner and Bischof 2006 on-line boosting, as Munaro 2012): weak
learners are Gaussian models of one feature for the track (positives) and for
other people (negatives); selectors keep the weak learner with the least
weighted error, with voting weight ``alpha = 1/2 ln((1 - e) / e)``.
:class:`AppearanceModel` keeps the classifiers of all tracks, a bank of other
people's recent histograms as negatives, and the classifiers of deleted
tracks for a while, so that a lost identity can be given back.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from collections.abc import Sequence

import numpy as np

from optrack.params import Params

__all__ = ["AppearanceModel", "FeaturePool", "OnlineBoostedClassifier", "histogram_shape"]

#: Errors are kept inside (ERROR_FLOOR, 1 - ERROR_FLOOR) so alpha stays finite.
ERROR_FLOOR = 1.0e-3


def histogram_shape(length: int, shape_text: str) -> tuple[int, ...]:
    """The grid of a flat histogram of ``length`` bins: ``shape_text`` ("16x4") if it
    fits, else one axis."""
    try:
        shape = tuple(int(p) for p in shape_text.lower().split("x") if p)
    except ValueError:
        shape = ()
    if shape and int(np.prod(shape)) == length:
        return shape
    return (length,)


class FeaturePool:
    """Random boxes in a histogram grid; a feature is the histogram mass inside a box."""

    def __init__(
        self, shape: tuple[int, ...], count: int, min_box_bins: int, rng: np.random.Generator
    ) -> None:
        self.shape = shape
        grids = np.indices(shape).reshape(len(shape), -1)  # (axes, bins)
        boxes = np.ones((count, grids.shape[1]), dtype=np.float64)
        for axis, bins in enumerate(shape):
            side = min(min_box_bins, bins)
            lo = rng.integers(0, bins - side + 1, size=count)
            hi = np.array([rng.integers(a + side, bins + 1) for a in lo])
            inside = (grids[axis][None, :] >= lo[:, None]) & (grids[axis][None, :] < hi[:, None])
            boxes *= inside
        self.boxes = boxes  # (K, bins)

    @property
    def size(self) -> int:
        return self.boxes.shape[0]

    def __call__(self, histograms: np.ndarray) -> np.ndarray:
        """Features of histograms (M, bins) -> (M, K)."""
        return histograms @ self.boxes.T


class OnlineBoostedClassifier:
    """One track's on-line boosted classifier over a :class:`FeaturePool`'s features."""

    def __init__(self, features: int, selectors: int, params: Params) -> None:
        self.params = params
        self.mean = np.zeros((2, features))  # row 0: negatives, row 1: positives
        self.var = np.full((2, features), params.min_feature_std**2)
        self.count = np.zeros(2, dtype=np.int64)
        selectors = min(selectors, features)  # each selector takes a different weak learner
        self.lambda_correct = np.ones((selectors, features))
        self.lambda_wrong = np.ones((selectors, features))
        self.selected = np.zeros(selectors, dtype=np.int64)
        self.alpha = np.zeros(selectors)

    @property
    def positives(self) -> int:
        return int(self.count[1])

    @property
    def trained(self) -> bool:
        return self.count[0] > 0 and self.count[1] >= self.params.min_samples

    def weak(self, f: np.ndarray) -> np.ndarray:
        """Every weak learner's vote (+1 this person, -1 someone else) on features f (..., K)."""
        log_like = -0.5 * ((f[..., None, :] - self.mean) ** 2 / self.var + np.log(self.var))
        return np.where(log_like[..., 1, :] >= log_like[..., 0, :], 1.0, -1.0)

    def confidence(self, f: np.ndarray) -> np.ndarray:
        """Normalised strong-classifier margin in [-1, 1] of features (M, K); 0 untrained."""
        f = np.atleast_2d(f)
        total = self.alpha.sum()
        if not self.trained or total <= 0:
            return np.zeros(len(f))
        votes = self.weak(f)[:, self.selected]
        return votes @ self.alpha / total

    def learn(self, f: np.ndarray, positive: bool) -> None:
        """One on-line boosting step with sample f (K,) of label ``positive``."""
        label = 1 if positive else 0
        y = 1.0 if positive else -1.0
        self.count[label] += 1
        rate = max(1.0 / self.count[label], self.params.learning_rate)
        delta = f - self.mean[label]
        self.mean[label] += rate * delta
        floor = self.params.min_feature_std**2
        self.var[label] = np.maximum((1.0 - rate) * (self.var[label] + rate * delta**2), floor)
        if self.count[0] == 0:
            return  # no negatives yet: nothing to discriminate
        correct = self.weak(f) == y
        hit = correct.astype(np.float64)
        miss = 1.0 - hit
        lambda_correct, lambda_wrong = self.lambda_correct, self.lambda_wrong
        importance = 1.0
        for s in range(self.selected.size):
            lambda_correct[s] += importance * hit
            lambda_wrong[s] += importance * miss
            error = lambda_wrong[s] / (lambda_correct[s] + lambda_wrong[s])
            error[self.selected[:s]] = np.inf  # each selector takes a weak learner of its own
            best = int(error.argmin())
            e = min(max(float(error[best]), ERROR_FLOOR), 1.0 - ERROR_FLOOR)
            self.selected[s] = best
            self.alpha[s] = 0.5 * math.log((1.0 - e) / e) if e < 0.5 else 0.0
            importance *= 1.0 / (2.0 * (1.0 - e)) if correct[best] else 1.0 / (2.0 * e)


@dataclasses.dataclass
class _Lost:
    classifier: OnlineBoostedClassifier
    x: float
    y: float
    last_detection: float
    deleted: float


class AppearanceModel:
    """Every track's classifier, the negatives bank and the identities of deleted tracks."""

    def __init__(self, params: Params) -> None:
        self.params = params
        self.rng = np.random.default_rng(params.seed)
        self.pool: FeaturePool | None = None
        self.classifiers: dict[int, OnlineBoostedClassifier] = {}
        self.last_learned: dict[int, float] = {}
        self.bank: deque[tuple[float, int, np.ndarray]] = deque()
        self.lost: dict[int, _Lost] = {}

    # --------------------------------------------------------------- features
    def features(self, histograms: Sequence[Sequence[float]]) -> np.ndarray | None:
        """Features (M, K) of detections' histograms; rows of NaN where a detection has none.
        None when no detection has a histogram."""
        lengths = {len(h) for h in histograms if len(h)}
        if not lengths:
            return None
        length = max(lengths)
        if self.pool is None or self.pool.boxes.shape[1] != length:
            shape = histogram_shape(length, self.params.histogram_shape)
            self.pool = FeaturePool(shape, self.params.features, self.params.min_box_bins, self.rng)
            self.classifiers.clear()
            self.lost.clear()
            self.bank.clear()
        H = np.full((len(histograms), length), np.nan)
        for row, h in enumerate(histograms):
            if len(h) == length:
                H[row] = h
        return self.pool(H)

    def classifier(self, track_id: int) -> OnlineBoostedClassifier:
        found = self.classifiers.get(track_id)
        if found is None:
            assert self.pool is not None
            found = OnlineBoostedClassifier(self.pool.size, self.params.selectors, self.params)
            self.classifiers[track_id] = found
        return found

    def confidence(self, track_id: int, F: np.ndarray) -> np.ndarray:
        """Classifier confidence of a track for each feature row (0 where unknown)."""
        found = self.classifiers.get(track_id)
        out = np.zeros(len(F))
        valid = np.all(np.isfinite(F), axis=1)
        if found is not None and valid.any():
            out[valid] = found.confidence(F[valid])
        return out

    # --------------------------------------------------------------- learning
    def learn(self, t: float, track_id: int, f: np.ndarray, others: np.ndarray) -> bool:
        """Teach a track its own features f and others' (rows of ``others``), rate-limited.

        Negatives are the other detections of the batch, topped up from the
        bank of other people's recent histograms, and random colour histograms
        (people in general). Returns True when it learned.
        """
        if not np.all(np.isfinite(f)):
            return False
        last = self.last_learned.get(track_id)
        if last is not None and t - last < self.params.update_interval:
            return False
        self.last_learned[track_id] = t
        self._expire(t)
        negatives = [row for row in others if np.all(np.isfinite(row))]
        negatives = negatives[: self.params.max_negatives]
        missing = self.params.max_negatives - len(negatives)
        if missing > 0:
            pool = [g for (_, tid, g) in self.bank if tid != track_id]
            if pool:
                picks = self.rng.choice(len(pool), size=min(missing, len(pool)), replace=False)
                negatives.extend(pool[i] for i in picks)
        generic = self.params.generic_negatives
        if generic:
            assert self.pool is not None
            bins = self.pool.boxes.shape[1]
            random_histograms = self.rng.dirichlet(
                np.full(bins, self.params.generic_concentration), size=generic
            )
            negatives.extend(self.pool(random_histograms))
        classifier = self.classifier(track_id)
        for g in negatives:
            classifier.learn(g, positive=False)
        classifier.learn(f, positive=True)
        self.bank.append((t, track_id, f.copy()))
        return True

    def _expire(self, now: float) -> None:
        memory = self.params.negative_memory
        while self.bank and now - self.bank[0][0] > memory:
            self.bank.popleft()
        for tid in [k for k, v in self.lost.items() if now - v.deleted > self.params.memory]:
            del self.lost[tid]

    # ----------------------------------------------------------- identities
    def forget(self, track_id: int, x: float, y: float, last_detection: float, now: float) -> None:
        """A track was deleted: keep its classifier for recovery for ``memory`` seconds."""
        self.last_learned.pop(track_id, None)
        found = self.classifiers.pop(track_id, None)
        if found is not None and found.trained and self.params.memory > 0:
            self.lost[track_id] = _Lost(found, x, y, last_detection, now)

    def drop(self, track_id: int) -> None:
        """A track ended without being worth remembering (a fake)."""
        self.classifiers.pop(track_id, None)
        self.last_learned.pop(track_id, None)

    def take_lost(self, track_id: int) -> OnlineBoostedClassifier | None:
        found = self.lost.pop(track_id, None)
        return None if found is None else found.classifier

    def lost_candidates(self) -> list[tuple[int, float, float, float]]:
        """(id, x, y, last_detection) of deleted tracks still remembered."""
        return [(tid, v.x, v.y, v.last_detection) for tid, v in self.lost.items()]

    def lost_confidence(self, track_id: int, F: np.ndarray) -> np.ndarray:
        found = self.lost.get(track_id)
        out = np.zeros(len(F))
        valid = np.all(np.isfinite(F), axis=1)
        if found is not None and valid.any():
            out[valid] = found.classifier.confidence(F[valid])
        return out

    def adopt(self, track_id: int, classifier: OnlineBoostedClassifier) -> None:
        """Give a track (that took a lost identity) that identity's classifier."""
        self.classifiers[track_id] = classifier
