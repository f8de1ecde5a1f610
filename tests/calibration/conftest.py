"""Fixtures of the calibration tests (helpers live in calibration_helpers.py)."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def opencv_data(shared_data: Path) -> Path:
    """OpenCV's real stereo chessboard images (../shared/data/opencv)."""
    folder = shared_data / "opencv"
    if not folder.is_dir():
        pytest.skip(f"OpenCV's chessboard images not found at {folder}")
    return folder


@pytest.fixture(scope="module")
def network():
    """A synthetic network of six cameras: (true world_T_camera, intrinsics)."""
    from optrack.calibration.synthetic import synthetic_session

    session = synthetic_session(6, 10, floor_views=0, seed=3)
    return session.world_T_camera, session.intrinsics
