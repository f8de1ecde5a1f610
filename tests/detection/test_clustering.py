"""Person candidates in the ground frame: Euclidean clusters, head-based sub-clusters,
height and width limits."""

from __future__ import annotations

import numpy as np
import pytest

from optrack.detection import detection_params
from optrack.detection.clustering import (
    Candidate,
    TallColumns,
    cluster_point_limits,
    euclidean_clusters,
    head_based_subclusters,
    person_candidates,
    tall_columns,
)

PARAMS = detection_params()
STEP = 0.05  # spacing of the synthetic points, about a voxel


def block(x0, x1, y0, y1, z0, z1):
    axes = [np.arange(a, b + 1e-9, STEP) for a, b in ((x0, x1), (y0, y1), (z0, z1))]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def person(x, y, height=1.75, shoulders=0.44):
    """Torso and legs as a box, the head as a narrower box on top (ground frame, z up)."""
    head_from = height - 0.25
    body = block(x - shoulders / 2, x + shoulders / 2, y - 0.12, y + 0.12, 0.1, head_from)
    head = block(x - 0.08, x + 0.08, y - 0.08, y + 0.08, head_from + STEP, height)
    return np.concatenate([body, head])


def test_one_person_is_one_candidate_standing_where_their_head_is():
    candidates = person_candidates(person(0.5, 3.0), PARAMS)
    assert len(candidates) == 1
    (c,) = candidates
    assert c.height == pytest.approx(1.75, abs=0.01)
    np.testing.assert_allclose(c.head, [0.5, 3.0], atol=0.02)
    np.testing.assert_allclose(c.center, [0.5, 3.0, 0.875], atol=0.02)
    assert c.width == pytest.approx(0.44, abs=0.06)


def test_two_people_shoulder_to_shoulder_are_split_at_their_heads():
    together = np.concatenate([person(0.0, 3.0), person(0.45, 3.0, height=1.65)])
    assert len(euclidean_clusters(together, 0.12, 1, 10**6)) == 1  # touching: one cluster
    candidates = sorted(person_candidates(together, PARAMS), key=lambda c: c.head[0])
    assert len(candidates) == 2
    np.testing.assert_allclose(candidates[0].head, [0.0, 3.0], atol=0.05)
    np.testing.assert_allclose(candidates[1].head, [0.45, 3.0], atol=0.05)
    assert candidates[0].height == pytest.approx(1.75, abs=0.01)
    assert candidates[1].height == pytest.approx(1.65, abs=0.01)


def test_heads_closer_than_the_minimum_distance_stay_one_person():
    close = np.concatenate([person(0.0, 3.0), person(0.25, 3.0)])
    assert len(person_candidates(close, PARAMS)) == 1
    split = detection_params(overrides={"heads_minimum_distance": 0.1})
    c = Candidate.from_points(close, 0.125)
    assert len(head_based_subclusters(c, split, cluster_point_limits(split)[0])) == 2


def test_clusters_whose_heads_are_close_on_the_floor_are_merged():
    # A person whose head and body were cut apart (e.g. by an arm's shadow) is one person.
    body = person(1.0, 2.0)
    head = body[body[:, 2] > 1.55] + [0.0, 0.0, 0.1]  # separated by a 0.1 m gap in z... and
    lower = body[body[:, 2] <= 1.3]  # ... a bigger one below: two clusters, heads 0 m apart
    candidates = person_candidates(np.concatenate([head, lower]), PARAMS)
    assert len(candidates) == 1


def test_too_tall_too_short_and_too_small_clusters_are_not_people():
    pillar = block(2.0, 2.3, 1.0, 1.3, 0.1, 2.9)  # reaches above max_height
    child = person(-1.0, 2.0, height=0.9)
    crumb = block(0.0, 0.05, 0.0, 0.05, 1.0, 1.7)  # tall enough, too few points
    adult = person(1.0, 4.0)
    candidates = person_candidates(np.concatenate([pillar, child, crumb, adult]), PARAMS)
    assert [round(c.height, 2) for c in candidates] == [1.75]
    children = detection_params(preset="children")
    heights = sorted(
        round(c.height, 2) for c in person_candidates(np.concatenate([child, adult]), children)
    )
    assert heights == [0.9, 1.75]


def test_a_person_leaning_on_a_tall_cupboard_is_dropped_with_it_as_pcl_does():
    cupboard = block(0.22, 1.0, 3.0, 3.5, 0.1, 2.6)
    leaning = person(0.0, 3.2)
    assert person_candidates(np.concatenate([cupboard, leaning]), PARAMS) == []


def test_a_person_clear_of_a_wall_is_found_and_one_against_it_is_not():
    wall = block(1.0, 1.05, 0.0, 6.0, 0.1, 2.4)  # taller than max_height: never clustered
    clear = person(0.6, 2.0)  # shoulders 0.18 m from the wall: beyond the tolerance
    against = person(0.75, 4.0)  # shoulders 0.03 m from it: joined to it, as PCL would
    candidates = person_candidates(np.concatenate([wall, clear, against]), PARAMS)
    assert [tuple(np.round(c.head, 1)) for c in candidates] == [(0.6, 2.0)]


def test_tall_columns_mark_walls_and_what_touches_them():
    wall = block(1.0, 1.05, 0.0, 1.0, 0.1, 2.4)
    touching = block(0.9, 0.95, 0.4, 0.6, 0.5, 1.0)  # 0.05 m from the wall
    apart = block(0.5, 0.6, 0.4, 0.6, 0.5, 1.0)  # 0.4 m from it
    points = np.concatenate([wall, touching, apart])
    in_tall, near = tall_columns(points, 0.06, 2.3, 0.12)
    n_wall, n_touching = len(wall), len(touching)
    assert in_tall[:n_wall].all() and not in_tall[n_wall:].any()
    assert near[n_wall : n_wall + n_touching].all() and not near[n_wall + n_touching :].any()


def test_tall_columns_found_on_the_points_judge_the_voxels_of_the_rest():
    # As the detector does: the columns from the points, then near() on voxel centroids.
    wall = block(1.0, 1.05, 0.0, 1.0, 0.1, 2.4)
    low = block(0.5, 0.6, 0.4, 0.6, 0.5, 1.0)
    points = np.concatenate([wall, low])
    columns = TallColumns(*points.T.astype(np.float32), 0.06, 2.3, 0.12)
    assert columns.in_tall[: len(wall)].all() and not columns.in_tall[len(wall) :].any()
    voxels = np.array(
        [
            [0.93, 0.5, 0.8],  # 0.07 m from the wall, lower than its bottom + tolerance
            [0.55, 0.5, 0.8],  # 0.45 m from it
            [0.93, 0.5, -0.5],  # next to it but far below its lowest point
            [9.0, 9.0, 1.0],  # off the grid of columns
        ]
    )
    assert columns.near(voxels).tolist() == [True, False, False, False]
    floor_only = TallColumns(*low.T, 0.06, 2.3, 0.12)  # nothing above max_height
    assert not floor_only.in_tall.any() and not floor_only.near(voxels).any()


def test_width_limits_apply():
    narrow = detection_params(overrides={"max_width": 0.3})
    assert person_candidates(person(0.0, 3.0), narrow) == []


def test_point_limits_follow_pcl():
    assert cluster_point_limits(detection_params("pcl")) == (36, 5111)


def test_euclidean_clusters_keep_only_sizes_within_limits():
    rng = np.random.default_rng(0)
    a = rng.uniform(0, 0.3, (100, 3))
    b = rng.uniform(0, 0.3, (20, 3)) + 5.0
    clusters = euclidean_clusters(np.concatenate([a, b]), 0.12, 30, 1000)
    assert [len(c) for c in clusters] == [100]
    assert euclidean_clusters(np.empty((0, 3)), 0.12, 1, 10) == []
