from __future__ import annotations

import cv2
import numpy as np
import pytest
from calibration_helpers import render, standing_board

from optrack.calibration.board import (
    CORNER_PARAMS,
    BoardError,
    Checkerboard,
    CoverageMap,
    find_corners,
)
from optrack.calibration.printable import board_image
from optrack.calibration.synthetic import look_at
from optrack.geometry import invert, project, transform_points
from optrack.types import Intrinsics


def test_board_is_parsed_from_columns_by_rows_and_metres():
    board = Checkerboard.parse("9x6", 0.025)
    assert (board.cols, board.rows, board.square) == (9, 6, 0.025)
    points = board.object_points
    assert points.shape == (54, 3)
    np.testing.assert_allclose(points[1], [0.025, 0, 0])
    np.testing.assert_allclose(points[9], [0, 0.025, 0])


@pytest.mark.parametrize(
    ("text", "square", "words"),
    [
        ("9-6", 0.025, "COLUMNSxROWS"),
        ("9x6", 0.0, "metres"),
        ("9x6", 25.0, "0.025"),
        ("1x6", 0.1, "2x2"),
    ],
)
def test_bad_board_descriptions_are_refused_in_one_sentence(text, square, words):
    with pytest.raises(BoardError, match=words) as error:
        Checkerboard.parse(text, square)
    message = str(error.value)
    assert message.endswith(".") and message.count("; ") <= 1 and "\n" not in message


def test_a_board_a_half_turn_maps_onto_itself_is_refused_for_networks():
    with pytest.raises(BoardError, match="half turn"):
        Checkerboard(8, 6, 0.1).require_asymmetric()
    Checkerboard(9, 6, 0.1).require_asymmetric()


def test_corners_of_the_printed_pattern_come_in_board_order_whichever_way_up():
    board = Checkerboard(9, 6, 0.03)
    image = board_image(board, px_per_square=30)
    upright = find_corners(image, board)
    turned = find_corners(np.ascontiguousarray(image[::-1, ::-1]), board)
    assert upright is not None and turned is not None
    # Corner 0 sits next to the dark square: one square in from the pattern's corner.
    np.testing.assert_allclose(upright[0], [59.5, 59.5], atol=0.3)
    height, width = image.shape
    flipped_back = np.column_stack([width - 1 - turned[:, 0], height - 1 - turned[:, 1]])
    np.testing.assert_allclose(flipped_back, upright, atol=0.3)


def test_corners_match_the_projection_of_a_rendered_board_to_a_fraction_of_a_pixel():
    board = Checkerboard(6, 5, 0.12)
    k = Intrinsics(250.0, 250.0, 159.5, 119.5, 320, 240)
    camera = look_at(np.array([0.0, -2.5, 1.6]), np.array([0.0, 0.0, 1.2]))
    pose = standing_board(board, np.array([0.1, 0.0, 1.2]), [0.0, -1.0, 0.2])
    infrared, _ = render(board, k, camera, pose, 3)
    corners = find_corners(infrared, board, infrared=True)
    truth, _ = project(transform_points(invert(camera) @ pose, board.object_points), k)
    assert corners is not None
    assert np.sqrt(np.mean(np.sum((corners - truth) ** 2, axis=1))) < 0.25


def test_low_resolution_infrared_board_is_found_after_equalising_and_upsampling():
    # An SR4500-like 176x144 image, dim and 16-bit: the board spans ~12 px squares.
    board = Checkerboard(6, 5, 0.12)
    k = Intrinsics(148.0, 148.0, 87.5, 71.5, 176, 144)
    camera = look_at(np.array([0.0, -2.2, 1.5]), np.array([0.0, 0.0, 1.2]))
    pose = standing_board(board, np.array([0.0, 0.0, 1.2]), [0.0, -1.0, 0.1])
    infrared, _ = render(board, k, camera, pose, 4)
    dim = (infrared.astype(np.uint16) * 12 + 3000).astype(np.uint16)  # low contrast, 16 bit
    truth, _ = project(transform_points(invert(camera) @ pose, board.object_points), k)
    corners = find_corners(dim, board, infrared=True)
    assert corners is not None
    assert np.sqrt(np.mean(np.sum((corners - truth) ** 2, axis=1))) < 0.35
    plain = CORNER_PARAMS.create({"search_width": 0, "infrared_equalize": False})
    without = find_corners(dim, board, plain, infrared=True)
    if without is not None:  # found anyway: the trick must not make it worse
        worse = np.sqrt(np.mean(np.sum((without - truth) ** 2, axis=1)))
        assert np.sqrt(np.mean(np.sum((corners - truth) ** 2, axis=1))) <= worse + 0.05


def test_no_board_gives_none():
    board = Checkerboard(9, 6, 0.025)
    noise = np.random.default_rng(0).integers(0, 255, (240, 320), dtype=np.uint8)
    assert find_corners(cv2.GaussianBlur(noise, (5, 5), 2), board) is None


def test_coverage_map_counts_corners_per_cell_and_the_covered_share():
    coverage = CoverageMap(640, 480, cells=4)
    assert coverage.counts.shape == (3, 4)
    coverage.add(np.array([[10.0, 10.0], [630.0, 470.0], [12.0, 12.0], [-50.0, 10.0]]))
    assert coverage.counts[0, 0] == 2 and coverage.counts[2, 3] == 1
    assert coverage.counts.sum() == 3  # the point outside the image is not counted
    assert coverage.fraction == pytest.approx(2 / 12)
