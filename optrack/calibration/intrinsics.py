"""Intrinsics of one camera from checkerboard views (OpenCV's calibrateCamera).

Each view's reprojection RMS is measured; views much worse than the others
(a blurred image, a corner snapped to the wrong place) are rejected and the
camera is calibrated again without them.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np
import yaml

from optrack.calibration.board import (
    CORNER_PARAMS,
    Checkerboard,
    CoverageMap,
    find_corners,
)
from optrack.errors import UserError
from optrack.io.files import atomic_write_text
from optrack.params import Param, Params, Schema, register
from optrack.types import Intrinsics

__all__ = [
    "INTRINSICS_PARAMS",
    "REGIONS",
    "TURNS",
    "IntrinsicsResult",
    "calibrate_intrinsics",
    "corners_from_images",
]

INTRINSICS_PARAMS = register(
    Schema(
        "calibration_intrinsics",
        [
            Param(
                "distortion_model",
                "k1k2p1p2k3",
                choices=("k1k2p1p2", "k1k2p1p2k3", "rational"),
                help="OpenCV distortion coefficients to estimate: 4, 5 (default) or the "
                "8-coefficient rational model for wide lenses.",
            ),
            Param("fix_aspect_ratio", False, help="Estimate one focal length (fx = fy)."),
            Param(
                "zero_tangential",
                False,
                help="Assume no tangential distortion (p1 = p2 = 0).",
            ),
            Param(
                "min_views",
                4,
                min=3,
                max=1000,
                step=1,
                help="Fewest board views to calibrate from (also the fewest kept after "
                "rejecting bad views).",
            ),
            Param(
                "reject_factor",
                3.0,
                min=1.0,
                max=100.0,
                step=0.5,
                help="A view is rejected when its RMS is this many times the median view's.",
            ),
            Param(
                "reject_min_px",
                0.5,
                min=0.0,
                max=50.0,
                step=0.1,
                unit="px",
                help="...and above this many pixels (good views are never rejected).",
            ),
            Param(
                "good_std_px",
                0.5,
                min=0.01,
                max=50.0,
                step=0.05,
                unit="px",
                help="The lens counts as good once its focal lengths and image centre are each "
                "pinned down to this many pixels (one standard deviation, from how well the "
                "views agree); until then the intrinsics page asks for more views and says "
                "where.",
            ),
            Param(
                "tilt_deg",
                20.0,
                min=1.0,
                max=80.0,
                step=1.0,
                unit="deg",
                help="A view counts as turned (left, right) or tilted (up, down) when the "
                "board's face is this far from looking straight at the camera.",
            ),
            Param(
                "max_rejection_rounds",
                3,
                min=0,
                max=20,
                step=1,
                help="Rounds of rejecting bad views and calibrating again.",
            ),
        ],
        help="Intrinsic calibration of one camera from checkerboard views.",
    )
)


class IntrinsicsError(UserError):
    """Intrinsics that cannot be computed from the given views."""


#: The image's regions the intrinsics page names when it asks for the board somewhere
#: (rows top to bottom, as the camera sees it).
REGIONS = (
    ("top-left corner", "top edge", "top-right corner"),
    ("left edge", "centre", "right edge"),
    ("bottom-left corner", "bottom edge", "bottom-right corner"),
)
#: The ways a view is turned, as the camera sees the board's face.
TURNS = ("turned left", "turned right", "tilted up", "tilted down")


@dataclasses.dataclass
class IntrinsicsResult:
    """Intrinsics, reprojection RMS (px) over the kept views, and what was kept; how well
    the views pin the lens down (OpenCV's standard deviations of fx, fy, cx, cy) and
    where the kept views put the board (corners per image region, views per turn)."""

    intrinsics: Intrinsics
    rms: float
    per_view_rms: list[float]  # one per kept view, px
    used: list[int]  # indices of kept views in the input
    rejected: list[int]  # indices of rejected views
    coverage: CoverageMap
    std_px: tuple[float, float, float, float] = (math.nan,) * 4  # fx, fy, cx, cy
    wanted_std_px: float = 0.5  # calibration_intrinsics.good_std_px when it was made
    regions: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((3, 3), int))
    turns: tuple[int, ...] = (0,) * len(TURNS)  # kept views turned each way of TURNS

    @property
    def uncertainty_px(self) -> float:
        """The largest standard deviation of fx, fy, cx, cy (px; inf when unknown)."""
        values = [v for v in self.std_px if math.isfinite(v)]
        return max(values) if len(values) == len(self.std_px) else math.inf

    @property
    def good(self) -> bool:
        """Whether the views pin the lens down to ``wanted_std_px`` (the lens is good)."""
        return self.uncertainty_px <= self.wanted_std_px

    def advice(self, sensor: str) -> str:
        """One sentence for the operator: the lens is good, or where to show the board
        next (the image region with the fewest corners, the way the fewest views turn)."""
        if self.good:
            return (
                f"{sensor}'s lens is good: focal lengths and image centre known within "
                f"{self.uncertainty_px:.2f} px "
                "(calibrate it now; more views do no harm)."
            )
        row, col = np.unravel_index(int(np.argmin(self.regions)), self.regions.shape)
        turn = TURNS[int(np.argmin(self.turns))]
        uncertain = (
            f"known to {self.uncertainty_px:.2f} px"
            if math.isfinite(self.uncertainty_px)
            else "not known yet"
        )
        return (
            f"Show the board near the {REGIONS[row][col]} of {sensor}'s image, {turn}: "
            f"the lens is {uncertain}, good from {self.wanted_std_px:g} px."
        )

    def as_dict(self, labels: Sequence[str] | None = None) -> dict[str, object]:
        k = self.intrinsics

        def name(i: int) -> object:
            return labels[i] if labels is not None else i

        return {
            "fx": k.fx,
            "fy": k.fy,
            "cx": k.cx,
            "cy": k.cy,
            "dist": list(k.dist),
            "width": k.width,
            "height": k.height,
            "rms": self.rms,
            "views": len(self.used),
            "rejected": [name(i) for i in self.rejected],
            "per_view_rms": {
                str(name(i)): e for i, e in zip(self.used, self.per_view_rms, strict=True)
            },
            "coverage": self.coverage.fraction,
            "std_px": dict(zip(("fx", "fy", "cx", "cy"), self.std_px, strict=True)),
            "good": self.good,
            "coverage_map": self.coverage.as_lists(),  # corners per cell, rows top to bottom
        }

    def describe(self, labels: Sequence[str]) -> str:
        """One line for the operator: the intrinsics, the RMS, the views rejected (by their
        ``labels``) and the image's coverage."""
        k = self.intrinsics
        rejected = ", ".join(labels[i] for i in self.rejected)
        return (
            f"fx={k.fx:.2f} fy={k.fy:.2f} cx={k.cx:.2f} cy={k.cy:.2f} dist={[round(float(v), 5) for v in k.dist]} "
            f"RMS {self.rms:.3f} px over {len(self.used)} views"
            + (f"; rejected {rejected}" if self.rejected else "")
            + f"; coverage {self.coverage.fraction:.0%} of the image; "
            + ("good" if self.good else "not good yet")
            + f" (fx, fy, cx, cy known to {self.uncertainty_px:.2f} px)"
        )

    def save(self, path: str | os.PathLike[str]) -> None:
        """The intrinsics, their RMS and the views used, as a small YAML file."""
        k = self.intrinsics
        fields = {
            "fx": k.fx,
            "fy": k.fy,
            "cx": k.cx,
            "cy": k.cy,
            "width": k.width,
            "height": k.height,
            "dist": list(k.dist),
            "rms_px": self.rms,
            "views": len(self.used),
        }
        atomic_write_text(path, yaml.safe_dump(fields, sort_keys=False))


def _flags(p: Params) -> int:
    flags = 0
    if p.distortion_model == "k1k2p1p2":
        flags |= cv2.CALIB_FIX_K3
    elif p.distortion_model == "rational":
        flags |= cv2.CALIB_RATIONAL_MODEL
    if p.fix_aspect_ratio:
        flags |= cv2.CALIB_FIX_ASPECT_RATIO
    if p.zero_tangential:
        flags |= cv2.CALIB_ZERO_TANGENT_DIST
    return flags


@dataclasses.dataclass
class _Solution:
    """One cv2.calibrateCameraExtended over some views."""

    rms: float
    camera: np.ndarray
    dist: np.ndarray
    per_view: np.ndarray  # RMS of each view, px
    std: np.ndarray  # standard deviations of fx, fy, cx, cy, px
    rotations: list[np.ndarray]  # camera_R_board of each view


def _calibrate(
    corners: Sequence[np.ndarray], board: Checkerboard, size: tuple[int, int], flags: int
) -> _Solution:
    objects = [board.object_points.astype(np.float32)] * len(corners)
    images = [c.reshape(-1, 1, 2).astype(np.float32) for c in corners]
    camera = np.eye(3)
    rms, camera, dist, rvecs, _, std, _, per_view = cv2.calibrateCameraExtended(
        objects, images, size, camera, None, flags=flags
    )
    count = 8 if flags & cv2.CALIB_RATIONAL_MODEL else 5  # OpenCV pads to 14
    return _Solution(
        float(rms),
        camera,
        dist.ravel()[:count],
        per_view.ravel(),
        std.ravel()[:4],
        [cv2.Rodrigues(r)[0] for r in rvecs],
    )


def _turns(rotations: Sequence[np.ndarray], tilt_deg: float) -> tuple[int, ...]:
    """Views turned each way of :data:`TURNS`: the board face's direction in the camera
    (x right, y down) at least ``tilt_deg`` off the line of sight."""
    counts = [0] * len(TURNS)
    limit = math.sin(math.radians(tilt_deg))
    for rotation in rotations:
        face = -rotation[:, 2] * (1.0 if rotation[2, 2] > 0 else -1.0)  # towards the camera
        for k, turned in enumerate((face[0] < -limit, face[0] > limit)):
            counts[k] += bool(turned)
        for k, tilted in enumerate((face[1] < -limit, face[1] > limit)):
            counts[2 + k] += bool(tilted)
    return tuple(counts)


def _regions(corners: Sequence[np.ndarray], width: int, height: int) -> np.ndarray:
    """Corners in each region of :data:`REGIONS` (3x3 counts, rows top to bottom)."""
    counts = np.zeros((3, 3), dtype=np.int64)
    for view in corners:
        points = np.asarray(view, dtype=np.float64).reshape(-1, 2)
        col = np.clip((points[:, 0] + 0.5) * 3 // width, 0, 2).astype(int)
        row = np.clip((points[:, 1] + 0.5) * 3 // height, 0, 2).astype(int)
        np.add.at(counts, (row, col), 1)
    return counts


def calibrate_intrinsics(
    corners: Sequence[np.ndarray],
    board: Checkerboard,
    image_size: tuple[int, int],
    params: Params | None = None,
) -> IntrinsicsResult:
    """Calibrate from the corners of several views of ``board``.

    ``corners``: one Nx2 array per view (pixels, board order); ``image_size``
    is (width, height). Views whose reprojection RMS is above both
    ``reject_factor`` x the median and ``reject_min_px`` are dropped, worst
    first, and the camera is calibrated again.
    """
    p = params if params is not None else INTRINSICS_PARAMS.create()
    width, height = image_size
    if len(corners) < p.min_views:
        raise IntrinsicsError(
            f"intrinsics need at least {p.min_views} views of the {board.cols}x{board.rows} "
            f"board; only {len(corners)} were found. Show the board in more images."
        )
    flags = _flags(p)
    used = list(range(len(corners)))
    rejected: list[int] = []
    solution = _calibrate([corners[i] for i in used], board, image_size, flags)
    for _ in range(int(p.max_rejection_rounds)):
        per_view = solution.per_view
        threshold = max(p.reject_factor * float(np.median(per_view)), p.reject_min_px)
        bad = [i for i, e in zip(used, per_view, strict=True) if e > threshold]
        if not bad or len(used) - len(bad) < p.min_views:
            break
        rejected += bad
        used = [i for i in used if i not in bad]
        solution = _calibrate([corners[i] for i in used], board, image_size, flags)
    camera = solution.camera
    coverage = CoverageMap(width, height, int(CORNER_PARAMS.defaults()["coverage_cells"]))
    for i in used:
        coverage.add(corners[i])
    intrinsics = Intrinsics(
        fx=float(camera[0, 0]),
        fy=float(camera[1, 1]),
        cx=float(camera[0, 2]),
        cy=float(camera[1, 2]),
        width=width,
        height=height,
        dist=tuple(float(v) for v in solution.dist),
    )
    std = tuple(float(v) for v in solution.std)
    return IntrinsicsResult(
        intrinsics=intrinsics,
        rms=solution.rms,
        per_view_rms=[float(e) for e in solution.per_view],
        used=used,
        rejected=sorted(rejected),
        coverage=coverage,
        std_px=(std[0], std[1], std[2], std[3]),
        wanted_std_px=float(p.good_std_px),
        regions=_regions([corners[i] for i in used], width, height),
        turns=_turns(solution.rotations, float(p.tilt_deg)),
    )


def corners_from_images(
    paths: Sequence[str | os.PathLike[str]],
    board: Checkerboard,
    *,
    infrared: bool = False,
    params: Params | None = None,
) -> tuple[list[np.ndarray | None], tuple[int, int]]:
    """Corners found in each image file (None where the board is not found) and the
    image size (width, height), which must be the same for all images."""
    results: list[np.ndarray | None] = []
    size: tuple[int, int] | None = None
    first = ""
    for path in paths:
        path = Path(path)
        if not path.is_file():
            raise IntrinsicsError(f"image {path} does not exist; check the path.")
        image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if image is None:
            raise IntrinsicsError(f"image {path} is not an image OpenCV can read.")
        if image.ndim == 3:
            image = cv2.cvtColor(image[..., :3], cv2.COLOR_BGR2RGB)
        this = (image.shape[1], image.shape[0])
        if size is None:
            size, first = this, str(path)
        elif this != size:
            raise IntrinsicsError(
                f"image {path} is {this[0]}x{this[1]} but {first} is {size[0]}x{size[1]}; "
                "give images of one camera at one resolution."
            )
        results.append(find_corners(image, board, params, infrared=infrared))
    if size is None:
        raise IntrinsicsError("no images were given; list the chessboard images to use.")
    return results, size
