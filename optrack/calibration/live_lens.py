"""The intrinsics page's views of one sensor (the live calibration's lens check).

While the page captures, every view in which the board moved is kept
(``calibration_live.intrinsics_min_motion_px``), the image's coverage is counted,
and from ``calibration_intrinsics.min_views`` views on the lens is calibrated
again after each new view (:func:`optrack.calibration.intrinsics.
calibrate_intrinsics`, OpenCV's calibrateCameraExtended): its standard deviations
say whether the lens is good yet (``calibration_intrinsics.good_std_px``) and its
coverage and turns where to show the board next (:meth:`IntrinsicsResult.advice`).
"""

from __future__ import annotations

import dataclasses
import threading

import cv2
import numpy as np

from optrack.calibration.board import CORNER_PARAMS, Checkerboard, CoverageMap
from optrack.calibration.intrinsics import (
    INTRINSICS_PARAMS,
    IntrinsicsResult,
    calibrate_intrinsics,
)
from optrack.calibration.still import corner_motion_px
from optrack.errors import UserError
from optrack.types import Intrinsics

__all__ = ["LensViews"]


@dataclasses.dataclass
class LensViews:
    """One sensor's views of the intrinsics page, their coverage and the lens so far."""

    corners: list[np.ndarray] = dataclasses.field(default_factory=list)
    coverage: CoverageMap | None = None
    lens: IntrinsicsResult | None = None  # from the views so far (None: too few yet)

    def take(self, corners: np.ndarray, intrinsics: Intrinsics, min_motion_px: float) -> bool:
        """Keep a view when the board moved ``min_motion_px`` (RMS) since the last kept
        one; whether it was kept."""
        if self.corners and corner_motion_px(corners, self.corners[-1]) < min_motion_px:
            return False
        self.corners.append(corners)
        if self.coverage is None:
            cells = int(CORNER_PARAMS.defaults()["coverage_cells"])
            self.coverage = CoverageMap(intrinsics.width, intrinsics.height, cells)
        self.coverage.add(corners)
        return True

    def check(self, board: Checkerboard, size: tuple[int, int], lock: threading.RLock) -> None:
        """Calibrate the lens from the views kept so far (enough of them) and keep it
        while no newer view or new start came meanwhile; ``lock`` guards these views and
        is not held while calibrating (the GUI polls the state meanwhile)."""
        with lock:
            views = list(self.corners)
        if len(views) < int(INTRINSICS_PARAMS.defaults()["min_views"]):
            return
        try:
            lens = calibrate_intrinsics(views, board, size)
        except (UserError, cv2.error):  # views that pin nothing down: no check yet
            return
        with lock:
            if len(self.corners) >= len(views) and self.corners[len(views) - 1] is views[-1]:
                self.lens = lens
