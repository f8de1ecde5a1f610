"""The checkerboard: its geometry, finding its corners in colour and infrared
images, and a coverage map of where corners have been seen.

Board frame (OpenPTrack's and OpenCV's): origin at the first inner corner,
x along a row of inner corners (``cols`` of them), y along a column (``rows``
of them), z = x cross y, pointing away from the side that is seen. Corner
``k`` is ``(k % cols, k // cols) * square``. The printed board
(:mod:`optrack.calibration.printable`) has a dark square diagonally before
corner 0, which makes the order of corners the same in every camera for a
board with one odd and one even count (such as 9x6).
"""

from __future__ import annotations

import dataclasses
import math
import re

import cv2
import numpy as np

from optrack.errors import UserError
from optrack.params import Param, Params, Schema, register

__all__ = [
    "CORNER_PARAMS",
    "OPENCV_SAMPLE_CORNERS",
    "BoardError",
    "Checkerboard",
    "CoverageMap",
    "find_corners",
    "to_gray",
]


class BoardError(UserError):
    """A checkerboard description that cannot be used."""


CORNER_PARAMS = register(
    Schema(
        "calibration_corners",
        [
            Param(
                "subpix_window",
                11,
                min=2,
                max=30,
                step=1,
                unit="px",
                help="Largest half-size of the sub-pixel corner search window (it also stays "
                "below subpix_window_fraction of the corner spacing).",
            ),
            Param(
                "subpix_window_fraction",
                0.6,
                min=0.0,
                max=2.0,
                step=0.05,
                help="The sub-pixel window's half-size stays below this fraction of the corner "
                "spacing, so that it never reaches the grid lines through the neighbouring "
                "corners (0: always subpix_window, as OpenCV's calibration sample).",
            ),
            Param(
                "subpix_border_fraction",
                0.35,
                min=0.0,
                max=2.0,
                step=0.05,
                help="Corners of the outermost rows and columns: the window's half-size also "
                "stays below this fraction of the corner spacing, so that it never reaches "
                "the outer edge of the outer squares, which printed boards often cut short "
                "(0: no extra limit).",
            ),
            Param(
                "subpix_iterations",
                40,
                min=1,
                max=200,
                step=1,
                help="Iterations of OpenCV's cornerSubPix.",
            ),
            Param(
                "subpix_epsilon",
                0.001,
                min=1e-6,
                max=0.1,
                unit="px",
                help="cornerSubPix stops when a corner moves less than this.",
            ),
            Param(
                "fast_check",
                True,
                help="Quickly skip images without a board (OpenCV's CALIB_CB_FAST_CHECK).",
            ),
            Param(
                "infrared_equalize",
                True,
                help="Equalise the histogram of infrared images before looking for the board.",
            ),
            Param(
                "search_width",
                1024,
                min=0,
                max=4096,
                step=16,
                unit="px",
                help="Narrower images are searched for the board upsampled to this width: "
                "small boards are found far more often (OpenPTrack's trick for the 176x144 "
                "SR4500, used for every camera). 0: never upsample.",
            ),
            Param(
                "max_detection_width",
                1280,
                min=320,
                max=8192,
                step=16,
                unit="px",
                help="Wider images are searched for the board at this width; the corners are "
                "then refined at full resolution.",
            ),
            Param(
                "coverage_cells",
                8,
                min=2,
                max=64,
                step=1,
                help="Cells across the image width in the coverage map (rows follow the "
                "aspect ratio).",
            ),
        ],
        help="Finding checkerboard corners in colour and infrared images.",
    )
)

#: OpenCV's calibration sample's corner refinement (an 11-pixel window whatever the squares'
#: size), which made OpenCV's left_intrinsics.yml; ``calibration_corners`` values.
OPENCV_SAMPLE_CORNERS = {
    "subpix_window": 11,
    "subpix_window_fraction": 0.0,
    "subpix_border_fraction": 0.0,
}


@dataclasses.dataclass(frozen=True)
class Checkerboard:
    """A planar chessboard: ``cols`` x ``rows`` inner corners, ``square`` metres apart."""

    cols: int
    rows: int
    square: float

    def __post_init__(self) -> None:
        if self.cols < 2 or self.rows < 2:
            raise BoardError(
                f"a checkerboard needs at least 2x2 inner corners; got {self.cols}x{self.rows}."
            )
        if not (math.isfinite(self.square) and self.square > 0):
            raise BoardError(
                f"the checkerboard square size must be a positive length in metres; got {self.square}."
            )

    @classmethod
    def parse(cls, text: str, square: float) -> Checkerboard:
        """A board from ``"CxR"`` (inner corners, e.g. ``"9x6"``) and the square size (m)."""
        match = re.fullmatch(r"\s*(\d+)\s*[xX*]\s*(\d+)\s*", text or "")
        if match is None:
            raise BoardError(
                f"--board must be the inner corners as COLUMNSxROWS, e.g. 9x6; got '{text}'."
            )
        if square is None or not square > 0:
            raise BoardError(
                f"--square must be the side of one square in metres, e.g. 0.025; got {square}."
            )
        if square > 1.0:
            raise BoardError(
                f"--square {square} is more than a metre; give the square size in metres "
                "(25 mm is 0.025)."
            )
        return cls(int(match.group(1)), int(match.group(2)), float(square))

    @property
    def size(self) -> tuple[int, int]:
        """OpenCV's pattern size (columns, rows)."""
        return (self.cols, self.rows)

    @property
    def count(self) -> int:
        return self.cols * self.rows

    @property
    def symmetric(self) -> bool:
        """True when a half turn maps the pattern onto itself (both counts odd or both even):
        then two cameras may number the corners differently."""
        return self.cols % 2 == self.rows % 2

    @property
    def object_points(self) -> np.ndarray:
        """Corners in the board frame, Nx3 float64 metres (z = 0), OpenCV's order."""
        grid = np.mgrid[0 : self.cols, 0 : self.rows].T.reshape(-1, 2)
        points = np.zeros((self.count, 3), dtype=np.float64)
        points[:, :2] = grid * self.square
        return points

    @property
    def center(self) -> np.ndarray:
        """Centre of the inner-corner grid in the board frame."""
        return np.array([(self.cols - 1) * self.square / 2, (self.rows - 1) * self.square / 2, 0.0])

    def describe(self) -> str:
        return f"{self.cols}x{self.rows} inner corners, {self.square * 1000:g} mm squares"

    def require_asymmetric(self) -> None:
        """Refuse a board whose corner order two cameras could disagree on."""
        if self.symmetric:
            raise BoardError(
                f"a {self.cols}x{self.rows} board looks the same after a half turn, so cameras "
                "can number its corners differently; use one odd and one even count, e.g. 9x6."
            )

    def as_dict(self) -> dict[str, float | int]:
        return {"cols": self.cols, "rows": self.rows, "square": self.square}


# --------------------------------------------------------------------- images


def to_gray(image: np.ndarray) -> np.ndarray:
    """8-bit grey image from RGB uint8, grey uint8, or 16-bit (scaled by its range)."""
    image = np.asarray(image)
    if image.ndim == 3:
        if image.dtype != np.uint8:
            image = cv2.normalize(image, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
        return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    if image.dtype == np.uint8:
        return image
    values = image.astype(np.float32)
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return np.zeros(image.shape, dtype=np.uint8)
    low, high = np.percentile(finite, (0.5, 99.5))
    scaled = (np.nan_to_num(values, nan=low) - low) * (255.0 / max(high - low, 1e-9))
    return np.clip(scaled, 0, 255).astype(np.uint8)


def _subpix_window(
    corners: np.ndarray, board: Checkerboard, largest: int, fraction: float = 0.6
) -> int:
    """Half-size of cornerSubPix's window: below ``fraction`` of the smallest corner
    spacing (``largest`` when ``fraction`` is 0)."""
    if fraction <= 0:
        return int(largest)
    grid = corners.reshape(board.rows, board.cols, 2)
    spacing = min(
        float(np.min(np.linalg.norm(np.diff(grid, axis=1), axis=2))),
        float(np.min(np.linalg.norm(np.diff(grid, axis=0), axis=2))),
    )
    return int(max(2, min(largest, math.floor(fraction * spacing))))


def _border_mask(board: Checkerboard) -> np.ndarray:
    """True for the corners of the outermost rows and columns (board order)."""
    grid = np.zeros((board.rows, board.cols), dtype=bool)
    grid[[0, -1], :] = True
    grid[:, [0, -1]] = True
    return grid.ravel()


def _subpix_windows(corners: np.ndarray, board: Checkerboard, p: Params) -> tuple[int, int]:
    """(inner, border) half-sizes of cornerSubPix's window for ``corners`` (any order that
    keeps rows and columns, as findChessboardCorners returns them)."""
    inner = _subpix_window(corners, board, int(p.subpix_window), float(p.subpix_window_fraction))
    border_fraction = float(p.subpix_border_fraction)
    if border_fraction <= 0:
        return inner, inner
    return inner, min(inner, _subpix_window(corners, board, int(p.subpix_window), border_fraction))


def _corner_subpix(
    gray: np.ndarray,
    corners: np.ndarray,
    board: Checkerboard,
    windows: tuple[int, int],
    criteria: tuple[int, int, float],
) -> np.ndarray:
    """cornerSubPix with one window for the inner corners and one for the border corners."""
    start = np.ascontiguousarray(corners.reshape(-1, 2), dtype=np.float32)
    refined = start.copy()
    inner, border = windows
    groups = [(np.ones(len(start), dtype=bool), inner)]
    if border != inner:
        mask = _border_mask(board)
        groups = [(~mask, inner), (mask, border)]
    for mask, window in groups:
        refined[mask] = cv2.cornerSubPix(
            gray, start[mask].reshape(-1, 1, 2), (window, window), (-1, -1), criteria
        ).reshape(-1, 2)
    return refined


def _canonical_order(corners: np.ndarray, gray: np.ndarray, board: Checkerboard) -> np.ndarray:
    """Put the corners in the board's own order, the same in every camera.

    The grid seen from the front keeps x then y turning clockwise in the image
    (v points down); a mirrored numbering is undone. Then, for a board that a
    half turn does not map onto itself, the square diagonally before corner 0
    must be the darker of the two outer squares at that end of the first row.
    """
    grid = corners.reshape(board.rows, board.cols, 2)
    x_step = grid[0, -1] - grid[0, 0]
    y_step = grid[-1, 0] - grid[0, 0]
    if x_step[0] * y_step[1] - x_step[1] * y_step[0] < 0:  # mirrored: reverse each row
        grid = grid[:, ::-1]
    if not board.symmetric:
        source = np.array(
            [[0, 0], [board.cols - 1, 0], [0, board.rows - 1], [board.cols - 1, board.rows - 1]],
            dtype=np.float32,
        )
        target = grid[[0, 0, -1, -1], [0, -1, 0, -1]].astype(np.float32)
        homography = cv2.getPerspectiveTransform(source, target)
        samples = np.array(
            [[[-0.5, -0.5], [0.5, -0.5]]], dtype=np.float32
        )  # square before corner 0, its neighbour along x
        pixels = cv2.perspectiveTransform(samples, homography).reshape(-1, 2)
        height, width = gray.shape
        spacing = float(np.linalg.norm(x_step)) / max(board.cols - 1, 1)
        radius = max(1, int(spacing * 0.2))
        values = []
        for u, v in pixels:
            u0, v0 = int(round(u)), int(round(v))
            patch = gray[
                max(v0 - radius, 0) : min(v0 + radius + 1, height),
                max(u0 - radius, 0) : min(u0 + radius + 1, width),
            ]
            values.append(float(patch.mean()) if patch.size else math.nan)
        if all(math.isfinite(v) for v in values) and values[0] > values[1]:
            grid = grid[::-1, ::-1]  # a half turn
    return np.ascontiguousarray(grid.reshape(-1, 2))


def find_corners(
    image: np.ndarray,
    board: Checkerboard,
    params: Params | None = None,
    *,
    infrared: bool = False,
) -> np.ndarray | None:
    """The board's inner corners in ``image`` (Nx2 float64 pixels, board order), or None.

    Colour images are converted to grey; infrared images (8 or 16 bit) are
    scaled to 8 bits and, for the search, histogram-equalised. The search
    runs on the image resized to ``search_width`` when it is narrower (small
    boards are found far more often: OpenPTrack's SR4500 trick) or to
    ``max_detection_width`` when it is wider. Corners are then refined to
    sub-pixel accuracy in the original, unequalised image (equalising moves
    edges), or in the upsampled one when the squares are too small for a
    3-pixel window, and returned in the original image's pixels (pixel
    centres at integers). The window of a corner of the outermost rows and
    columns is kept smaller (``subpix_border_fraction``): the outer squares of
    a printed board are often cut short, and a window that reaches their cut
    edge pulls the corner off by pixels.
    """
    p = params if params is not None else CORNER_PARAMS.create()
    gray = to_gray(image)  # linear in the light: sub-pixel refinement works on this one
    detect = cv2.equalizeHist(gray) if infrared and p.infrared_equalize else gray
    width = gray.shape[1]
    scale = 1.0
    if 0 < width < p.search_width:
        scale = float(p.search_width) / width
    elif width > p.max_detection_width:
        scale = float(p.max_detection_width) / width
    search = detect
    if scale != 1.0:
        interpolation = cv2.INTER_CUBIC if scale > 1 else cv2.INTER_AREA
        search = cv2.resize(detect, None, fx=scale, fy=scale, interpolation=interpolation)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    if p.fast_check:
        flags |= cv2.CALIB_CB_FAST_CHECK
    found, corners = cv2.findChessboardCorners(search, board.size, flags=flags)
    if not found or corners is None or len(corners) != board.count:
        return None
    corners = corners.reshape(-1, 2).astype(np.float32)
    criteria = (
        cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT,
        int(p.subpix_iterations),
        float(p.subpix_epsilon),
    )
    native = (corners + 0.5) / scale - 0.5
    windows = _subpix_windows(native, board, p)
    if scale > 1 and min(windows) < 3:  # squares too small here: refine where they are larger
        larger = cv2.resize(gray, None, fx=scale, fy=scale, interpolation=cv2.INTER_CUBIC)
        refined = _corner_subpix(
            larger, corners, board, _subpix_windows(corners, board, p), criteria
        )
        refined = (refined + 0.5) / scale - 0.5
    else:
        refined = _corner_subpix(gray, native, board, windows, criteria)
    return _canonical_order(refined, gray, board).astype(np.float64)


class CoverageMap:
    """How much of the image the board's corners have covered (a coarse grid of counts).

    Good intrinsics need corners near the edges and corners of the image,
    where distortion is strongest; the map shows the operator where to move
    the board next.
    """

    def __init__(self, width: int, height: int, cells: int = 8) -> None:
        if width <= 0 or height <= 0:
            raise ValueError(f"a coverage map needs a positive image size; got {width}x{height}.")
        self.width = width
        self.height = height
        self.cells_x = int(cells)
        self.cells_y = max(1, round(cells * height / width))
        self.counts = np.zeros((self.cells_y, self.cells_x), dtype=np.int64)

    def add(self, corners: np.ndarray) -> None:
        corners = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
        inside = (
            (corners[:, 0] >= -0.5)
            & (corners[:, 0] < self.width - 0.5)
            & (corners[:, 1] >= -0.5)
            & (corners[:, 1] < self.height - 0.5)
        )
        cx = ((corners[inside, 0] + 0.5) * self.cells_x / self.width).astype(int)
        cy = ((corners[inside, 1] + 0.5) * self.cells_y / self.height).astype(int)
        np.add.at(
            self.counts, (np.clip(cy, 0, self.cells_y - 1), np.clip(cx, 0, self.cells_x - 1)), 1
        )

    @property
    def fraction(self) -> float:
        """Share of cells with at least one corner, 0..1."""
        return float(np.count_nonzero(self.counts)) / self.counts.size

    def as_lists(self) -> list[list[int]]:
        return self.counts.tolist()
