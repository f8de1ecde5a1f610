"""The skeleton stage's wire messages: a SkeletonBatch and a sensor's person clouds go
through MessagePack and back unchanged, and malformed ones are refused with a reason."""

from __future__ import annotations

import numpy as np
import pytest

from optrack.net.keys import SiteKeys
from optrack.net.messages import (
    MAX_PERSON_POINTS,
    MessageError,
    PersonCloud,
    PersonCloudsMessage,
    SkeletonsMessage,
    decode,
    encode,
)
from optrack.types import Skeleton, SkeletonBatch


def _batch(x: float = 1.0) -> SkeletonBatch:
    skeleton = Skeleton(
        id=4,
        height=1.75,
        state="tracking",
        rate_hz=12.5,
        joints={"head": (x, 2.0, 1.65, 0.9), "pelvis": (1.0, 2.0, 0.95, 0.8)},
    )
    return SkeletonBatch(stamp=1700000000.25, seq=3, skeletons=[skeleton])


def test_skeleton_batches_round_trip():
    message = SkeletonsMessage(batch=_batch(), sender="skeleton")
    back = decode(encode(message), SkeletonsMessage)
    assert back.batch == message.batch
    assert back.batch.skeletons[0].joints["head"] == (1.0, 2.0, 1.65, 0.9)


def test_a_skeleton_with_a_nan_joint_is_refused():
    with pytest.raises(MessageError) as caught:
        decode(encode(SkeletonsMessage(batch=_batch(float("nan")))), SkeletonsMessage)
    assert caught.value.reason == "invalid"


def test_person_clouds_keep_millimetres_around_the_person():
    rng = np.random.default_rng(0)
    world = rng.uniform([5.0, -7.0, 0.0], [5.6, -6.4, 1.8], size=(500, 3))
    centre = np.array([5.3, -6.7, 0.0])
    cloud = PersonCloud(
        x=5.3, y=-6.7, height=1.8, points=(world - centre).astype(np.float16).tobytes()
    )
    message = PersonCloudsMessage(sensor="cam0", stamp=10.0, clouds=[cloud])
    back = decode(encode(message), PersonCloudsMessage)
    assert np.max(np.abs(back.clouds[0].world_points() - world)) < 1e-3
    assert len(encode(message)) < 3200  # 6 bytes a point and a small header


@pytest.mark.parametrize(
    "points",
    [b"\x00" * 7, np.zeros((MAX_PERSON_POINTS + 1, 3), np.float16).tobytes()],
    ids=["not triples", "too many"],
)
def test_malformed_person_clouds_are_refused(points):
    message = PersonCloudsMessage(
        sensor="cam0", stamp=1.0, clouds=[PersonCloud(x=0.0, y=0.0, height=1.7, points=points)]
    )
    with pytest.raises(MessageError) as caught:
        decode(encode(message), PersonCloudsMessage)
    assert caught.value.reason == "invalid"


def test_the_keys():
    keys = SiteKeys("lab")
    assert keys.skeletons == "optrack/lab/skeletons"
    assert keys.person_clouds("cam0") == "optrack/lab/person_clouds/cam0"
    assert keys.person_clouds() == "optrack/lab/person_clouds/*"
