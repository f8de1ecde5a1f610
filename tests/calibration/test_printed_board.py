"""The corner finder against the truth: rendered views of a replica of OpenCV's sample board.

OpenCV's own calibration of its left*.jpg (left_intrinsics.yml: fx 535.92, the issue's
reference 536.1) and ours (533.2) differ by 0.55 %. These tests render the sample board
as printed (outer columns cut to half a square, measured on the real views) through
left_intrinsics.yml's own camera, distortion and 13 board poses, so that the true fx is
OpenCV's, and ask both corner methods for it.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from optrack.calibration.board import (
    CORNER_PARAMS,
    OPENCV_SAMPLE_CORNERS,
    Checkerboard,
    find_corners,
)
from optrack.calibration.intrinsics import INTRINSICS_PARAMS, calibrate_intrinsics
from optrack.calibration.printed import opencv_sample_replica

BOARD = Checkerboard(9, 6, 0.025)


@pytest.fixture(scope="module")
def replica(opencv_data):
    return opencv_sample_replica(opencv_data, supersample=2)


def test_the_replica_looks_like_the_real_views_to_the_corner_finder(replica, opencv_data):
    """Same camera, same poses: the board is found in all 13 rendered views, at the corners
    OpenCV's file says the real views have (within its 0.39 px RMS)."""
    images = replica.images
    assert len(images) == 13 and images[0].shape == (480, 640) and images[0].dtype == np.uint8
    found = [find_corners(image, BOARD) for image in images]
    assert all(c is not None for c in found)
    real = find_corners(cv2.imread(str(opencv_data / "left01.jpg")), BOARD)
    assert np.median(replica.corner_errors(0, real)) < 0.6


def test_default_corners_recover_the_true_focal_length_and_opencvs_window_inflates_it(replica):
    images, fx, size = replica.images, replica.fx, replica.size
    opencv_sample = CORNER_PARAMS.create(OPENCV_SAMPLE_CORNERS)
    clean = [find_corners(image, BOARD) for image in images]
    pulled = [find_corners(image, BOARD, opencv_sample) for image in images]
    # The default corners are within a fraction of a pixel of the truth everywhere.
    assert max(replica.corner_errors(k, c).max() for k, c in enumerate(clean)) < 0.5
    # OpenCV's 11-px window reaches the cut squares of left02 (index 1): its border corners
    # move by pixels, as in the real view (6.3 px), and the inner ones do not.
    left02 = replica.corner_errors(1, pulled[1])
    assert left02.max() > 3.0 and np.median(left02) < 0.3
    keep_all = INTRINSICS_PARAMS.create({"fix_aspect_ratio": True, "max_rejection_rounds": 0})
    ours = calibrate_intrinsics(clean, BOARD, size, keep_all)
    opencv = calibrate_intrinsics(pulled, BOARD, size, keep_all)
    assert abs(ours.intrinsics.fx - fx) / fx < 0.001
    assert ours.rms < 0.15 and max(ours.per_view_rms) < 0.25
    # As OpenCV made left_intrinsics.yml (every view kept): fx too high by more than the
    # 0.55 % that separates its figure on the real views from ours, left02 its worst view.
    assert (opencv.intrinsics.fx - fx) / fx > 0.0055
    assert int(np.argmax(opencv.per_view_rms)) == 1 and opencv.per_view_rms[1] > 1.0
