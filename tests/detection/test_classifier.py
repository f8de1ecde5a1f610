"""HOG confidence, windows, luminance, infrared equalisation and colour histograms."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from optrack.detection.classifier import (
    HogClassifier,
    equalised_infrared,
    hsv_histogram,
    luminance,
    person_window,
    window_geometry,
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


def test_window_follows_pcls_geometry():
    # A person 300 px tall centred at (320, 240): window 400 px tall, 200 wide.
    box = window_geometry(np.array([320, 90]), np.array([320, 390]), np.array([320, 240]), 0.75)
    assert box == (220, 40, 200, 400)


def test_window_is_black_outside_the_image_and_samples_inside():
    image = np.full((480, 640, 3), 200, np.uint8)
    inside = person_window(image, (100, 100, 64, 128))
    assert inside.shape == (128, 64, 3) and np.all(inside == 200)
    half_out = person_window(image, (-32, 0, 64, 128))
    assert np.all(half_out[:, :31] == 0) and np.all(half_out[:, 33:] == 200)
    assert np.all(person_window(image, (1000, 1000, 64, 128)) == 0)


def test_window_of_a_strided_crop_matches_the_full_image():
    rng = np.random.default_rng(0)
    image = cv2.GaussianBlur(rng.integers(0, 256, (480, 640), dtype=np.uint8), (0, 0), 6)
    box = (100, 50, 150, 300)
    full = person_window(image, box).astype(int)
    crop = image[50:350:2, 100:250:2]
    strided = person_window(crop, box, origin=(100, 50), stride=2).astype(int)
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
