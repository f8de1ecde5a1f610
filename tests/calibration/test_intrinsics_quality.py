"""How well a lens is known from its views (the intrinsics page's lens check): OpenCV's
standard deviations of fx, fy, cx, cy (calibrateCameraExtended) decide whether the lens
is good (calibration_intrinsics.good_std_px), and the views' corners per image region
and turns say in one sentence where the board is still missing. Views are projected
with a known lens (the simulated Kinect v2's colour image) plus corner noise."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from optrack.calibration.board import Checkerboard
from optrack.calibration.intrinsics import REGIONS, TURNS, calibrate_intrinsics
from optrack.calibration.live_session import LiveSession
from optrack.net.messages import BoardViewMessage
from optrack.types import Intrinsics

BOARD = Checkerboard(6, 5, 0.15)
LENS = Intrinsics(fx=365.5, fy=365.5, cx=254.9, cy=205.4, width=512, height=424)
SIZE = (LENS.width, LENS.height)
NOISE_PX = 0.07  # the simulated sensors' corners reproject at about this RMS


def view(u: float, v: float, distance: float, turn_deg: float, tilt_deg: float, rng) -> np.ndarray:
    """The board's corners with its centre at pixel (u, v), ``distance`` m away, turned
    about the camera's vertical axis and tilted about its horizontal one."""
    rotation = cv2.Rodrigues(np.radians([tilt_deg, 0.0, 0.0]))[0]
    rotation = cv2.Rodrigues(np.radians([0.0, turn_deg, 0.0]))[0] @ rotation
    centre = np.array([(u - LENS.cx) / LENS.fx, (v - LENS.cy) / LENS.fy, 1.0]) * distance
    points = (BOARD.object_points - BOARD.object_points.mean(axis=0)) @ rotation.T + centre
    pixels = points[:, :2] / points[:, 2:] * [LENS.fx, LENS.fy] + [LENS.cx, LENS.cy]
    return pixels + rng.normal(0.0, NOISE_PX, pixels.shape)


def spread_views(rng, count: int = 45) -> list[np.ndarray]:
    """Views all over the image, turned and tilted up to 40 degrees each way."""
    views = []
    for k in range(count):
        u = 110 + 290 * ((k * 7) % 9) / 8
        v = 110 + 200 * ((k * 5) % 7) / 6
        views.append(view(u, v, 1.8 + 0.4 * (k % 3), 40 * np.sin(k), 35 * np.cos(1.7 * k), rng))
    return views


def test_views_in_one_corner_facing_the_camera_are_not_good_and_the_advice_says_where():
    rng = np.random.default_rng(0)
    views = [view(400 + 14 * k, 370 - 10 * k, 4.0 + 0.05 * k, 3 * k, 0.0, rng) for k in range(6)]
    result = calibrate_intrinsics(views, BOARD, SIZE)
    assert not result.good and result.uncertainty_px > result.wanted_std_px
    # every corner is in the bottom-right region; no view is turned or tilted
    assert result.regions[2, 2] == 6 * BOARD.count and result.regions.sum() == 6 * BOARD.count
    assert result.turns == (0, 0, 0, 0)
    advice = result.advice("cam0")
    assert advice.startswith(f"Show the board near the {REGIONS[0][0]} of cam0's image, {TURNS[0]}")
    assert advice.endswith("good from 0.5 px.")
    assert result.as_dict()["good"] is False


def test_turns_are_named_as_the_camera_sees_the_board():
    rng = np.random.default_rng(1)
    views = [
        view(256, 212, 3.0, 40, 0, rng),  # the face looks towards the image's left
        view(256, 212, 3.0, -40, 0, rng),
        view(256, 212, 3.0, 0, -40, rng),  # the face looks up
        view(256, 212, 3.0, 0, 40, rng),
        view(256, 212, 3.0, 40, 40, rng),
    ]
    result = calibrate_intrinsics(views, BOARD, SIZE)
    assert dict(zip(TURNS, result.turns, strict=True)) == {
        "turned left": 2,
        "turned right": 1,
        "tilted up": 1,
        "tilted down": 2,
    }


def test_views_all_over_the_image_turned_many_ways_make_the_lens_good_and_its_spread_honest():
    """Good: fx, fy, cx, cy within good_std_px; over noise draws, the true lens is within
    three of OpenCV's standard deviations of the estimate."""
    errors = []
    for seed in range(6):
        result = calibrate_intrinsics(spread_views(np.random.default_rng(seed)), BOARD, SIZE)
        assert result.good, result.std_px
        k = result.intrinsics
        error = np.array([k.fx - LENS.fx, k.fy - LENS.fy, k.cx - LENS.cx, k.cy - LENS.cy])
        errors.append(np.abs(error) / np.array(result.std_px))
    assert np.max(errors) < 3.0
    assert result.advice("cam0").startswith("cam0's lens is good")
    assert result.as_dict()["std_px"]["cx"] == pytest.approx(result.std_px[2])


def test_the_live_session_checks_the_lens_after_each_view_and_says_where_to_show_the_board():
    """The intrinsics page's backend: from calibration_intrinsics.min_views views on, the
    state carries the lens so far and the page's sentence is its advice; once the views
    pin the lens down, the sentence says it is good."""
    session = LiveSession(BOARD, ["cam0", "cam1"])
    session.begin("intrinsics", "cam0")
    rng = np.random.default_rng(2)
    corner = [view(400 + 14 * k, 370 - 10 * k, 4.0 + 0.05 * k, 3 * k, 0.0, rng) for k in range(6)]

    def send(corners: np.ndarray, seq: int, sensor: str = "cam0") -> None:
        session.take_view(
            BoardViewMessage(
                sensor=sensor,
                stamp=float(seq),
                phase="intrinsics",
                seq=seq,
                image="color",
                intrinsics=LENS,
                corners=[(float(x), float(y)) for x, y in corners],
            )
        )

    for seq, corners in enumerate(corner[:3]):
        send(corners, seq)
    assert session.state().sensors["cam0"].lens is None  # too few views to check
    for seq, corners in enumerate(corner[3:], start=3):
        send(corners, seq)
        send(corners, seq, "cam1")  # the other sensor's views are not this page's
    state = session.state()
    lens = state.sensors["cam0"].lens
    assert lens is not None and not lens.good and state.sensors["cam0"].views == 6
    assert state.message == lens.advice("cam0") and "top-left corner" in state.message
    for seq, corners in enumerate(spread_views(rng), start=10):
        send(corners, seq)
    state = session.state()
    assert state.sensors["cam0"].lens.good
    assert state.message.startswith("cam0's lens is good")
    result = session.calibrate_intrinsics("cam0", lambda fraction, sentence: None)
    assert result.good and len(result.used) == 6 + 45
    session.begin("intrinsics", "cam0")  # starting over forgets the views and the check
    assert session.state().sensors["cam0"].lens is None
