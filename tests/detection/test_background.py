"""Background subtraction: an occupancy voxel map learnt over a time span."""

from __future__ import annotations

import numpy as np

from optrack.detection import PeopleDetector, detection_params
from optrack.detection.background import BackgroundModel

from .conftest import KINECT1


def test_background_is_learnt_for_its_seconds_then_subtracted():
    model = BackgroundModel(0.3, 3.0)
    wall = np.array([[0.0, 0.0, 4.0], [0.5, 0.0, 4.0]])
    assert model.learn(wall, 10.0) and model.learn(wall + [0, 0.5, 0], 11.5)
    assert not model.learn(wall + [3, 3, 0], 13.0)  # 3 s later: done, not added
    assert not model.learning and model.voxels == 4
    person = np.array([[2.0, 0.0, 2.0]])
    mask = model.foreground(np.concatenate([wall + 0.01, person, wall + [3, 3, 0]]))
    assert mask.tolist() == [False, False, True, True, True]


def test_relearning_forgets_the_old_background():
    model = BackgroundModel(0.3, 1.0)
    model.learn(np.array([[0.0, 0.0, 1.0]]), 0.0)
    model.learn(np.array([[0.0, 0.0, 1.0]]), 2.0)
    assert not model.foreground(np.array([[0.0, 0.0, 1.0]]))[0]
    model.relearn()
    assert model.learning and model.voxels == 0
    assert model.foreground(np.array([[0.0, 0.0, 1.0]]))[0]


def test_people_in_the_learnt_background_are_not_detected_until_relearnt(five_people):
    params = detection_params(
        "pcl", overrides={"background_subtraction": True, "background_seconds": 1.0}
    )
    detector = PeopleDetector(params)
    args = (five_people.points, KINECT1, five_people.colors)
    # While learning, frames are still detected (without subtraction).
    assert len(detector.process_cloud(*args, stamp=0.0).detections) == 5
    assert detector.background.learning
    assert detector.process_cloud(*args, stamp=1.0).detections == []  # all background now
    detector.relearn_background()
    assert len(detector.process_cloud(*args, stamp=2.0).detections) == 5
