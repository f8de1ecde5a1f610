"""A person's points in one pass (fusion.person_points) against the plain path it replaces:
world_points then person_mask, to the bit, in the same order."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from optrack.geometry import make_pose
from optrack.skeleton.fusion import FUSION_PARAMS, person_mask, person_points, world_points
from optrack.types import Intrinsics, RGBDFrame


def _frame(rng: np.random.Generator, dtype) -> tuple[RGBDFrame, np.ndarray]:
    """A 120 x 160 depth image (a person-sized slab before a wall, holes, noise) and a
    camera 2.5 m up looking down at the room's middle."""
    metres = np.full((120, 160), 4.0) + rng.normal(0.0, 0.01, (120, 160))
    metres[20:110, 60:100] = 2.6 + rng.normal(0.0, 0.02, (90, 40))  # the person
    metres[rng.random(metres.shape) < 0.05] = 0.0  # holes
    if dtype == np.uint16:
        depth = np.round(metres * 1000).astype(np.uint16)
        scale = 0.001
    else:
        depth = metres.astype(np.float32)
        depth[rng.random(metres.shape) < 0.01] = np.nan
        scale = 1.0
    intrinsics = Intrinsics(fx=120.0, fy=120.0, cx=79.5, cy=59.5, width=160, height=120)
    look = Rotation.from_euler("xyz", [-np.pi / 2 - 0.5, 0.0, rng.uniform(-3, 3)])
    pose = make_pose(look, (0.1, -0.2, 2.5))
    return RGBDFrame(depth, intrinsics, depth_scale=scale), pose


@pytest.mark.parametrize(
    ("dtype", "stride", "jump", "seed"),
    [
        (np.uint16, 1, 0.1, 0),
        (np.uint16, 2, 0.0, 1),
        (np.float32, 1, 0.1, 2),
        (np.float32, 3, 0.05, 3),
    ],
)
def test_person_points_equal_world_points_then_the_mask(dtype, stride, jump, seed):
    rng = np.random.default_rng(seed)
    frame, pose = _frame(rng, dtype)
    params = FUSION_PARAMS.create({"stride": stride, "edge_jump": jump})
    roi = (7, 5, 151, 117)
    world = world_points(frame, pose, stride, roi, jump)
    middle = np.median(world[world[:, 2] > 0.3, :2], axis=0)
    height = float(np.percentile(world[:, 2], 90))
    for others in ((), [middle + (0.3, 0.1), middle - (0.2, 0.4)]):
        expected = world[person_mask(world, middle, height, params, others)]
        found = person_points(frame, pose, roi, middle, height, params, others)
        assert 10 < len(expected) < len(world)
        assert found.dtype == np.float32
        np.testing.assert_array_equal(found, expected)
