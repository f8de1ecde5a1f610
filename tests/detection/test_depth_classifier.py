"""The depth-only person classifier: real Kinect frames no one here rendered, its file,
its use by the detector, and its training command."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from optrack.bench.detection import PCL_PEOPLE_XZ, match_people
from optrack.cli import main
from optrack.detection import PeopleDetector, detection_params
from optrack.detection.classifier import HogClassifier
from optrack.detection.depth_classifier import (
    DESCRIPTOR_SIZE,
    DepthClassifier,
    default_depth_classifier,
    relative_depth,
)
from optrack.errors import UserError
from optrack.types import Intrinsics, RGBDFrame

from .conftest import KINECT1

#: The grabber sequences' intrinsics (pclzf/*.xml).
GRABBER = Intrinsics(525.0, 525.0, 320.0, 240.0, 640, 480)


def _xz(batch) -> np.ndarray:
    return np.array([(d.camera_xyz[0], d.camera_xyz[2]) for d in batch.detections]).reshape(-1, 2)


@pytest.mark.parametrize("model", ["pcl", "kinect1", "kinect2"])
def test_five_people_without_colour_are_the_five_found_with_it(five_people, model):
    with_colour = PeopleDetector(detection_params(model, overrides={"minimum_luminance": 0}))
    colour = with_colour.process_cloud(five_people.points, KINECT1, five_people.colors)
    assert {j.source for j in with_colour.last_judgements} == {"color"}
    assert len(colour.detections) == 5
    depth_only = PeopleDetector(detection_params(model))
    batch = depth_only.process_cloud(five_people.points, KINECT1)  # colour removed
    assert {j.source for j in depth_only.last_judgements} == {"depth"}
    assert len(batch.detections) == 5
    matched, worst = match_people(_xz(batch), _xz(colour))
    assert matched == 5 and worst < 0.2, worst
    assert match_people(_xz(batch), np.array(PCL_PEOPLE_XZ))[0] == 5
    # Every person clears the threshold, and every other candidate (things 4.8 m away
    # behind them) stays below it, each by a margin (log-odds).
    threshold = float(depth_only.params.min_depth_model_confidence)
    for judgement in depth_only.last_judgements:
        assert abs(judgement.confidence - threshold) > 0.75, judgement.confidence


@pytest.mark.parametrize("model", ["pcl", "kinect1", "kinect2"])
def test_empty_office_without_colour_has_nobody(office, model):
    detector = PeopleDetector(detection_params(model))
    assert detector.process_cloud(office.points, KINECT1).detections == []
    assert detector.last_judgements  # a candidate was judged, and refused
    threshold = float(detector.params.min_depth_model_confidence)
    assert all(j.source == "depth" for j in detector.last_judgements)
    assert all(j.confidence < threshold - 0.75 for j in detector.last_judgements)


def test_grabber_frames_give_the_same_people_with_and_without_colour(shared_data):
    # A laptop and a box on the floor, seen from above (a steep camera).
    frames = sorted((shared_data / "pcl" / "grabber_sequences" / "tiff").glob("*_depth.tiff"))
    assert len(frames) == 3
    params = {"ground_max_tilt": 85.0, "minimum_luminance": 0}
    for path in frames:
        depth = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        rgb = cv2.cvtColor(cv2.imread(str(path).replace("_depth", "_rgb")), cv2.COLOR_BGR2RGB)
        found = []
        for color in (rgb, None):
            detector = PeopleDetector(detection_params("kinect1", overrides=params))
            batch = detector.process(RGBDFrame(depth, GRABBER, depth_scale=0.001, color=color))
            assert detector.ground.plane is not None
            found.append(_xz(batch))
        assert len(found[0]) == len(found[1]) == 0


def test_depth_only_judgement_uses_the_trained_model_and_its_threshold(five_people):
    detector = PeopleDetector(detection_params("pcl"))
    detector.process_cloud(five_people.points, KINECT1)
    model = default_depth_classifier()
    for judgement in detector.last_judgements:
        silhouette, relative = judgement.windows[0]
        assert relative is not None
        assert judgement.confidence >= model.score(silhouette, relative) - 1e-9
    strict = PeopleDetector(detection_params("pcl", overrides={"min_depth_model_confidence": 20}))
    assert strict.process_cloud(five_people.points, KINECT1).detections == []
    # depth_classifier hog: OpenCV's people detector on the silhouette, as before
    hog = PeopleDetector(detection_params("pcl", overrides={"depth_classifier": "hog"}))
    hog.process_cloud(five_people.points, KINECT1)
    people = HogClassifier()
    for judgement in hog.last_judgements:
        silhouette, relative = judgement.windows[0]
        assert relative is None
        assert judgement.confidence >= people.score(silhouette) - 1e-9


def test_relative_depth_is_grey_at_the_persons_depth_dark_in_front_light_behind():
    z = np.array([[2.0, 2.0, 1.0, np.nan, 5.0, 2.3]], dtype=np.float32)
    mask = np.array([[True, True, False, False, False, False]])
    assert relative_depth(z, mask).tolist() == [[127, 127, 0, 255, 255, 191]]
    assert relative_depth(z, np.zeros_like(mask)).tolist() == [[255] * 6]


def test_model_file_round_trip_and_foreign_files_are_refused(tmp_path):
    rng = np.random.default_rng(0)
    model = DepthClassifier(rng.normal(size=DESCRIPTOR_SIZE), 0.5, {"threshold": 1.0})
    model.save(tmp_path / "m.npz")
    again = DepthClassifier.load(tmp_path / "m.npz")
    np.testing.assert_allclose(again.weights, model.weights.astype(np.float32))
    assert again.bias == 0.5 and again.info["threshold"] == 1.0
    with pytest.raises(UserError, match="does not exist"):
        DepthClassifier.load(tmp_path / "none.npz")
    (tmp_path / "bad.npz").write_bytes(b"not a model")
    with pytest.raises(UserError, match="not a model written by 'optrack train"):
        DepthClassifier.load(tmp_path / "bad.npz")
    np.savez(tmp_path / "old.npz", weights=np.zeros(3780), bias=0.0, info=json.dumps({}))
    with pytest.raises(UserError, match="train it again"):
        DepthClassifier.load(tmp_path / "old.npz")
    with pytest.raises(UserError, match="weights"):
        DepthClassifier(np.zeros(10), 0.0)


def test_shipped_model_is_small_and_says_how_it_was_made():
    model = default_depth_classifier()
    assert len(model.weights) == DESCRIPTOR_SIZE
    assert model.info["test"]["recall"] > 0.7 and model.info["test"]["precision"] > 0.98


def test_train_command_writes_a_model_with_held_out_scores(tmp_path, capsys):
    out = tmp_path / "depth.npz"
    argv = ["train", "depth-classifier", "--out", str(out), "--scenes", "3", "--seconds", "1"]
    assert main([*argv, "--every", "6", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["seeds"] == [1000, 1001, 1002] and report["out"] == str(out)
    for part in ("train", "validation", "test"):
        assert report[part]["windows"] > 0 and report[part]["people"] > 0
    assert report["test"]["recall"] is not None
    model = DepthClassifier.load(out)
    assert model.info["threshold"] == report["threshold"]


def test_a_trained_file_is_used_through_the_depth_model_parameter(tmp_path, five_people):
    rng = np.random.default_rng(1)
    model = DepthClassifier(rng.normal(size=DESCRIPTOR_SIZE), -0.5)
    model.save(tmp_path / "mine.npz")
    params = detection_params("pcl", overrides={"depth_model": str(tmp_path / "mine.npz")})
    detector = PeopleDetector(params)
    detector.process_cloud(five_people.points, KINECT1)
    assert detector.last_judgements
    for judgement in detector.last_judgements:
        assert judgement.confidence >= model.score(*judgement.windows[0]) - 1e-6


def test_train_command_refuses_too_few_scenes_in_one_sentence(tmp_path, capsys):
    argv = ["train", "depth-classifier", "--out", str(tmp_path / "m.npz"), "--scenes", "2"]
    assert main(argv) != 0
    err = capsys.readouterr().err
    assert "at least 3 scenes" in err and "Traceback" not in err
