"""HOG confidence, windows, luminance, infrared equalisation and colour histograms."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from optrack.detection.classifier import (
    HogClassifier,
    equalised_infrared,
    hsv_histogram,
    level_window,
    luminance,
    person_window,
    window_footprint,
)


def test_confidence_is_the_score_opencvs_own_detector_gives(shared_data):
    rng = np.random.default_rng(3)
    classifier = HogClassifier()
    hog = cv2.HOGDescriptor()
    hog.setSVMDetector(cv2.HOGDescriptor_getDefaultPeopleDetector())
    video = cv2.VideoCapture(str(shared_data / "opencv" / "vtest.avi"))
    ok, frame = video.read()
    assert ok
    windows = [np.ascontiguousarray(frame[100:228, 300:364])]
    windows.append(rng.integers(0, 256, (128, 64, 3), dtype=np.uint8))
    ours = classifier.scores(windows)
    for window, score in zip(windows, ours, strict=True):
        _, weights = hog.detect(window, hitThreshold=-100.0)
        assert score == pytest.approx(float(np.ravel(weights)[0]), abs=1e-3)


def window_coordinates(to_image, points, K):
    """Window pixel (u, v) of camera-frame points."""
    pixels = (points @ K.T)[:, :2] / points[:, 2:3]
    back = np.c_[pixels, np.ones(len(pixels))] @ np.linalg.inv(to_image).T
    return back[:, :2] / back[:, 2:3]


@pytest.mark.parametrize("tilt_deg", [0.0, 30.0])
def test_person_stands_upright_in_the_middle_of_the_window_whatever_the_tilt(tilt_deg):
    K = np.array([[365.5, 0, 254.9], [0, 365.5, 205.4], [0, 0, 1.0]])
    t = np.radians(tilt_deg)
    up = np.array([0.0, -np.cos(t), -np.sin(t)])  # the floor's normal, camera frame
    forward = np.cross(up, [1.0, 0, 0])  # horizontal, away from the camera
    foot = 2.6 * -up + 4.0 * forward / np.linalg.norm(forward) + [1.5, 0, 0] @ np.eye(3)
    head = foot + 1.8 * up
    center = foot + 0.9 * up
    to_image = level_window(center, 1.8, up, K, 0.75)
    (hu, hv), (fu, fv), (cu, cv_) = window_coordinates(to_image, np.stack([head, foot, center]), K)
    assert hu == pytest.approx(31.5, abs=1e-6) and fu == pytest.approx(31.5, abs=1e-6)
    assert cv_ == pytest.approx(63.5, abs=1e-6)
    assert fv - hv == pytest.approx(0.75 * 128, abs=1e-6)  # PCL's fill of the window


def test_window_is_black_outside_the_image_and_samples_inside():
    image = np.full((480, 640, 3), 200, np.uint8)
    shift = np.array([[1.0, 0, 100], [0, 1.0, 100], [0, 0, 1]])  # window = pixels 100..
    assert np.all(person_window(image, shift) == 200)
    half_out = person_window(image, np.array([[1.0, 0, -32], [0, 1.0, 0], [0, 0, 1]]))
    assert np.all(half_out[:, :31] == 0) and np.all(half_out[:, 33:] == 200)
    far = np.array([[1.0, 0, 1000], [0, 1.0, 1000], [0, 0, 1]])
    assert np.all(person_window(image, far) == 0)
    assert window_footprint(shift, (480, 640)) == (100, 100, 164, 228)


def test_window_of_a_strided_crop_matches_the_full_image():
    rng = np.random.default_rng(0)
    image = cv2.GaussianBlur(rng.integers(0, 256, (480, 640), dtype=np.uint8), (0, 0), 6)
    scale = np.array([[150 / 64, 0, 100], [0, 300 / 128, 50], [0, 0, 1]])
    full = person_window(image, scale).astype(int)
    crop = image[50:350:2, 100:250:2]
    strided = person_window(crop, scale, origin=(100, 50), stride=2).astype(int)
    assert np.abs(full - strided)[2:-2, 2:-2].mean() < 3


def test_luminance_uses_openptracks_weights():
    image = np.zeros((10, 10, 3), np.uint8)
    image[..., 0], image[..., 1], image[..., 2] = 100, 200, 50
    assert luminance(image) == pytest.approx(0.3 * 100 + 0.59 * 200 + 0.11 * 50)


def test_infrared_is_equalised_to_the_full_range():
    ir = np.tile(np.linspace(1000, 1200, 64, dtype=np.uint16), (48, 1))
    out = equalised_infrared(ir)
    assert out.dtype == np.uint8 and out.min() < 10 and out.max() == 255


def test_histogram_is_normalised_and_peaks_at_the_colour():
    red = np.tile([[200, 10, 10]], (50, 1)).astype(np.uint8)
    hist = hsv_histogram(red, 16, 4)
    assert len(hist) == 64 and sum(hist) == pytest.approx(1.0)
    assert int(np.argmax(hist)) // 4 == 0  # hue bin 0: red
    assert hsv_histogram(np.empty((0, 3), np.uint8), 16, 4) == []
