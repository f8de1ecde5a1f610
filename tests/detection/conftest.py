"""Real frames shared by the detection tests (read once per session)."""

from __future__ import annotations

import pytest

from optrack.io.pcd import PointCloudData, read_pcd
from optrack.types import Intrinsics

#: PCL's unit test: Kinect v1 intrinsics of five_people.pcd and office1.pcd.
KINECT1 = Intrinsics(525.0, 525.0, 319.5, 239.5, 640, 480)


@pytest.fixture(scope="session")
def five_people(shared_data) -> PointCloudData:
    return read_pcd(shared_data / "pcl" / "five_people.pcd")


@pytest.fixture(scope="session")
def office(shared_data) -> PointCloudData:
    return read_pcd(shared_data / "pcl" / "office1.pcd")
