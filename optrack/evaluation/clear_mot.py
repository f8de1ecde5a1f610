"""CLEAR MOT scores in the ground plane (Bernardin and Stiefelhagen 2008), with motmetrics.

A hypothesis matches a ground-truth person within ``radius`` metres on the
floor (0.5 m, as OpenPTrack's evaluation). Ground-truth people that do not
count in a frame (nobody can see them) are "don't care": a track on one of
them is neither a hit nor a false positive, as MOTChallenge treats
distractors.
"""

from __future__ import annotations

import dataclasses

import motmetrics as mm
import numpy as np
from scipy.optimize import linear_sum_assignment

__all__ = ["ClearMot", "MotScore"]

_METRICS = {
    "mota": "mota",
    "motp": "motp",
    "fp": "num_false_positives",
    "fn": "num_misses",
    "idsw": "num_switches",
    "precision": "precision",
    "recall": "recall",
    "frames": "num_frames",
    "objects": "num_objects",
    "matches": "num_matches",
}


@dataclasses.dataclass(frozen=True)
class MotScore:
    mota: float
    motp: float  # mean distance of matches, m
    fp: int
    fn: int
    idsw: int
    precision: float
    recall: float
    frames: int
    objects: int
    matches: int

    def as_dict(self) -> dict[str, float | int]:
        return dataclasses.asdict(self)


def _number(value: object) -> float:
    value = float(value)  # type: ignore[arg-type]
    return value if np.isfinite(value) else 0.0


class ClearMot:
    """Accumulate frames of ground truth and hypotheses, then :meth:`score`."""

    def __init__(self, radius: float = 0.5) -> None:
        self.radius = radius
        self.accumulator = mm.MOTAccumulator(auto_id=True)

    def add(
        self,
        gt_ids: np.ndarray,
        gt_xy: np.ndarray,
        counted: np.ndarray,
        hyp_ids: np.ndarray,
        hyp_xy: np.ndarray,
    ) -> None:
        """One frame: ground truth (ids, floor positions, counts-or-not) and hypotheses."""
        gt_ids = np.asarray(gt_ids, dtype=np.int64)
        hyp_ids = np.asarray(hyp_ids, dtype=np.int64)
        gt_xy = np.asarray(gt_xy, dtype=np.float64).reshape(-1, 2)
        hyp_xy = np.asarray(hyp_xy, dtype=np.float64).reshape(-1, 2)
        counted = np.asarray(counted, dtype=bool)
        distance = np.linalg.norm(gt_xy[:, None, :] - hyp_xy[None, :, :], axis=2)
        keep = np.ones(len(hyp_ids), dtype=bool)
        if (~counted).any() and len(hyp_ids):
            inside = distance <= self.radius
            rows, cols = linear_sum_assignment(np.where(inside, distance, 1e6))
            for i, j in zip(rows, cols, strict=True):
                if inside[i, j] and not counted[i]:
                    keep[j] = False  # a track on a person nobody can see: don't care
        distance = distance[counted][:, keep]
        distance[distance > self.radius] = np.nan
        self.accumulator.update(gt_ids[counted].tolist(), hyp_ids[keep].tolist(), distance)

    def score(self) -> MotScore:
        host = mm.metrics.create()
        summary = host.compute(self.accumulator, metrics=list(_METRICS.values()), name="all")
        row = summary.iloc[0]
        values = {key: _number(row[name]) for key, name in _METRICS.items()}
        return MotScore(
            mota=values["mota"],
            motp=values["motp"],
            fp=int(values["fp"]),
            fn=int(values["fn"]),
            idsw=int(values["idsw"]),
            precision=values["precision"],
            recall=values["recall"],
            frames=int(values["frames"]),
            objects=int(values["objects"]),
            matches=int(values["matches"]),
        )
