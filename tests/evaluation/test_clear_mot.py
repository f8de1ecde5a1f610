"""CLEAR MOT in the ground plane with motmetrics."""

from __future__ import annotations

import numpy as np
import pytest

from optrack.evaluation.clear_mot import ClearMot


def _frame(
    mot: ClearMot,
    gt: dict[int, tuple[float, float]],
    hyp: dict[int, tuple[float, float]],
    counted: set[int] | None = None,
) -> None:
    ids = np.array(list(gt), dtype=np.int64)
    mot.add(
        ids,
        np.array(list(gt.values())).reshape(-1, 2),
        np.array([counted is None or i in counted for i in ids], dtype=bool),
        np.array(list(hyp), dtype=np.int64),
        np.array(list(hyp.values())).reshape(-1, 2),
    )


def test_perfect_tracks_score_one() -> None:
    mot = ClearMot()
    for k in range(10):
        _frame(mot, {1: (k * 0.1, 0.0), 2: (0.0, 3.0)}, {7: (k * 0.1 + 0.1, 0.0), 8: (0.0, 3.0)})
    score = mot.score()
    assert (score.mota, score.fp, score.fn, score.idsw, score.frames) == (1.0, 0, 0, 0, 10)
    assert score.motp == pytest.approx(0.05)  # metres, mean over 20 matches


def test_an_id_swap_is_counted_and_misses_and_false_positives_too() -> None:
    mot = ClearMot()
    _frame(mot, {1: (0.0, 0.0), 2: (2.0, 0.0)}, {7: (0.0, 0.0), 8: (2.0, 0.0)})
    _frame(mot, {1: (0.0, 0.0), 2: (2.0, 0.0)}, {8: (0.0, 0.0), 7: (2.0, 0.0)})  # swap
    _frame(mot, {1: (0.0, 0.0), 2: (2.0, 0.0)}, {8: (0.0, 0.0), 9: (5.0, 5.0)})  # 2 missed
    score = mot.score()
    assert score.idsw == 2
    assert score.fn == 1 and score.fp == 1
    assert score.mota == pytest.approx(1 - (1 + 1 + 2) / 6)


def test_farther_than_half_a_metre_is_not_a_match() -> None:
    mot = ClearMot(radius=0.5)
    _frame(mot, {1: (0.0, 0.0)}, {7: (0.51, 0.0)})
    score = mot.score()
    assert (score.fp, score.fn) == (1, 1)


def test_a_track_on_a_person_nobody_can_see_is_neither_hit_nor_false_positive() -> None:
    mot = ClearMot()
    _frame(mot, {1: (0.0, 0.0), 2: (3.0, 0.0)}, {7: (0.0, 0.0), 8: (3.1, 0.0)}, counted={1})
    _frame(mot, {1: (0.0, 0.0), 2: (3.0, 0.0)}, {7: (0.0, 0.0)}, counted={1})  # not a miss
    score = mot.score()
    assert (score.mota, score.fp, score.fn, score.objects) == (1.0, 0, 0, 2)
